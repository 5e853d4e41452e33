"""``--record URL`` streams a run's episodes to a Rerun viewer, and ``--spawn`` starts one, as Rerun users expect.

No viewer window can open here: the viewer is stood in for by Rerun's own command line started headless in the
test (``rerun --port P --save FILE``: the gRPC server a viewer runs, saving what it receives), and what it
received is read back with ``etmpc replay``'s reader and compared with the run's own JSON. A URL that nothing
answers, and ``--spawn`` without a screen, are one line each before any episode is played."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.views.replay import replay_summary
from etmpc.views.sinks import viewer_url

EVALUATE = ["evaluate", "--task", "cart_pendulum", "--policy", "every:3", "--episodes"]
RERUN = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")  # the viewer the SDK installs


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def listening(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
    except OSError:
        return False
    return True


def complete(path: Path) -> bool:
    """Whether ``path`` holds a whole recording yet (its end marker read)."""
    try:
        replay_summary(path)
    except EtmpcError:
        return False
    return True


@pytest.fixture
def receiver(tmp_path):
    """A headless Rerun server on a free local port that saves what it receives: ``(url, saved file)``."""
    if not Path(RERUN).is_file():
        pytest.skip("the rerun command line is not installed")
    port, saved = free_port(), tmp_path / "received.rrd"
    server = subprocess.Popen(
        [RERUN, "--bind", "127.0.0.1", "--port", str(port), "--save", str(saved)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # the command is a Python launcher of Rerun's binary: both are ended together
    )
    try:
        deadline = time.monotonic() + 30
        while not listening(port):
            assert server.poll() is None and time.monotonic() < deadline, "the Rerun server did not start"
            time.sleep(0.2)
        yield f"rerun+http://127.0.0.1:{port}/proxy", saved, server
    finally:
        if server.poll() is None:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait(timeout=30)


def test_evaluate_streams_its_episodes_to_a_viewer_and_the_viewer_receives_them_all(tmp_path, receiver, capsys):
    url, saved, server = receiver
    run = tmp_path / "run.json"
    assert main([*EVALUATE, "2", "--json", str(run), "--record", url]) == 0
    assert f"streamed the episodes to {url}" in capsys.readouterr().out
    deadline = time.monotonic() + 30  # the server writes what it receives as it comes: wait for the end marker
    while not (saved.is_file() and complete(saved)) and time.monotonic() < deadline:
        time.sleep(0.3)
    os.killpg(server.pid, signal.SIGINT)  # then stopped as Ctrl-C would
    server.wait(timeout=30)
    replayed = replay_summary(saved)  # complete: the end marker came too
    live = json.loads(run.read_text())["runs"]
    assert [(r.policy, r.episode, r.steps, r.recomputes) for r in replayed] == [
        (r["policy"], r["episode"], r["steps"], r["recomputes"]) for r in live
    ]
    assert [r.objective for r in replayed] == pytest.approx([r["objective"] for r in live], rel=1e-12)


def test_a_url_that_nothing_answers_is_one_line_before_any_episode(tmp_path, capsys):
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    run = tmp_path / "run.json"
    code = main([*EVALUATE, "1", "--record", url, "--json", str(run)])
    err = capsys.readouterr().err
    assert code == 2 and not run.exists()
    assert err.startswith(f"etmpc: error: no Rerun viewer answers at {url}") and err.count("\n") == 1


def test_spawn_without_a_screen_is_one_line(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main([*EVALUATE, "1", "--spawn"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("etmpc: error: --spawn opens a Rerun viewer window and there is no screen here")
    assert err.count("\n") == 1


def test_a_viewers_url_takes_rerun_forms_and_the_old_tcp_address(capsys):
    assert viewer_url("rerun+http://127.0.0.1:9876/proxy") == "rerun+http://127.0.0.1:9876/proxy"
    assert viewer_url("tcp://127.0.0.1:9877") == "rerun+http://127.0.0.1:9877/proxy"
    assert main([*EVALUATE, "1", "--record", "tcp://127.0.0.1"]) == 2
    assert "argument --record: 'tcp://127.0.0.1': a viewer's URL names its host and port" in capsys.readouterr().err
