"""A plugin that exits on import, seen from the command line: etmpc still answers, and says so in one
line per plugin (``etmpc: warning: ...``), not in Python's two-line warnings format. The plugin is a
module and its distribution's metadata (``.dist-info``, the entry points) in a folder on PYTHONPATH:
what an installed package looks like to ``importlib.metadata``. In-process cases: tests/systems/test_registry.py."""

import os
import subprocess
import sys

EXITS = "raise SystemExit(0)  # as a script's `if __name__` guard gone wrong would\n"


def test_a_plugin_that_exits_on_import_is_one_warning_line_each_and_the_command_still_runs(tmp_path):
    (tmp_path / "fake_exits.py").write_text(EXITS)
    info = tmp_path / "fake_exits-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-exits\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[etmpc.tasks]\nexits = fake_exits\n\n[etmpc.policies]\nexits = fake_exits:KIND\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    env.pop("PYTHONWARNINGS", None)
    result = subprocess.run(
        [sys.executable, "-m", "etmpc.cli", "evaluate", "--help"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "--policy" in result.stdout and "exits" not in result.stdout
    assert sorted(result.stderr.splitlines()) == [
        "etmpc: warning: policy kind plugin 'exits' (fake_exits:KIND) failed to load (SystemExit(0)); left out",
        "etmpc: warning: task plugin 'exits' (fake_exits) failed to import (SystemExit(0)); its tasks are left out",
    ]
