"""Progress on stderr: in a log, lines with the count and the time left, few of them; a bar only on a terminal.

Driven by a fake clock (no sleeping): each test moves the time itself."""

from __future__ import annotations

import io
import re

import pytest

from etmpc.common import progress
from etmpc.common.progress import Progress, clock_time, command, stage

LINE = re.compile(r"^etmpc score: (\d+)/(\d+) episodes, (\d+:\d\d) elapsed, about (\d+:\d\d) left$")


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _run(total: int, seconds_each: float, **kwargs) -> tuple[list[str], list[float]]:
    """``total`` episodes of ``seconds_each`` under ``etmpc score``, in a log: its lines and when each came."""
    clock, stream = Clock(), io.StringIO()
    said, at = [], []
    with command("etmpc score"), Progress(total, stream=stream, clock=clock, **kwargs) as bar:
        for _ in range(total):
            clock.now += seconds_each
            bar.update()
            new = stream.getvalue().splitlines()[len(said) :]
            said += new
            at += [clock.now - 1000.0] * len(new)
    said += stream.getvalue().splitlines()[len(said) :]
    return said, at


def test_a_log_gets_lines_with_the_count_and_the_time_left_every_30_s_and_at_each_quarter():
    said, at = _run(500, 1.0)  # 500 episodes of a second each
    *lines, last = said
    assert last == "etmpc score: 500/500 episodes, done in 8:20"
    parsed = [LINE.match(line) for line in lines]
    assert all(parsed), lines
    counts = [int(m[1]) for m in parsed]
    assert counts[0] == 10 and parsed[0][3] == "0:10" and parsed[0][4] == "8:10"  # 490 left at one a second
    assert parsed[5][4] == clock_time(500 - counts[5])  # the estimate follows the rate
    assert {125, 250, 375} <= set(counts)  # 25, 50 and 75 %
    gaps = [b - a for a, b in zip(at, at[1 : len(lines)])]
    quarters = {i for i, n in enumerate(counts[1:]) if n in (125, 250, 375)}
    assert all(gap >= 30 or i in quarters for i, gap in enumerate(gaps)), gaps
    assert min(gaps) >= progress.CLOSEST and len(lines) <= 20


def test_no_line_before_10_s_of_work_so_a_short_command_prints_none():
    said, _ = _run(100, 0.09)  # 9 s in all
    assert said == []


def test_however_many_and_fast_the_updates_a_long_run_gets_a_few_dozen_lines():
    said, at = _run(200_000, 0.05)  # 10 000 s, an update every 50 ms
    assert 20 <= len(said) <= 60
    assert all(b - a >= progress.CLOSEST for a, b in zip(at, at[1:]))
    assert max(b - a for a, b in zip(at, at[1:-1])) <= progress.LONGEST + 0.06  # the update after it is due


def test_work_done_before_is_counted_but_does_not_make_the_estimate_faster():
    clock = Clock()
    bar = Progress(100, stream=io.StringIO(), clock=clock)
    bar.skip(50)  # kept from an earlier run
    assert bar.left() is None
    clock.now += 10.0
    bar.update(5)
    clock.now += 5.0
    bar.update(5)
    assert bar.n == 60 and bar.left() == pytest.approx(40.0) and bar.times() == "0:15 elapsed, about 0:40 left"


def test_the_bar_is_off_when_stderr_is_not_a_terminal_and_on_when_it_is():
    log, tty = io.StringIO(), io.StringIO()
    with Progress(10, stream=log) as bar:  # a StringIO is no terminal
        bar.update(3)
        assert bar._bar is None
    with Progress(10, stream=tty, terminal=True) as bar:
        bar.update(3)
        assert bar._bar is not None
    assert log.getvalue() == "" and "/10 [" in tty.getvalue()  # tqdm's bar, drawn at its start


def test_disabled_it_shows_nothing_but_still_counts():
    clock, stream = Clock(), io.StringIO()
    with Progress(10, enabled=False, stream=stream, clock=clock) as bar:
        for _ in range(10):
            clock.now += 60.0
            bar.update()
        bar.write("a learner's report")
    assert stream.getvalue() == "" and bar.n == 10


def test_inside_a_whole_commands_tracker_each_part_counts_into_it_and_shows_nothing_of_its_own():
    clock, whole_log, part_log = Clock(), io.StringIO(), io.StringIO()
    with command("etmpc score"), Progress(20, whole=True, stream=whole_log, clock=clock) as whole:
        for _ in range(2):
            with Progress(10, stream=part_log, clock=clock) as part:
                for _ in range(10):
                    clock.now += 2.0
                    part.update()
            assert part.n == 10
    assert whole.n == 20 and part_log.getvalue() == ""
    lines = whole_log.getvalue().splitlines()
    assert lines[0] == "etmpc score: 5/20 episodes, 0:10 elapsed, about 0:30 left"
    assert lines[-1] == "etmpc score: 20/20 episodes, done in 0:40"


def test_inside_another_tracker_a_new_one_shows_nothing():
    clock, outer_log, inner_log = Clock(), io.StringIO(), io.StringIO()
    with Progress(10, stream=outer_log, clock=clock) as outer:
        with Progress(10, stream=inner_log, clock=clock) as inner:
            clock.now += 60.0
            inner.update(5)
    assert inner_log.getvalue() == "" and outer.n == 0


def test_a_stage_is_named_in_the_lines_of_its_trackers():
    clock, stream = Clock(), io.StringIO()
    with command("etmpc reproduce"), stage("cart_pendulum: DPI training"):
        with Progress(4, "", stream=stream, clock=clock, unit="steps") as bar:
            for _ in range(2):
                clock.now += 10.0
                bar.update()
    assert stream.getvalue().splitlines()[0] == (
        "etmpc reproduce: cart_pendulum: DPI training: 2/4 steps, 0:20 elapsed, about 0:20 left"
    )


def test_an_interrupted_run_says_no_done_line():
    clock, stream = Clock(), io.StringIO()
    with pytest.raises(KeyboardInterrupt), Progress(10, stream=stream, clock=clock) as bar:
        for _ in range(2):
            clock.now += 10.0
            bar.update()
        raise KeyboardInterrupt
    assert len(stream.getvalue().splitlines()) == 1 and "done" not in stream.getvalue()


def test_times_read_as_a_clock():
    assert [clock_time(s) for s in (0, 9.6, 83, 600, 3723)] == ["0:00", "0:10", "1:23", "10:00", "1:02:03"]


def test_a_result_goes_to_stdout_whole_with_the_bar_cleared_around_it(capsys):
    tty = io.StringIO()
    with Progress(2, stream=tty, terminal=True) as bar:
        bar.result("cart_pendulum: 10 test-set episodes")
        bar.update()
    assert capsys.readouterr().out == "cart_pendulum: 10 test-set episodes\n" and "/2 [" in tty.getvalue()


def test_the_time_to_the_first_episode_a_pool_starting_is_not_taken_for_the_rate():
    clock, stream = Clock(), io.StringIO()
    with command("etmpc score"), Progress(40, stream=stream, clock=clock) as bar:
        clock.now += 17.0  # the workers start
        bar.update()
        assert bar.left() is None  # one episode: no rate yet, no line
        bar.update()  # in the same chunk: still no rate
        assert bar.left() is None
        for _ in range(5):
            clock.now += 1.0
            bar.update()
    first = stream.getvalue().splitlines()[0]
    assert first == "etmpc score: 7/40 episodes, 0:22 elapsed, about 0:28 left"  # 33 episodes at six in the 5 s since the first
