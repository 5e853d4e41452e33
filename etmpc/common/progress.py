"""How long long work has left, on stderr (stdout keeps the results): one helper for every command.

``with Progress(total, label) as bar: ... bar.update(n)`` shows

* on a terminal, a tqdm bar (its own time left);
* otherwise (stderr is a log), a line now and then, e.g.
  ``etmpc score: 120/500 episodes, 1:23 elapsed, about 4:10 left``: the first once :data:`FIRST_LINE_AFTER`
  seconds have passed with work done (a command that ends sooner prints none, and the estimate has some work
  behind it), then every :data:`EVERY` seconds or a tenth of the time so far, whichever is longer (at most
  :data:`LONGEST`), and at 25, 50 and 75 % (never two lines :data:`CLOSEST` seconds apart); and, if it printed
  any, one line when the work is done. A long run's log gets a few dozen lines, not one per episode.

The time left is the work left at the rate of the work done since the first unit (the time to the first one, a
pool of workers starting, is paid once: counted in, it made a verify of 40 episodes whose workers took 17 s to
start say "about 10:46 left" at its first episode, for 10 s of work), once that work spans :data:`MEASURED`
seconds (results come in chunks: two units in the same instant are no rate). :meth:`Progress.skip` counts work that was
already done (a kept row, a resumed run) without making the estimate faster.

**Whole commands.** A tracker made with ``whole=True`` counts a command's units of work up front (a suite
score: every task's episodes of every policy); trackers opened inside it (each evaluation's) count into
it and show nothing of their own, so the estimate is the whole command's. Inside any other open tracker a
new one shows nothing (no bar over a bar). :func:`stage` names the part of a command that runs (``with
stage("cart_pendulum: DPI training"): ...``) in the lines of the trackers opened inside it, and
:func:`command` names the command (``etmpc score``) at the start of every line.

**Within an episode.** A single episode can run for minutes (a rollout that simulates to the episode's end at
each decision). :class:`EpisodeSteps` counts its steps and, once the episode has run :data:`FIRST_LINE_AFTER`
seconds, says where it is every :data:`EVERY` seconds (``etmpc evaluate: episode 0 of rollout:every:7: step
40/600, 0:31 elapsed, about 7:15 left``), above the bar if one shows, in whichever process plays it; a shorter
episode says nothing. :func:`episode` names the episode in those lines.

Progress changes nothing but stderr: no number, no file. Tests drive it with a fake ``clock`` and ``stream``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar, Token

FIRST_LINE_AFTER = 10.0  # seconds of work before the first line: an estimate from less is noise
EVERY = 30.0  # seconds between lines, at the least
LONGEST = 600.0  # ... and at the most, however long the run
CLOSEST = 5.0  # a quarter's line waits this long after the last line
MEASURED = 5.0  # seconds of work since the first unit before there is a rate (results come in chunks)

_COMMAND: ContextVar[str] = ContextVar("etmpc_progress_command", default="etmpc")
_STAGES: ContextVar[tuple[str, ...]] = ContextVar("etmpc_progress_stages", default=())
_OPEN: ContextVar[Progress | None] = ContextVar("etmpc_progress_open", default=None)
_EPISODE: ContextVar[str] = ContextVar("etmpc_progress_episode", default="an episode")


@contextmanager
def command(name: str) -> Iterator[None]:
    """Within it, progress lines start with ``name`` (``etmpc score``) rather than ``etmpc``."""
    token = _COMMAND.set(name)
    try:
        yield
    finally:
        _COMMAND.reset(token)


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Within it, the trackers opened name this stage of the command in their lines and bars."""
    token = _STAGES.set((*_STAGES.get(), name))
    try:
        yield
    finally:
        _STAGES.reset(token)


def _title(label: str = "") -> str:
    """What a line starts with: the command, the stages it is in, and ``label`` (``etmpc score: DPI: episodes``)."""
    return ": ".join([_COMMAND.get(), *_STAGES.get(), *([label] if label else [])])


def clock_time(seconds: float) -> str:
    """``83`` -> ``1:23``, ``3723`` -> ``1:02:03``."""
    whole = max(0, int(round(seconds)))
    hours, rest = divmod(whole, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


def say(line: str, stream=None) -> None:
    """A line on stderr (``stream``), above the open tracker's bar if it shows one."""
    open_ = _OPEN.get()
    if open_ is not None and open_._bar is not None:
        open_._bar.write(line, file=open_._stream)
    else:
        print(line, file=sys.stderr if stream is None else stream, flush=True)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


class Progress:
    """``total`` units of work (``unit``: ``episodes``, ``steps``), counted with :meth:`update` (and
    :meth:`skip`), shown as the module says; ``enabled=False`` shows nothing. ``n`` and ``total`` are its
    own count whether it shows or not. ``stream`` (default stderr), ``clock`` (default ``time.monotonic``)
    and ``terminal`` (default: whether ``stream`` is one) are for tests."""

    def __init__(
        self,
        total: int,
        label: str = "",
        enabled: bool = True,
        unit: str = "episodes",
        *,
        whole: bool = False,
        stream=None,
        clock: Callable[[], float] = time.monotonic,
        terminal: bool | None = None,
    ):
        self.n, self.total, self.unit, self.whole = 0, int(total), unit, whole
        self._skipped = 0
        self._first: float | None = None  # when the first unit of work was done here
        self._rated = 0  # units done here since then: the estimate's rate is theirs
        self._stream = sys.stderr if stream is None else stream
        self._clock = clock
        self._started = clock()
        self._title = _title(label)
        outer = _OPEN.get()
        self._parent = outer if outer is not None and outer.whole else None
        shown = enabled and outer is None  # inside another tracker: its count shows (a whole one's), or nothing
        terminal = _is_terminal(self._stream) if terminal is None else terminal
        self._lines = shown and not terminal
        self._last_line: float | None = None
        self._quarters = 0  # the quarters said in a line
        self._said = 0
        self._bar = None
        if shown and terminal:
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                desc=self._title.removeprefix("etmpc "),
                unit="ep" if unit == "episodes" else f" {unit}",
                file=self._stream,
                leave=False,
            )
        self._token: Token[Progress | None] | None = None  # set by __enter__ of the outermost bar

    def __enter__(self) -> Progress:
        if _OPEN.get() is None:
            self._token = _OPEN.set(self)
        return self

    def __exit__(self, kind, *_) -> None:
        self.close(finished=kind is None)

    def close(self, finished: bool = True) -> None:
        """End it: the bar goes; a log that had a line gets the last one (``finished``: the work ended)."""
        if self._token is not None:
            _OPEN.reset(self._token)
            self._token = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if finished and self._lines and self._said:
            self._print(f"{self._title}: {self.n}/{self.total} {self.unit}, done in {clock_time(self._elapsed())}")
            self._lines = False

    def update(self, n: int = 1) -> None:
        """``n`` more units done."""
        self._count(n, skipped=False)

    def skip(self, n: int) -> None:
        """``n`` units that need no work (done before): counted, but not in the rate of the estimate."""
        self._count(n, skipped=True)

    def _count(self, n: int, skipped: bool) -> None:
        self.n += n
        if skipped:
            self._skipped += n
        elif self._first is None:
            self._first = self._clock()
        else:
            self._rated += n
        if self._parent is not None:
            self._parent._count(n, skipped)
        if self._bar is not None:
            self._bar.update(n)
        if self._lines:
            self._maybe_line()

    def times(self) -> str:
        """``1:23 elapsed, about 4:10 left`` (the time left when any work was done here)."""
        elapsed = self._elapsed()
        left = self.left()
        return f"{clock_time(elapsed)} elapsed" + ("" if left is None else f", about {clock_time(left)} left")

    def left(self) -> float | None:
        """Seconds left at the rate of the work done here since its first unit (the time to the first, the
        workers' start, is not the rate: it is paid once); None before it spans :data:`MEASURED` seconds."""
        if self._first is None or self._rated <= 0 or self._clock() - self._first < MEASURED:
            return None
        return max(0, self.total - self.n) * (self._clock() - self._first) / self._rated

    def write(self, line: str) -> None:
        """A line of the work's own (a learner's report), on stderr, above the bar; nothing when quiet."""
        if self._parent is not None:
            self._parent.write(line)
        elif self._bar is not None:
            self._bar.write(line, file=self._stream)
        elif self._lines:
            self._print(line)

    def result(self, text: str) -> None:
        """``text`` on stdout (a result, printed whether progress shows or not), the bar cleared around it."""
        if self._bar is not None:
            self._bar.write(text, file=sys.stdout)
        else:
            print(text, flush=True)

    def _elapsed(self) -> float:
        return self._clock() - self._started

    def _maybe_line(self) -> None:
        elapsed, now = self._elapsed(), self._clock()
        if self.left() is None or elapsed < FIRST_LINE_AFTER or self.n >= self.total:
            return  # nothing to estimate from yet, or done (close says so)
        quarters = min(3, 4 * self.n // max(1, self.total))
        since = None if self._last_line is None else now - self._last_line
        due = since is None or since >= min(max(EVERY, elapsed / 10), LONGEST) or (quarters > self._quarters and since >= CLOSEST)
        if due:
            self._last_line, self._quarters = now, quarters
            self._print(f"{self._title}: {self.n}/{self.total} {self.unit}, {self.times()}")

    def _print(self, line: str) -> None:
        self._said += 1
        print(line, file=self._stream, flush=True)


@contextmanager
def episode(name: str) -> Iterator[None]:
    """Within it, an episode's step lines name it (``episode 3 of every:3``) rather than ``an episode``."""
    token = _EPISODE.set(name)
    try:
        yield
    finally:
        _EPISODE.reset(token)


class EpisodeSteps:
    """The steps of one episode (``total``), counted with :meth:`update`: once the episode has run
    :data:`FIRST_LINE_AFTER` seconds, a line on stderr every :data:`EVERY` seconds with the step it is at and
    its time left at the rate so far (see the module). ``clock`` and ``stream`` are for tests."""

    def __init__(self, total: int, clock: Callable[[], float] = time.monotonic, stream=None):
        self.n, self.total = 0, int(total)
        self._clock, self._stream = clock, stream
        self._started = clock()
        self._next = self._started + FIRST_LINE_AFTER

    def update(self) -> None:
        """One more step done (a clock read: nothing else unless a line is due)."""
        self.n += 1
        now = self._clock()
        if now >= self._next and self.n < self.total:
            self._next = now + EVERY
            elapsed = now - self._started
            left = (self.total - self.n) * elapsed / self.n
            where = f"step {self.n}/{self.total}, {clock_time(elapsed)} elapsed, about {clock_time(left)} left"
            say(f"{_title(_EPISODE.get())}: {where}", self._stream)
