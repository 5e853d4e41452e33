"""The command line against a hostile user and a hostile machine.

Every case below is a bad input or a fault. Each asserts what the tool promises: exit code 2 (130
for Ctrl-C, 143 for SIGTERM), exactly one line on stderr that names the problem, no traceback,
every file that was there before byte-identical, no partial file left, and no process left.

Most cases run the command in this process (``etmpc.cli.main``), so the module stays fast; the
ones that need a real process (signals, a full disk, the OpenGL backend) run ``etmpc`` as one.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from etmpc.evaluation import testsets as ts_mod
from etmpc.cli import main

from tests.conftest import REPO

CART_POLICY = REPO / "policies" / "cart_pendulum" / "balance" / "learned.json"
BATTERY_POLICY = REPO / "policies" / "battery" / "trading" / "learned.json"


# -- what every case checks -----------------------------------------------------------------------
def _files(root: Path) -> dict[str, bytes | str | None]:
    """Every file (its bytes), directory (None) and other entry (a FIFO: its type, never read) under ``root``."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root)] = None
        for f in filenames:
            path = os.path.join(dirpath, f)
            regular = os.path.isfile(path)
            out[os.path.relpath(path, root)] = Path(path).read_bytes() if regular else f"mode {os.stat(path).st_mode:o}"
    return out


def _children(pid: int) -> list[int]:
    """The processes ``pid`` started, but multiprocessing's resource tracker: one per interpreter, started
    with the first pool and kept for the interpreter's life (not a worker left behind)."""
    kids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
                command = Path(f"/proc/{entry}/cmdline").read_bytes()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid and b"resource_tracker" not in command:
                kids.append(int(entry))
    return kids


def _assert_one_line(stderr: str, must_name: str) -> None:
    assert "Traceback" not in stderr, stderr
    lines = stderr.strip("\n").splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("etmpc: "), stderr
    assert must_name.lower() in lines[0].lower(), (must_name, lines[0])


# -- the setups: each makes files in the case's directory and returns nothing ----------------------
def _write_testset(directory: Path, name: str, change=None) -> Path:
    """The stored cart test set, first 5 episodes, with ``change(arrays, meta)`` applied, written
    with a matching checksum (so only the contents are wrong)."""
    stored = ts_mod.load(ts_mod.default_path("cart_pendulum", "balance"), "cart_pendulum", "balance")
    arrays = {k: np.array(v[:5]) for k, v in stored.arrays.items()}
    meta = dict(stored.meta, episodes=5)
    if change is not None:
        arrays, meta = change(arrays, meta)
    path = directory / name
    ts_mod.write(path, arrays, meta)
    return path


def _policy_file(directory: Path, name: str, edit) -> None:
    data = json.loads(CART_POLICY.read_text())
    edit(data)
    (directory / name).write_text(json.dumps(data))


def _overflowing(data: dict) -> None:
    """Two terms of the decision value that are +inf and -inf on every state, whatever the order of the sum
    (a sum of finite overflowing terms would depend on the BLAS kernel's order, so on the machine): such
    weights are refused when the file is read, before any episode (LogisticPolicy.from_json)."""
    theta = [0.0] * len(data["theta"])
    theta[0] = theta[1] = 1e308
    data["theta"] = theta
    norm = data["normalisation"]
    norm["mean"][0], norm["mean"][1] = 1e10, -1e10  # phi_0 <= -1e9 and phi_1 >= 1e9 on any state of the task
    norm["std"][0] = norm["std"][1] = 1.0


TINY_RUN = ["--set", "episodes=2", "--set", "eval_every=2", "--set", "eval_episodes=2", "--set", "normalisation_episodes=2"]
TINY_RUN += ["--set", "validation_episodes=2", "--seeds", "0"]


_TINY_RUN_FILES: dict[str, bytes] = {}  # filled once per process


def _tiny_gpomdp_run() -> dict[str, bytes]:
    """The files of a finished GPOMDP run of ``TINY_RUN``'s settings on the battery: trained once per process, in a
    few seconds, for the cases that doctor it."""
    if not _TINY_RUN_FILES:
        import tempfile

        from etmpc.learning.base import learner_class
        from etmpc.learning.runner import run

        cls = learner_class("gpomdp")
        settings = cls.Settings(episodes=2, eval_every=2, eval_episodes=2, normalisation_episodes=2, validation_episodes=2)
        with tempfile.TemporaryDirectory() as folder:
            run(cls(settings), "battery", Path(folder), (0,), progress=False)
            _TINY_RUN_FILES.update(
                {p.relative_to(folder).as_posix(): p.read_bytes() for p in Path(folder).rglob("*") if p.is_file()}
            )
    return _TINY_RUN_FILES


def _saved_run(kind: str, run: Path) -> None:
    """A run's saved state in ``run``, doctored: a GPOMDP checkpoint with text in its learning curve, a finished PPO
    run and a self-trigger's (on their tasks at their own price), a PPO run under way whose checkpoint took 1e999 s."""
    if kind == "train-text-in-curve":
        for name, content in _tiny_gpomdp_run().items():
            (run / name).parent.mkdir(parents=True, exist_ok=True)
            (run / name).write_bytes(content)
        checkpoint = json.loads((run / "checkpoint.json").read_text())
        checkpoint["curve"][0]["objective"] = "0.5"
        (run / "checkpoint.json").write_text(json.dumps(checkpoint))
        return
    (run / "checkpoints").mkdir(parents=True)
    saved = dict(timesteps=256, simulated_steps=512, file="checkpoints/step_00000256.zip", validation_objective=0.5)
    saved |= {"wall_seconds": 1.0 if kind == "ppo-finished" else "1e999"}
    state = {"format": "etmpc-ppo-resume", "version": 1, "task": "battery/trading", "settings": {}, "checkpoints": [saved]}
    if kind == "ppo-finished":
        state |= dict(format="etmpc-ppo-run", workers=1, environment_steps=256, simulated_steps=512, wall_seconds=1.0)
        state |= dict(selected=saved["file"], objective_sense="max", stable_baselines3="2.3.2", torch="2.3.1")
        (run / "training.json").write_text(json.dumps(state))
    elif kind == "ppo-infinite-seconds":
        (run / "checkpoints" / "resume.json").write_text(json.dumps(state).replace('"1e999"', "1e999"))
    else:
        from etmpc.learning.selftrigger import SelfSettings

        (run / "checkpoints").rmdir()
        hyper = dict(SelfSettings().to_json(), system="cart_pendulum/balance", recompute_price=0.1, base="every:3")
        hyper |= dict(base_selection={"every:3": 1.0}, labelled_solves=1, best_keep_counts={"3": 1}, chosen="ridge 0.1")
        policy = {"format": "etmpc-self-trigger", "version": 1, "domain": "cart_pendulum/balance", "candidates": [1, 3]}
        policy |= {"theta": [[0.0, 0.0], [1.0, 0.0]], "mean": [0.0], "scale": [1.0]}
        (run / "selected.json").write_text(json.dumps(policy | {"hyperparameters": hyper | {"validation": {"ridge 0.1": 1.0}}}))


def _setup(kind: str, d: Path) -> None:
    if kind == "existing-json":
        (d / "ev.json").write_text('{"mine": true}\n')
    elif kind == "file-parent":
        (d / "afile").write_text("not a directory\n")
    elif kind == "a-dir":
        (d / "out.json").mkdir()
        (d / "out.rrd").mkdir()
    elif kind == "user-dir":
        (d / "run").mkdir()
        (d / "run" / "notes.txt").write_text("my notes\n")
    elif kind == "reproduce-dir":
        (d / "run").mkdir()
        (d / "run" / "settings.json").write_text('{"settings": {}, "domains": []}\n')
        (d / "run" / "REPORT.md").write_text("# a report\n")
    elif kind == "train-dir":
        (d / "run").mkdir()
        (d / "run" / "checkpoint.json").write_text("{}\n")
        (d / "run" / "curve.json").write_text("{}\n")
    elif kind == "bad-settings":
        (d / "run").mkdir()
        (d / "run" / "settings.json").write_text("{not json")
    elif kind == "user-task-dir":  # a task's folder in a run directory: DOMAIN/TASK
        (d / "run" / "battery" / "trading").mkdir(parents=True)
        (d / "run" / "battery" / "trading" / "notes.txt").write_text("my notes\n")
    elif kind == "other-sweep":
        (d / "run" / "battery" / "trading").mkdir(parents=True)
        settings = '{"format": "etmpc-sweep", "domain": "battery/trading", "settings": {}}\n'
        (d / "run" / "battery" / "trading" / "settings.json").write_text(settings)
    elif kind == "corrupt-policy":
        (d / "p.json").write_text('{"format": "etmpc-logistic-policy", "theta": [1, 2')
    elif kind == "huge-theta":
        _policy_file(d, "p.json", _overflowing)
    elif kind == "nan-theta":
        _policy_file(d, "p.json", lambda data: data.update(theta=[float("nan")] * len(data["theta"])))
    elif kind == "ts-no-sha":
        _write_testset(d, "ts.npz").with_name("ts.npz.sha256").unlink()
    elif kind == "ts-empty":
        (d / "ts.npz").write_bytes(b"")
        (d / "ts.npz.sha256").write_text(f"{ts_mod.hashlib.sha256(b'').hexdigest()}  ts.npz\n")
    elif kind == "ts-short-disturbance":
        _write_testset(d, "ts.npz", lambda a, m: ({**a, "disturbance": a["disturbance"][:, :50]}, m))
    elif kind == "ts-count-mismatch":
        _write_testset(d, "ts.npz", lambda a, m: ({**a, "disturbance": a["disturbance"][:3]}, m))
    elif kind == "ts-missing-array":
        _write_testset(d, "ts.npz", lambda a, m: ({"initial_state": a["initial_state"]}, m))
    elif kind == "ts-other-task":
        _write_testset(d, "ts.npz", lambda a, m: (a, dict(m, domain="battery", task="trading")))
    elif kind == "ts-nan":
        _write_testset(d, "ts.npz", lambda a, m: ({**a, "initial_state": a["initial_state"] * np.nan}, m))
    elif kind == "ts-bad-meta":
        _write_testset(d, "ts.npz", lambda a, m: (a, dict(m, episodes="five")))
    elif kind == "ts-corrupt":
        path = _write_testset(d, "ts.npz")
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0xFF
        path.write_bytes(bytes(data))
    elif kind == "rrd-garbage":
        (d / "r.rrd").write_bytes(b"RRF2" + bytes(range(256)) * 8)
    elif kind == "text-file":
        (d / "r.rrd").write_text("hello\n")
    elif kind == "deep-files":  # nested past Python's JSON and YAML readers (a RecursionError there)
        (d / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
        (d / "deep.yml").write_text("episodes: " + "[" * 100_000 + "]" * 100_000 + "\n")
    elif kind == "wrong-types":  # a card and an evaluation of this suite's shape, with text where numbers go
        from etmpc.evaluation.references import SUITE_VERSION, stored

        reference = {"stored": "x", "episodes": 4, "test_set_sha256": stored("battery", 4).test_set_sha256}
        card = {"format": "etmpc-scorecard", "suite_version": SUITE_VERSION, "tasks": ["battery"]}
        card |= {"task_versions": {"battery": 1}, "references": {"battery": reference}, "aggregates": []}
        row = dict(task="battery", policy="always", episodes=4, objective_mean=0.8, objective_sense="max", recomputes_mean=100)
        row |= dict(failures_mean=0.0, solver_failures=0, nonfinite_episodes=0, score="1", score_ci95=0.0, episode_scores=[0.0])
        row |= dict(better_share=0.0, cpu_ms={}, reference="every:1")
        (d / "card.json").write_text(json.dumps(card | {"rows": [row]}))
        evaluation = {"domain": "cart_pendulum", "task": "balance", "test_set": {"path": "t.npz", "sha256": "0"}, "seed": 0}
        (d / "ev.json").write_text(json.dumps(evaluation | {"policies": {}, "runs": "every:2"}))
    elif kind == "hostile-cards":  # a well-formed card of this suite (its numbers aside), and each one field changed
        _hostile_cards(d)
    elif kind in ("train-text-in-curve", "ppo-finished", "ppo-infinite-seconds", "self-finished"):
        _saved_run(kind, d / "run")
    elif kind.startswith("py-"):
        (d / f"{kind.replace('-', '_')}.py").write_text(TRIGGERS[kind])
    elif kind != "none":
        raise AssertionError(kind)


def _hostile_cards(d: Path) -> None:
    """``NAME.json`` for each of :data:`CARD_EDITS`: a card of this suite's shape (one row of 4 episodes, its
    numbers not consistent: every case is refused before they are read) with that edit, and the module a ``py:``
    row names, which leaves a file behind if it is ever imported."""
    from etmpc.evaluation.references import SUITE_VERSION, stored

    sha = stored("battery", 4).test_set_sha256
    reference = {"stored": "battery/trading/references.json", "episodes": 4, "test_set_sha256": sha}
    card = {"format": "etmpc-scorecard", "suite_version": SUITE_VERSION, "tasks": ["battery/trading"]}
    card |= {"task_versions": {"battery/trading": 1}, "references": {"battery/trading": reference}}
    four = [0.5, 0.6, 0.7, 0.8]
    row = dict(task="battery/trading", policy="every:3", episodes=4, objective_mean=0.6, objective_sense="max")
    row |= dict(recomputes_mean=34.0, failures_mean=0.0, solver_failures=0, nonfinite_episodes=0, score=1.0, score_ci95=0.5)
    row |= dict(episode_scores=four, better_share=0.5, cpu_ms={}, reference="every:1", task_version=1, failures_ci95=0.0)
    row |= dict(episode_failures=[0] * 4, episode_objectives=four, episode_recomputes=[34] * 4, episode_solver_failures=[0] * 4)
    aggregate = dict(policy="every:3", tasks=1, iqm=1.0, iqm_ci95=[0.0, 2.0])
    aggregate |= dict(probability_of_improvement=0.5, probability_of_improvement_ci95=[0.0, 1.0])
    card |= {"rows": [row], "aggregates": [aggregate], "machine": {"processor": "x86_64", "system": "Linux", "libm": "fma"}}
    for name, edit in CARD_EDITS.items():
        edited = json.loads(json.dumps(card))
        edit(edited)
        (d / f"{name}.json").write_text(json.dumps(edited))
    (d / "card_code.py").write_text("open('imported', 'w').write('the card ran me')\nT = None\n")


def _carried(card: dict, options: dict | None = None, task: str = "battery/trading") -> None:
    """The card's references made those of a task scored with options (``options``; else one that exists, and the
    best schedule's objectives one short); ``task``: the card made one of that task."""
    if task != "battery/trading":
        from etmpc.evaluation.references import stored
        from etmpc.systems import task_version

        card |= {"tasks": [task], "task_versions": {task: task_version(task)}}
        card["references"] = {task: card["references"].pop("battery/trading")}
        card["references"][task]["test_set_sha256"] = stored(task, 4).test_set_sha256
        card["rows"][0]["task"] = task
    ref = card["references"][task]
    ref |= {"stored": None, "options": options or {"lqr_input_weight": "0.2"}, "best_objectives": [1.0] * (4 if options else 3)}
    ref |= {"oracle_objectives": [2.0] * 4, "objective_sense": "max", "best_periodic": "every:1"}
    ref |= {"oracle": "oracle:every:1", "recompute_price": 0.0, "gap": 1.0}


CARD_EDITS = {
    "as_it_is": lambda c: None,
    "machine_list": lambda c: c.update(machine=["x86_64"]),
    "libm_list": lambda c: c["machine"].update(libm=["fma"]),
    "libm_unknown": lambda c: c["machine"].update(libm="avx512"),
    "objectives_empty": lambda c: c["rows"][0].update(episode_objectives=[]),
    "aggregates_number": lambda c: c.update(aggregates=3),
    "aggregate_policy_list": lambda c: c["aggregates"][0].update(policy=["every:3"]),
    "task_versions_list": lambda c: c.update(task_versions=[1]),
    "carried_short": _carried,
    "planted_solver": lambda c: _carried(c, {"solver.qpsol": "planted"}, "cart_pendulum/kicks"),
    "row_episodes_list": lambda c: c["rows"][0].update(episodes=[4]),
    "py_row": lambda c: [e.update(policy="py:card_code:T") for e in (*c["rows"], *c["aggregates"])],
    "py_row_shielded": lambda c: [e.update(policy="shield:4:py:card_code:T") for e in (*c["rows"], *c["aggregates"])],
}


# Triggers of a hostile user's, each a module of its own (py:MODULE:NAME), named after its setup.
_RULE = "    spec = 'mine'\n    stochastic = False\n"
TRIGGERS = {
    "py-exit-in-decide": f"class T:\n{_RULE}    def decide(self, s, rng):\n        raise SystemExit(3)\n",
    "py-exit-on-import": "raise SystemExit(4)\n",
    "py-exit-in-factory": "def T():\n    raise SystemExit(5)\n",
    "py-exit-in-a-member": "class T:\n    spec = 'mine'\n    @property\n    def stochastic(self):\n        raise SystemExit(6)\n"
    "    def decide(self, s, rng):\n        return False\n",
    "py-interrupt-in-decide": f"class T:\n{_RULE}    def decide(self, s, rng):\n        raise KeyboardInterrupt\n",
    "py-base-exception": f"class Boom(BaseException):\n    pass\nclass T:\n{_RULE}"
    "    def decide(self, s, rng):\n        raise Boom('out of here')\n",
    "py-import-fails": "import no_such_module_anywhere\n",
    "py-writes-into-state": f"class T:\n{_RULE}    def decide(self, s, rng):\n        s.x[1] = 0.0\n        return False\n",
    "py-writes-into-observation": f"class T:\n{_RULE}    def decide(self, s, rng):\n"
    "        s.observation['soc'] = 1.0\n        return False\n",
    "py-unpicklable": f"import threading\nclass T:\n{_RULE}    def __init__(self):\n        self.lock = threading.Lock()\n"
    "    def decide(self, s, rng):\n        return s.age >= 3\n",
}


# -- the in-process cases: (id, setup, argv, what the line must name) -------------------------------
EV = ["evaluate", "--task", "cart_pendulum"]
CASES = [
    # names and policies
    ("unknown-task", "none", ["evaluate", "--task", "cartpole", "--policy", "always"], "cartpole"),
    ("unknown-policy", "none", [*EV, "--policy", "sometimes"], "sometimes"),
    ("every-zero", "none", [*EV, "--policy", "every:0"], "every:0"),
    ("every-text", "none", [*EV, "--policy", "every:x"], "every:x"),
    ("threshold-negative", "none", [*EV, "--policy", "threshold:-1"], "threshold:-1"),
    ("threshold-nan", "none", [*EV, "--policy", "threshold:nan"], "threshold:nan"),
    ("threshold-inf", "none", [*EV, "--policy", "threshold:inf"], "threshold:inf"),
    ("rl-missing", "none", [*EV, "--policy", "rl:no/such.json"], "no/such.json"),
    ("rl-corrupt", "corrupt-policy", [*EV, "--policy", "rl:p.json"], "p.json"),
    ("rl-other-domain", "none", [*EV, "--policy", f"rl:{BATTERY_POLICY}"], "battery"),
    ("rl-nan-theta", "nan-theta", [*EV, "--policy", "rl:p.json"], "p.json"),
    (
        "rl-overflowing-theta",
        "huge-theta",
        [*EV, "--policy", "rl:p.json", "--episodes", "1", "--workers", "1"],
        "p.json: theta[0] is 1e+308, beyond",
    ),
    ("rollout-bad-k", "none", [*EV, "--policy", "rollout:every:3:0"], "rollout:every:3:0"),
    ("oracle-of-oracle", "none", [*EV, "--policy", "oracle:oracle:always"], "oracle:oracle:always"),
    ("policy-twice", "none", [*EV, "--policy", "always", "--policy", "always"], "twice"),
    # numbers
    ("episodes-zero", "none", [*EV, "--policy", "always", "--episodes", "0"], "--episodes"),
    ("episodes-negative", "none", [*EV, "--policy", "always", "--episodes", "-3"], "--episodes"),
    ("episodes-too-many", "none", [*EV, "--policy", "always", "--episodes", "1000"], "1000"),
    ("repeats-zero", "none", [*EV, "--policy", "always", "--repeats", "0"], "--repeats"),
    ("workers-zero", "none", [*EV, "--policy", "always", "--workers", "0"], "--workers"),
    ("workers-absurd", "none", [*EV, "--policy", "always", "--workers", "1000000000000"], "--workers"),
    ("seed-negative", "none", [*EV, "--policy", "always", "--seed", "-1"], "--seed"),
    ("seed-text", "none", [*EV, "--policy", "always", "--seed", "one"], "--seed"),
    ("seed-huge", "none", [*EV, "--policy", "always", "--seed", str(2**64)], "--seed"),
    # test sets
    ("testset-missing", "none", [*EV, "--policy", "always", "--test-set", "nope.npz"], "nope.npz"),
    ("testset-no-checksum", "ts-no-sha", [*EV, "--policy", "always", "--test-set", "ts.npz"], "sha256"),
    ("testset-empty", "ts-empty", [*EV, "--policy", "always", "--test-set", "ts.npz"], "ts.npz"),
    ("testset-short-disturbance", "ts-short-disturbance", [*EV, "--policy", "always", "--test-set", "ts.npz"], "disturbances"),
    ("testset-count-mismatch", "ts-count-mismatch", [*EV, "--policy", "always", "--test-set", "ts.npz"], "disturbance"),
    ("testset-missing-array", "ts-missing-array", [*EV, "--policy", "always", "--test-set", "ts.npz"], "disturbance"),
    ("testset-other-task", "ts-other-task", [*EV, "--policy", "always", "--test-set", "ts.npz"], "battery"),
    ("testset-nan", "ts-nan", [*EV, "--policy", "always", "--test-set", "ts.npz"], "finite"),
    ("testset-bad-meta", "ts-bad-meta", [*EV, "--policy", "always", "--test-set", "ts.npz"], "episodes"),
    ("testset-corrupt", "ts-corrupt", [*EV, "--policy", "always", "--test-set", "ts.npz"], "corrupted"),
    # outputs
    ("json-is-directory", "a-dir", [*EV, "--policy", "always", "--json", "out.json"], "directory"),
    ("json-parent-is-file", "file-parent", [*EV, "--policy", "always", "--json", "afile/ev.json"], "afile"),
    ("record-parent-is-file", "file-parent", [*EV, "--policy", "always", "--record", "afile/r.rrd"], "afile"),
    ("record-is-directory", "a-dir", [*EV, "--policy", "always", "--record", "out.rrd"], "directory"),
    ("record-not-rrd", "none", [*EV, "--policy", "always", "--record", "r.txt"], ".rrd"),
    ("json-and-record-same", "existing-json", [*EV, "--policy", "always", "--record", "ev.rrd", "--json", "ev.rrd"], "same file"),
    ("json-overwrites-testset", "ts-no-sha", [*EV, "--policy", "always", "--test-set", "ts.npz", "--json", "ts.npz"], "ts.npz"),
    ("replay-json-overwrites-recording", "rrd-garbage", ["replay", "r.rrd", "--json", "r.rrd"], "r.rrd"),
    ("bench-json-parent-is-file", "file-parent", ["bench", "--task", "battery", "--json", "afile/b.json"], "afile"),
    # backends
    ("backend-unknown", "none", [*EV, "--policy", "always", "--backend", "slurm"], "--backend"),
    ("address-without-ray", "none", [*EV, "--policy", "always", "--address", "auto"], "--address"),
    # the command itself
    ("no-command", "none", [], "command"),
    ("unknown-command", "none", ["evalute"], "evalute"),
    ("unknown-option", "none", [*EV, "--policy", "always", "--fast"], "--fast"),
    # train
    ("train-unknown-task", "none", ["train", "--task", "pendulum", "--out", "run"], "pendulum"),
    ("train-out-is-file", "file-parent", ["train", "--task", "battery", "--out", "afile"], "afile"),
    ("train-into-user-directory", "user-dir", ["train", "--task", "battery", "--out", "run", "--episodes", "2"], "notes.txt"),
    ("train-resume-into-reproduce", "reproduce-dir", ["train", "--task", "battery", "--out", "run", "--resume"], "settings.json"),
    ("train-seeds-reversed", "none", ["train", "--task", "battery", "--out", "run", "--seeds", "4-1"], "--seeds"),
    ("train-seeds-absurd", "none", ["train", "--task", "battery", "--out", "run", "--seeds", "0-100000000000"], "--seeds"),
    (
        "train-learning-rate-nan",
        "none",
        ["train", "--task", "battery", "--out", "run", "--algorithm", "gpomdp", "--learning-rate", "nan"],
        "learning_rate must be a number (finite), got nan",
    ),
    (
        "train-dpi-option-with-gpomdp",
        "none",
        ["train", "--task", "battery", "--out", "run", "--algorithm", "gpomdp", "--futures", "3"],
        "--futures",
    ),
    ("train-record-negative", "none", ["train", "--task", "battery", "--out", "run", "--record", "-1"], "--record"),
    (
        "train-eval-episodes-too-many",
        "none",
        ["train", "--task", "battery", "--out", "run", "--eval-episodes", "1000", "--episodes", "2", "--seeds", "0"],
        "1000",
    ),
    # files and settings a user hands in: read by one reader, checked by one check
    (
        "settings-nested-too-deep",
        "deep-files",
        ["train", "--task", "battery", "--out", "run", "--settings", "deep.json"],
        "nested",
    ),
    (
        "settings-yaml-nested-too-deep",
        "deep-files",
        ["train", "--task", "battery", "--out", "run", "--settings", "deep.yml"],
        "nested",
    ),
    ("verify-card-nested-too-deep", "deep-files", ["verify", "deep.json"], "nested too deeply"),
    ("figure-evaluation-nested-too-deep", "deep-files", ["figure", "bars", "deep.json", "--out", "x.png"], "nested"),
    (
        "train-set-nan-ridge",
        "none",
        ["train", "--task", "battery", "--out", "run", "--set", "ridge=.nan"],
        "ridge must be a number",
    ),
    ("train-set-bool-episodes", "none", ["train", "--task", "battery", "--out", "run", "--set", "episodes=true"], "got True"),
    (
        "train-set-count-overflows",
        "none",
        ["train", "--task", "battery", "--out", "run", "--set", f"episodes={10**23}"],
        "in -1e9..1e9",
    ),
    (
        "train-ppo-bad-reward-baseline",
        "none",
        ["train", "--task", "battery", "--out", "run", "--algorithm", "ppo", "--set", "reward_baseline=bogus"],
        "reward_baseline",
    ),
    # a run handed to --resume is data, and resumed only as the run it was
    (
        "train-resume-text-in-curve",
        "train-text-in-curve",
        ["train", "--task", "battery", "--algorithm", "gpomdp", *TINY_RUN, "--out", "run", "--resume"],
        "checkpoint.json is corrupt (curve[0].objective must be a number (finite), got '0.5')",
    ),
    (
        "train-resume-ppo-finished-at-another-price",
        "ppo-finished",
        ["train", "--task", "battery", "--algorithm", "ppo", "--price", "0.5", "--out", "run", "--resume"],
        "holds a ppo run on battery/trading, not battery/trading@0.5",
    ),
    (
        "train-resume-ppo-infinite-seconds",
        "ppo-infinite-seconds",
        ["train", "--task", "battery", "--algorithm", "ppo", "--out", "run", "--resume"],
        "checkpoints[0].wall_seconds must be a number (finite), got inf",
    ),
    (
        "train-resume-self-finished-at-another-price",
        "self-finished",
        ["train", "--task", "cart_pendulum", "--algorithm", "self", "--price", "0.5", "--out", "run", "--resume"],
        "holds a self run on cart_pendulum/balance, not cart_pendulum/balance@0.5",
    ),
    ("verify-row-text-score", "wrong-types", ["verify", "card.json"], "score must be a number, got '1'"),
    # a card is evidence: every field of its type, and no code run that the card alone names
    ("verify-machine-not-an-object", "hostile-cards", ["verify", "machine_list.json"], "machine must be an object"),
    ("verify-libm-a-list", "hostile-cards", ["verify", "libm_list.json"], "machine.libm must be one of fma, sse2, other"),
    ("verify-libm-unknown", "hostile-cards", ["verify", "libm_unknown.json"], "machine.libm must be one of fma, sse2, other"),
    ("verify-objectives-empty", "hostile-cards", ["verify", "objectives_empty.json"], "episode_objectives holds 0 values"),
    ("verify-aggregates-a-number", "hostile-cards", ["verify", "aggregates_number.json"], "aggregates must be a list"),
    ("verify-aggregate-policy-list", "hostile-cards", ["verify", "aggregate_policy_list.json"], "aggregates[0].policy must be"),
    ("verify-task-versions-list", "hostile-cards", ["verify", "task_versions_list.json"], "task_versions must be an object"),
    (
        "verify-carried-references-short",
        "hostile-cards",
        ["verify", "carried_short.json"],
        "references.battery/trading.best_objectives must be a list of 4 finite numbers",
    ),
    (
        "verify-options-name-a-planted-solver",
        "hostile-cards",
        ["verify", "planted_solver.json"],
        "references.cart_pendulum/kicks.options: option solver.qpsol: 'planted' is not one of",
    ),
    (
        "leaderboard-card-episodes-a-list",
        "hostile-cards",
        ["score", "--leaderboard", "--out", "lb", "--card", "row_episodes_list.json"],
        "episodes",
    ),
    ("verify-py-row-not-allowed", "hostile-cards", ["verify", "py_row.json"], "--allow-code py:card_code:T"),
    (
        "verify-py-row-inner-spec-allowed-only",
        "hostile-cards",
        ["verify", "py_row_shielded.json", "--allow-code", "py:card_code:T"],
        "--allow-code shield:4:py:card_code:T",
    ),
    ("figure-runs-text", "wrong-types", ["figure", "bars", "ev.json", "--out", "x.png"], "ev.json is not an etmpc evaluation"),
    (
        "leaderboard-readme-in-policies",
        "none",
        ["score", "--leaderboard", "--out", "lb", "--readme", str(CART_POLICY)],
        "etmpc's data folder",
    ),
    # reproduce
    ("reproduce-out-is-file", "file-parent", ["reproduce", "--out", "afile"], "afile"),
    ("reproduce-into-training-run", "train-dir", ["reproduce", "--quick", "--out", "run"], "checkpoint.json"),
    ("reproduce-into-user-directory", "user-dir", ["reproduce", "--quick", "--out", "run"], "notes.txt"),
    ("reproduce-unreadable-settings", "bad-settings", ["reproduce", "--quick", "--out", "run"], "settings.json"),
    # render
    ("render-battery", "none", ["render", "--task", "battery", "--policy", "always", "--out", "v.mp4"], "battery"),
    ("render-not-mp4", "none", ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.avi"], ".mp4"),
    (
        "render-episode-negative",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--episode", "-1"],
        "--episode",
    ),
    (
        "render-episode-out-of-range",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--episode", "100"],
        "100",
    ),
    (
        "render-odd-width",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--width", "641"],
        "641",
    ),
    (
        "render-fps-absurd",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--fps", "1e9"],
        "--fps",
    ),
    (
        "render-fps-zero",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--fps", "0"],
        "--fps",
    ),
    (
        "render-seed-negative",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "v.mp4", "--seed", "-1"],
        "--seed",
    ),
    (
        "render-out-parent-is-file",
        "file-parent",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", "afile/v.mp4"],
        "afile",
    ),
    # sweep, and prices
    ("price-negative", "none", [*EV, "--policy", "always", "--price", "-1"], "--price"),
    ("price-infinite", "none", [*EV, "--policy", "always", "--price", "inf"], "--price"),
    ("train-price-nan", "none", ["train", "--task", "battery", "--out", "run", "--price", "nan"], "--price"),
    ("sweep-price-nan", "none", ["sweep", "--task", "battery", "--prices", "0,nan"], "--prices"),
    ("sweep-price-text", "none", ["sweep", "--task", "battery", "--prices", "1e-4,cheap"], "cheap"),
    ("sweep-price-twice", "none", ["sweep", "--task", "battery", "--prices", "1e-4,0.0001"], "twice"),
    ("sweep-task-twice", "none", ["sweep", "--task", "battery", "--task", "battery"], "twice"),
    ("sweep-unknown-task", "none", ["sweep", "--task", "cartpole"], "cartpole"),
    ("sweep-episodes-too-many", "none", ["sweep", "--task", "battery", "--episodes", "1000"], "1000"),
    (
        "sweep-into-user-directory",
        "user-task-dir",
        ["sweep", "--task", "cart_pendulum", "--task", "battery", "--out", "run"],
        "notes.txt",
    ),
    # self-triggering policies
    ("self-missing", "none", [*EV, "--policy", "self:no/such.json"], "no/such.json"),
    ("self-given-a-logistic-policy", "none", [*EV, "--policy", f"self:{CART_POLICY}"], "not a self-trigger policy"),
    ("self-corrupt", "corrupt-policy", [*EV, "--policy", "self:p.json"], "p.json"),
    ("self-no-path", "none", [*EV, "--policy", "self:"], "self:PATH"),
    ("train-self-out-is-a-directory", "a-dir", ["train-self", "--task", "cart_pendulum", "--out", "out.json"], "out.json"),
    ("train-self-unknown-task", "none", ["train-self", "--task", "cartpole", "--out", "p.json"], "cartpole"),
    ("train-self-negative-price", "none", ["train-self", "--task", "battery", "--out", "p.json", "--price", "-1"], "--price"),
    ("sweep-other-settings", "other-sweep", ["sweep", "--task", "battery", "--out", "run", "--quick"], "other settings"),
    # replay and bench
    ("replay-missing", "none", ["replay", "none.rrd"], "none.rrd"),
    ("replay-garbage", "rrd-garbage", ["replay", "r.rrd"], "r.rrd"),
    ("replay-text", "text-file", ["replay", "r.rrd"], "r.rrd"),
    ("replay-json-is-directory", "a-dir", ["replay", "r.rrd", "--json", "out.json"], "directory"),
    ("bench-unknown-task", "none", ["bench", "--task", "cartpole"], "cartpole"),
    ("bench-episodes-too-many", "none", ["bench", "--task", "battery", "--episodes", "1000", "--no-reference"], "1000"),
    # a trigger's own code cannot end the command, silently or otherwise, nor change its own run
    (
        "py-exit-in-decide",
        "py-exit-in-decide",
        [*EV, "--policy", "py:py_exit_in_decide:T", "--episodes", "1", "--workers", "1", "--json", "ev.json"],
        "SystemExit(3)",
    ),
    (
        "py-exit-in-decide-on-a-worker",
        "py-exit-in-decide",
        [*EV, "--policy", "py:py_exit_in_decide:T", "--episodes", "2", "--workers", "2", "--json", "ev.json"],
        "SystemExit(3)",
    ),
    ("py-exit-on-import", "py-exit-on-import", [*EV, "--policy", "py:py_exit_on_import:T"], "SystemExit(4)"),
    ("py-exit-in-factory", "py-exit-in-factory", [*EV, "--policy", "py:py_exit_in_factory:T"], "SystemExit(5)"),
    ("py-exit-in-a-member", "py-exit-in-a-member", [*EV, "--policy", "py:py_exit_in_a_member:T"], "SystemExit(6)"),
    (
        "py-interrupt-in-decide",
        "py-interrupt-in-decide",
        [*EV, "--policy", "py:py_interrupt_in_decide:T", "--episodes", "1", "--workers", "1", "--record", "r.rrd"],
        "KeyboardInterrupt",
    ),
    (
        "py-base-exception",
        "py-base-exception",
        [*EV, "--policy", "py:py_base_exception:T", "--episodes", "1", "--workers", "1"],
        "Boom: out of here",
    ),
    ("py-import-fails", "py-import-fails", [*EV, "--policy", "py:py_import_fails:T"], "no_such_module_anywhere"),
    (
        "py-writes-into-state",
        "py-writes-into-state",
        [*EV, "--policy", "py:py_writes_into_state:T", "--episodes", "1", "--workers", "1"],
        "read-only",
    ),
    (
        "py-writes-into-observation",
        "py-writes-into-observation",
        ["evaluate", "--task", "battery", "--policy", "py:py_writes_into_observation:T", "--episodes", "1", "--workers", "1"],
        "read-only",
    ),
    (
        "py-unpicklable-on-workers",
        "py-unpicklable",
        [*EV, "--policy", "py:py_unpicklable:T", "--episodes", "2", "--workers", "2"],
        "--workers 1",
    ),
    # found on the way
    (
        "render-beyond-the-framebuffer",
        "none",
        ["render", "--task", "reacher", "--policy", "always", "--out", "v.mp4", "--width", "2560", "--height", "1440"],
        "framebuffer",
    ),
    (
        "reproduce-task-twice",
        "none",
        ["reproduce", "--quick", "--task", "battery", "--task", "battery/trading", "--out", "run"],
        "twice",
    ),
    ("sweep-task-twice-by-two-names", "none", ["sweep", "--task", "battery", "--task", "battery/trading"], "twice"),
    ("sweep-other-settings-named", "other-sweep", ["sweep", "--task", "battery", "--out", "run", "--quick"], "settings.episodes"),
]


def refused_in_one_line(argv: list[str], names: str, root: Path, capsys, within=contextlib.nullcontext()) -> None:
    """``etmpc ARGV``, run in this process in ``root`` (the case's directory, set up) ``within`` a context (an
    alarm, say), is refused as the tool promises: exit code 2, one line on stderr naming ``names``, every file
    under ``root`` as it was (nothing new, no partial file) and no process left behind."""
    before, processes = _files(root), set(_children(os.getpid()))  # earlier tests' helpers may live on
    with warnings.catch_warnings(record=True) as caught, within:  # a warning would be a second line on stderr
        warnings.simplefilter("always")
        code = main(list(argv))
    _, err = capsys.readouterr()
    assert code == 2, err
    _assert_one_line(err + "".join(f"{w.message}\n" for w in caught), names)
    assert _files(root) == before
    assert set(_children(os.getpid())) <= processes


@pytest.mark.parametrize("setup, argv, names", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_hostile_input_is_one_line_and_touches_nothing(setup, argv, names, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)  # importing a py: trigger writes nothing either
    _setup(setup, tmp_path)
    refused_in_one_line(argv, names, tmp_path, capsys)


# -- faults that need a real process -------------------------------------------------------------
def _etmpc(args: list[str], cwd: Path, env: dict | None = None, file_size_limit: int | None = None, **popen) -> subprocess.Popen:
    """``etmpc ARGS`` in its own session; ``file_size_limit`` bytes per file (RLIMIT_FSIZE): the
    kernel refuses writes past it as it does on a full disk."""

    def limit():
        # Ctrl-C as a terminal delivers it: a command started in the background of a non-interactive
        # shell (`cmd &`, as a CI script may run the suite) inherits SIGINT ignored, and so would etmpc.
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if file_size_limit is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a refused write, not a killed process
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

    full_env = {**os.environ, "MUJOCO_GL": "egl", **(env or {})}
    return subprocess.Popen(
        [sys.executable, "-m", "etmpc.cli", *args],
        cwd=cwd,
        env=full_env,
        preexec_fn=limit,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        **popen,
    )


@pytest.mark.parametrize(
    "args, names",
    [
        (
            ["evaluate", "--task", "battery", "--policy", "always", "--episodes", "2", "--workers", "1", "--json", "ev.json"],
            "ev.json",
        ),
        (
            ["evaluate", "--task", "battery", "--policy", "always", "--episodes", "2", "--workers", "1", "--record", "new.rrd"],
            "new.rrd",
        ),
        (
            [
                "train",
                "--task",
                "battery",
                "--out",
                "run",
                "--episodes",
                "2",
                "--eval-every",
                "2",
                "--eval-episodes",
                "1",
                "--seeds",
                "0",
                "--validation-episodes",
                "1",
                "--labels",
                "1",
                "--futures",
                "1",
                "--horizon",
                "2",
                "--workers",
                "1",
            ],
            "run",
        ),
    ],
    ids=["json", "record", "train"],
)
def test_a_full_disk_is_one_line_and_leaves_the_old_files(args, names, tmp_path, request):
    kind = request.node.callspec.id
    _setup("existing-json", tmp_path)
    before = _files(tmp_path)
    # The check before the run writes 4 kB: a limit of 5 bytes fails it (no work is done), 5 kB
    # passes it and fails the checkpoint, 50 kB fails the recording.
    limit = {"json": 5, "record": 50_000, "train": 5_000}[kind]
    proc = _etmpc(args, tmp_path, file_size_limit=limit)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err
    _assert_one_line(err, names)
    after = _files(tmp_path)
    assert {k: v for k, v in after.items() if k in before} == before
    leftovers = [k for k in after if k not in before and (".tmp" in k or ".partial" in k or k.endswith(".rrd"))]
    assert leftovers == []


@pytest.mark.parametrize("backend, names", [("bogus", "MUJOCO_GL=bogus"), ("glfw", "DISPLAY")])
def test_a_rendering_backend_that_cannot_work_is_one_line(backend, names, tmp_path):
    env = {"MUJOCO_GL": backend}
    proc = _etmpc(["render", "--task", "cart_pendulum", "--policy", "never", "--out", "v.mp4"], tmp_path, env=env)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, err
    _assert_one_line(err, names)
    assert _files(tmp_path) == {}


def test_a_truncated_recording_is_an_error(tmp_path):
    recording = tmp_path / "r.rrd"
    assert (
        main(
            [
                "evaluate",
                "--task",
                "battery",
                "--policy",
                "always",
                "--policy",
                "every:5",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--record",
                str(recording),
            ]
        )
        == 0
    )
    data = recording.read_bytes()
    for cut in (len(data) // 3, len(data) - 100):
        (tmp_path / "cut.rrd").write_bytes(data[:cut])
        proc = _etmpc(["replay", "cut.rrd"], tmp_path)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, err
        _assert_one_line(err, "cut.rrd")


@pytest.mark.parametrize(
    "how, code, line", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated"), ("SIGKILL", -9, None)]
)
def test_stopping_a_parallel_run_leaves_no_worker_and_no_file(how, code, line, tmp_path):
    _setup("existing-json", tmp_path)
    before = _files(tmp_path)
    proc = _etmpc(
        ["evaluate", "--task", "cart_pendulum", "--policy", "always", "--workers", "2", "--json", "ev.json", "--record", "r.rrd"],
        tmp_path,
    )
    deadline = time.monotonic() + 120
    workers = []
    while time.monotonic() < deadline and len(workers) < 2:  # the pool is up and working
        time.sleep(0.5)
        workers = [p for p in _children(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text(errors="replace")]
    assert len(workers) >= 2
    time.sleep(2)
    sig = getattr(signal, how)
    # Ctrl-C reaches the whole process group, as a terminal sends it; the others only the command.
    os.killpg(proc.pid, sig) if how == "SIGINT" else os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    if line is not None:
        _assert_one_line(err, line)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(Path(f"/proc/{w}").exists() for w in workers):
        time.sleep(0.2)
    assert not [
        w for w in workers if Path(f"/proc/{w}").exists() and Path(f"/proc/{w}/stat").read_text().split(") ")[1][0] != "Z"
    ]
    after = _files(tmp_path)
    assert {k: v for k, v in after.items() if k in before} == before
    if how != "SIGKILL":  # SIGKILL leaves the recording's partial file: nothing runs to remove it
        assert set(after) == set(before)


def test_version():
    proc = subprocess.run([sys.executable, "-m", "etmpc.cli", "--version"], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.startswith("etmpc ")


# -- the Python API: the same checks, the same messages, as EtmpcError -----------------------------
class _Unpicklable:
    spec, stochastic = "unpicklable", False

    def __init__(self):
        self.rule = lambda s: s.age >= 3

    def decide(self, s, rng):
        return self.rule(s)


API_CASES = [  # (id, keyword arguments, what the message says, the command line's options for the same input)
    ("workers-zero", {"workers": 0}, "workers: must be >= 1, got 0", ["--workers", "0"]),
    ("workers-absurd", {"workers": 10**12}, "workers: at most 512 worker processes", ["--workers", str(10**12)]),
    ("workers-fraction", {"workers": 1.5}, "workers: 1.5 is not a whole number", None),
    ("episodes-fraction", {"episodes": 1.5}, "episodes: 1.5 is not a whole number", None),
    ("episodes-zero", {"episodes": 0}, "episodes: must be >= 1, got 0", ["--episodes", "0"]),
    ("episodes-a-bool", {"episodes": True}, "episodes: True is not a whole number", None),
    ("repeats-zero", {"repeats": 0}, "repeats: must be >= 1, got 0", ["--repeats", "0"]),
    ("seed-negative", {"seed": -1}, "seed: a seed is a whole number in 0..2**63-1, got -1", ["--seed", "-1"]),
    ("seed-huge", {"seed": 2**64}, "seed: a seed is a whole number in 0..2**63-1", ["--seed", str(2**64)]),
    ("seed-text", {"seed": "1"}, "seed: '1' is not a whole number", None),
    (
        "price-nan",
        {"recompute_price": float("nan")},
        "a price of a recompute is a finite number >= 0, got nan",
        ["--price", "nan"],
    ),
    ("price-text", {"recompute_price": "0.1"}, "recompute_price: '0.1' is not a number", None),
    (
        "policies-a-string",
        {"policies": "always"},
        "a list of policy specs or objects is needed, got str (for one policy: ['always'])",
        None,
    ),
    ("policies-empty", {"policies": []}, "policies: the list is empty", None),
    ("policies-a-dict", {"policies": {"always": 1}}, "a list of policy specs or objects is needed, got dict", None),
    ("task-not-a-name", {"task": 3}, "task: a task name (str) is needed, got int 3", None),
    ("record-not-rrd", {"record": "r.txt"}, "r.txt does not end in .rrd", None),
    ("unpicklable-on-workers", {"policies": [_Unpicklable()], "workers": 2}, "workers=1", None),
    ("progress-not-a-bool", {"progress": "yes"}, "progress: True or False", None),
]


@pytest.mark.parametrize("kwargs, says, cli", [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES])
def test_the_python_api_refuses_what_the_command_line_refuses_with_the_same_message(
    kwargs, says, cli, tmp_path, monkeypatch, capsys
):
    import etmpc
    from etmpc.common.errors import EtmpcError

    monkeypatch.chdir(tmp_path)
    arguments = {"task": "battery", "policies": ["always"], "episodes": 1, "workers": 1, "progress": False} | kwargs
    with pytest.raises(EtmpcError) as raised:
        etmpc.evaluate(**arguments)
    message = str(raised.value)
    assert says in message and "\n" not in message
    assert _files(tmp_path) == {}
    if cli is not None:  # the command line's line ends with the same words
        assert main(["evaluate", "--task", "battery", "--policy", "always", *cli]) == 2
        line = capsys.readouterr().err.strip()
        assert line.endswith(message.split(": ", 1)[1]), (line, message)


def test_a_real_ctrl_c_inside_a_triggers_decide_still_stops_the_command(tmp_path):
    """The trigger's own KeyboardInterrupt is its failure (exit 2); the user's Ctrl-C, arriving while the
    trigger decides, is still the user's (exit 130, 'interrupted')."""
    (tmp_path / "slow_trigger.py").write_text(
        "import time\nclass T:\n    spec = 'slow'\n    stochastic = False\n"
        "    def decide(self, s, rng):\n        time.sleep(0.2)\n        return s.age >= 3\n"
    )
    proc = _etmpc(
        ["evaluate", "--task", "battery", "--policy", "py:slow_trigger:T", "--workers", "1", "--json", "ev.json"], tmp_path
    )
    time.sleep(8)  # imports, then deciding: a Ctrl-C now lands inside decide almost surely (it sleeps 0.2 s of each step)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    _assert_one_line(err, "interrupted")
    assert not (tmp_path / "ev.json").exists()


# -- nothing a user types destroys a file: an output is never an input nor in etmpc's data ----------
STORED_REFERENCES = REPO / "tasks" / "battery" / "trading" / "references.json"
STORED_TESTSET = REPO / "tasks" / "cart_pendulum" / "balance" / "testset.npz"
SHIPPED_PPO = REPO / "policies" / "cart_pendulum" / "balance" / "ppo.zip"


def _data_files() -> dict[str, bytes | None]:
    """Every file of etmpc's data folders in the checkout (stored test sets, references, models, policies)."""
    return {f"{folder}/{k}": v for folder in ("tasks", "policies", "models") for k, v in _files(REPO / folder).items()}


def _own_setup(kind: str, d: Path) -> None:
    if kind == "mine-json":
        (d / "mine.json").write_text('{"mine": true}\n')
    elif kind == "policy-copy":
        (d / "p.json").write_bytes(CART_POLICY.read_bytes())
    elif kind == "sb3-copy":
        (d / "m.zip").write_bytes(SHIPPED_PPO.read_bytes())
        (d / "m.json").write_bytes(SHIPPED_PPO.with_suffix(".json").read_bytes())
    elif kind == "readme-no-end":
        (d / "R.md").write_text("# mine\n\n<!-- leaderboard:begin -->\n| a table |\n")
    elif kind == "kept-row-a-list":
        (d / "results" / "leaderboard" / "always" / "battery").mkdir(parents=True)
        (d / "results" / "leaderboard" / "always" / "battery" / "trading.json").write_text("[1, 2, 3]\n")
    elif kind == "kept-row-edited":
        from etmpc.common.documents import sealed

        row = sealed({"key": {"spec": "always"}, "row": {"score": -275.8}, "played": {"commit": "abc"}})
        row["row"]["score"] = 99.9  # a better number, typed by hand
        (d / "results" / "leaderboard" / "always" / "battery").mkdir(parents=True)
        (d / "results" / "leaderboard" / "always" / "battery" / "trading.json").write_text(json.dumps(row))
    else:
        _setup(kind, d)


OWN_CASES = [  # (id, setup, argv, what the one line must name)
    (
        "score-json-on-the-stored-references",
        "none",
        ["score", "--policy", "every:3", "--task", "battery", "--json", str(STORED_REFERENCES)],
        "data folder",
    ),
    (
        "score-json-on-the-policy-it-scores",
        "none",
        ["score", "--policy", f"rl:{BATTERY_POLICY}", "--task", "battery", "--json", str(BATTERY_POLICY)],
        "data folder",
    ),
    (
        "score-json-on-a-users-policy-it-scores",
        "policy-copy",
        ["score", "--policy", "rl:p.json", "--task", "cart_pendulum", "--json", "p.json"],
        "policy",
    ),
    ("evaluate-json-on-its-rl-file", "policy-copy", [*EV, "--policy", "rl:p.json", "--json", "p.json"], "p.json"),
    (
        "evaluate-json-on-the-file-a-shield-wraps",
        "policy-copy",
        [*EV, "--policy", "shield:5:rl:p.json", "--json", "p.json"],
        "p.json",
    ),
    (
        "evaluate-json-on-a-rollouts-base-file",
        "policy-copy",
        [*EV, "--policy", "rollout:rl:p.json:2", "--json", "p.json"],
        "p.json",
    ),
    ("evaluate-json-on-the-stored-test-set", "none", [*EV, "--policy", "always", "--json", str(STORED_TESTSET)], "data folder"),
    ("evaluate-json-on-an-sb3-sidecar", "sb3-copy", [*EV, "--policy", "sb3:m.zip", "--json", "m.json"], "m.json"),
    (
        "render-out-into-the-data",
        "none",
        ["render", "--task", "cart_pendulum", "--policy", "always", "--out", str(REPO / "tasks" / "cart_pendulum" / "v.mp4")],
        "data folder",
    ),
    (
        "train-into-the-shipped-policies",
        "none",
        ["train", "--task", "battery", "--out", str(REPO / "policies" / "battery" / "trading")],
        "data folder",
    ),
    ("train-out-holds-the-data", "none", ["train", "--task", "battery", "--out", str(REPO)], "data folder"),
    (
        "testset-into-the-data",
        "none",
        ["testset", "--task", "battery", "--seed", "1", "--out", str(REPO / "tasks" / "battery" / "new.npz")],
        "data folder",
    ),
    (
        "references-into-the-data",
        "none",
        ["score", "--references", "--task", "battery", "--out", str(REPO / "tasks")],
        "data folder",
    ),
    ("score-misspelt-spec-keeps-the-old-card", "mine-json", ["score", "--policy", "evry:3", "--json", "mine.json"], "evry:3"),
    (
        "score-spec-for-another-task-before-any-episode",
        "mine-json",
        ["score", "--policy", f"rl:{CART_POLICY}", "--task", "cart_pendulum", "--task", "battery", "--json", "mine.json"],
        "battery",
    ),
    ("score-out-without-a-mode", "none", ["score", "--policy", "every:3", "--out", "x"], "--out"),
    (
        "score-overflowing-weights",
        "huge-theta",
        ["score", "--policy", "rl:p.json", "--task", "cart_pendulum", "--episodes", "1", "--workers", "1", "--json", "card.json"],
        "p.json: theta[0] is 1e+308, beyond",
    ),
    (
        "leaderboard-readme-without-its-end-marker",
        "readme-no-end",
        ["score", "--leaderboard", "--task", "battery", "--out", "docs", "--readme", "R.md"],
        "R.md",
    ),
    (
        "leaderboard-kept-row-a-list",
        "kept-row-a-list",
        ["score", "--leaderboard", "--task", "battery", "--out", "docs"],
        "not a row",
    ),
    (
        "leaderboard-kept-row-edited",
        "kept-row-edited",
        ["score", "--leaderboard", "--task", "battery", "--out", "docs"],
        "checksum",
    ),
]


@pytest.mark.parametrize("setup, argv, names", [c[1:] for c in OWN_CASES], ids=[c[0] for c in OWN_CASES])
def test_no_output_lands_on_an_input_or_in_the_data(setup, argv, names, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _own_setup(setup, tmp_path)
    before, data = _files(tmp_path), _data_files()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(list(argv))
    _, err = capsys.readouterr()
    assert code == 2, err
    _assert_one_line(err + "".join(f"{w.message}\n" for w in caught), names)
    assert _files(tmp_path) == before
    assert _data_files() == data


def test_a_card_with_a_failed_row_never_replaces_an_existing_card(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    (tmp_path / "late_failure.py").write_text(
        "class T:\n    spec = 'late'\n    stochastic = False\n    def decide(self, s, rng):\n"
        "        raise RuntimeError('fails while playing')\n"
    )
    (tmp_path / "card.json").write_text('{"mine": true}\n')
    assert (
        main(
            [
                "score",
                "--policy",
                "py:late_failure:T",
                "--task",
                "battery",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--json",
                "card.json",
            ]
        )
        == 2
    )
    _assert_one_line(capsys.readouterr().err, "card.json not written")
    assert (tmp_path / "card.json").read_text() == '{"mine": true}\n'


def test_a_shipped_policy_changed_in_place_is_never_scored_under_its_name(tmp_path, monkeypatch, capsys):
    """The checkout's policies/ with one file changed (as a retrain in place, or a swap, would leave it):
    refused in one line; the same bytes elsewhere are a user's policy like any other."""
    import shutil

    from etmpc.evaluation import inputs

    root = tmp_path / "root"
    shutil.copytree(REPO / "policies", root / "policies")
    for folder in ("tasks", "models"):
        (root / folder).symlink_to(REPO / folder)
    monkeypatch.setattr(inputs, "data_root", lambda: root)
    changed = root / "policies" / "cart_pendulum" / "balance" / "learned.json"
    data = json.loads(changed.read_text())
    data["theta"][0] += 1.0
    changed.write_text(json.dumps(data))
    assert main([*EV, "--policy", f"rl:{changed}", "--episodes", "1", "--workers", "1"]) == 2
    _assert_one_line(capsys.readouterr().err, "not the policy etmpc ships")
    mine = tmp_path / "mine.json"
    mine.write_bytes(changed.read_bytes())
    assert main([*EV, "--policy", f"rl:{mine}", "--episodes", "1", "--workers", "1"]) == 0
    assert (
        main(
            [
                *EV,
                "--policy",
                f"rl:{root / 'policies' / 'battery' / 'trading' / 'learned.json'}",
                "--episodes",
                "1",
                "--workers",
                "1",
            ]
        )
        == 2
    )  # untouched, but for another task: its own line, not the checksum's
    assert "not the policy etmpc ships" not in capsys.readouterr().err


def test_every_shipped_policy_file_is_in_the_manifest_with_its_checksum():
    import hashlib

    from etmpc.evaluation.inputs import shipped_digests

    digests = shipped_digests()
    files = {p.resolve() for p in (REPO / "policies").glob("*/*/*") if p.is_file()}
    assert set(digests) == files
    assert all(hashlib.sha256(p.read_bytes()).hexdigest() == digests[p] for p in files)


# -- the API checks its arguments as evaluate does ---------------------------------------------------
SCORE_API_CASES = [
    ("the-same-spec-twice", {"policies": ["every:3", "every:3"]}, "policy every:3 is given twice"),
    ("no-task", {"tasks": []}, "tasks: the list is empty"),
    ("a-task-twice", {"tasks": ["battery", "battery/trading"]}, "task battery/trading is given twice"),
    ("episodes-fraction", {"episodes": 1.5}, "episodes: 1.5 is not a whole number"),
    ("episodes-zero", {"episodes": 0}, "episodes: must be >= 1, got 0"),
    ("workers-zero", {"workers": 0}, "workers: must be >= 1, got 0"),
    ("a-misspelt-spec", {"policies": ["evry:3"]}, "unknown policy 'evry:3'"),
    ("test-set-not-a-path", {"test_set": 3}, "test_set: a file path is needed"),
    ("json-on-the-stored-references", {"json_path": str(STORED_REFERENCES)}, "data folder"),
]


@pytest.mark.parametrize("kwargs, says", [c[1:] for c in SCORE_API_CASES], ids=[c[0] for c in SCORE_API_CASES])
def test_the_score_api_refuses_bad_arguments_before_any_episode(kwargs, says, tmp_path, monkeypatch):
    import etmpc
    from etmpc.common.errors import EtmpcError
    from etmpc.evaluation import scorecard

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(scorecard, "play_and_score", lambda *a, **k: pytest.fail("an episode was played"))
    arguments = {"policies": ["every:3"], "tasks": ["battery"], "workers": 1, "progress": False} | kwargs
    data = _data_files()
    with pytest.raises(EtmpcError) as raised:
        etmpc.score(**arguments)
    assert says in str(raised.value) and "\n" not in str(raised.value)
    assert _files(tmp_path) == {} and _data_files() == data


def test_a_scorecard_is_strict_json_even_with_missing_numbers(tmp_path, monkeypatch):
    """One episode: no confidence interval can be given; it is null, never NaN, which jq and JavaScript refuse."""
    from etmpc.common.documents import loads

    monkeypatch.chdir(tmp_path)
    assert (
        main(["score", "--policy", "every:1", "--task", "battery", "--episodes", "1", "--workers", "1", "--json", "c.json"]) == 0
    )  # its best
    card = loads((tmp_path / "c.json").read_text())  # refuses NaN and Infinity
    (row,) = card["rows"]
    assert row["score_ci95"] is None and row["score"] == 0.0
    assert card["aggregates"][0]["iqm_ci95"] == [None, None]
