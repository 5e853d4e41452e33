"""What the commands print: the options set above every table (and in every JSON written), counts in words ("1
episode"), no interval printed as ``nan`` (one episode has none: ``n/a``), the score's note saying each count once,
and ``etmpc replay`` with evaluate's failure columns, the figures checked against the JSON evaluate writes."""

from __future__ import annotations

import json

from etmpc.cli import main

KICKS = "cart_pendulum/kicks"
DROPOUT = ["--option", "sensor.dropout=0.1"]
ONE = ["--episodes", "1", "--workers", "1"]


def _lines(out: str, start: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith(start)]


def test_evaluate_prints_its_options_above_the_table_and_no_nan_and_writes_them(tmp_path, capsys):
    path, recording = tmp_path / "e.json", tmp_path / "e.rrd"
    argv = ["evaluate", "--task", KICKS, "--policy", "every:3", "--policy", "never", "--against", "never", *ONE, *DROPOUT]
    assert main([*argv, "--json", str(path), "--record", str(recording)]) == 0
    out = capsys.readouterr().out
    written = json.loads(path.read_text())
    assert written["options"] == {"sensor.dropout": "0.1"}
    lines = out.splitlines()
    assert lines[1] == "options: --option sensor.dropout=0.1" and lines[2].startswith("policy")  # above the table
    assert "1 episode x 1 repeat per policy" in out and "1 episodes" not in out
    assert "nan" not in out and "n/a" in out  # one episode: no CI, said so

    # etmpc replay of the recording: evaluate's columns, its figures, and the options
    capsys.readouterr()
    assert main(["replay", str(recording)]) == 0
    shown = capsys.readouterr().out
    assert "options: --option sensor.dropout=0.1" in shown and "nan" not in shown
    head = next(line for line in shown.splitlines() if line.startswith("policy"))
    assert "falls/episode" in head and "solver failures" in head
    for spec, summary in written["policies"].items():
        (row,) = _lines(shown, spec + " ")
        assert f"{summary['failures_mean']:.2f} ± n/a" in row
        assert row.split()[-4] == str(summary["solver_failures"])  # the solver failures column, then the errors


def test_score_says_each_count_once_prints_no_nan_and_puts_the_options_above(capsys):
    argv = ["score", "--policy", "every:3", "--policy", "never", "--task", KICKS, "--task", "cart_pendulum/kicks_late"]
    assert main([*argv, *ONE, *DROPOUT]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == "options: --option sensor.dropout=0.1"
    assert "nan" not in out
    (note,) = _lines(out, "note:")
    assert note.startswith("note: 1 episode on every task, fewer than")
