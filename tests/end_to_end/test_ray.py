"""The Ray backend runs the same work as the local one and gives exactly the same numbers: on a Ray
instance it starts itself, and on an existing cluster it joins by address."""

import json
import os
import secrets
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import ray  # the 'ray' extra is part of the test install, so these tests run rather than skip

from etmpc.evaluation.evaluate import evaluate
from etmpc.learning.train import TrainConfig, train

TINY = dict(seeds=(0, 1), episodes=4, eval_every=2, eval_episodes=3, normalisation_episodes=2, validation_episodes=2)
POLICIES = ["always", "every:3", "threshold:0.2"]
# One worker runs them all, in turn: `ray stop --force` stops every Ray process of the user, and would
# stop a Ray instance another test had started.
pytestmark = pytest.mark.xdist_group("ray")


def files(out):
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_training_and_evaluation_agree_exactly_on_local_and_ray(tmp_path, monkeypatch):
    # Without --address the backend starts its own instance, even where Ray would otherwise join
    # another: RAY_ADDRESS names a cluster (here one that is gone), as a Ray left running would.
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{_free_port()}")
    config = TrainConfig("cart_pendulum", **TINY)
    train(config, tmp_path / "local", workers=1, progress=False)
    train(config, tmp_path / "ray", workers=2, backend="ray", progress=False)
    assert not ray.is_initialized()  # the instance it started is stopped again
    assert files(tmp_path / "local") == files(tmp_path / "ray")

    # Evaluation, including the learned (stochastic) policy, over two passes.
    policies = POLICIES + [f"rl:{tmp_path / 'local' / 'seed1' / 'last.json'}"]
    local = evaluate("cart_pendulum", policies, episodes=4, repeats=2, workers=1, progress=False)
    remote = evaluate("cart_pendulum", policies, episodes=4, repeats=2, workers=2, progress=False, backend="ray")
    assert local.runs == remote.runs and local.summaries == remote.summaries
    assert len(local.runs) == 4 * 4 * 2 and {r.recomputes for r in local.runs} != {40}  # not all alike


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_joins_an_existing_cluster_by_address(tmp_path):
    """`ray start --head` (with token authentication, as a real cluster would have), then
    `etmpc evaluate --backend ray --address HOST:PORT` runs the work there. A fresh process, as a user
    would run it: Ray reads its token once per process."""
    ray_cli = shutil.which("ray", path=str(Path(sys.executable).parent))
    assert ray_cli is not None, "the ray extra installs the ray command next to python"
    port = _free_port()
    env = dict(os.environ, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(16), RAY_USAGE_STATS_ENABLED="0")
    subprocess.run(
        [ray_cli, "start", "--head", f"--port={port}", "--num-cpus=2", "--include-dashboard=false"],
        env=env,
        check=True,
        capture_output=True,
        timeout=120,
    )
    try:
        argv = ["evaluate", "--task", "battery", *(a for p in POLICIES for a in ("--policy", p)), "--episodes", "3"]
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "etmpc.cli",
                *argv,
                "--backend",
                "ray",
                "--address",
                f"127.0.0.1:{port}",
                "--json",
                str(tmp_path / "joined.json"),
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        status = subprocess.run(
            [ray_cli, "status", f"--address=127.0.0.1:{port}"], env=env, capture_output=True, text=True, timeout=120
        )
        assert status.returncode == 0, "the cluster it joined is still up"
    finally:
        subprocess.run([ray_cli, "stop", "--force"], env=env, capture_output=True, timeout=120)
    local = evaluate("battery", POLICIES, episodes=3, workers=1, progress=False)
    assert json.loads((tmp_path / "joined.json").read_text())["runs"] == local.to_json()["runs"]


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_a_worker_with_another_test_set_refuses_with_the_same_one_line_error(backend):
    """Workers check the test set's digest against the driver's; the error reaches the user as the
    same one-line EtmpcError on either backend (not wrapped in Ray's remote traceback)."""
    from etmpc.common.errors import EtmpcError
    from etmpc.learning.jobs import _call
    from etmpc.evaluation.backends import make_backend

    job = ("evaluate", ("battery", "0" * 64, {}, 0, 0))
    with make_backend(backend, 2) as pool, pytest.raises(EtmpcError) as caught:
        pool.map(_call, [job, job])
    assert type(caught.value) is EtmpcError
    assert str(caught.value).startswith("test set ") and "0000000000" in str(caught.value) and "\n" not in str(caught.value)
