"""A PPO run's saved state (:class:`etmpc.learning.ppo.PpoLearner`), read back on ``--resume`` as data: ``training.json``
(a finished run), ``checkpoints/resume.json`` and ``checkpoints/resume_normalize.json`` (a run under way) and each
checkpoint's description (``checkpoints/step_N.json``). Every field is checked as it is read (its type, then, once
the run is known to be the one asked for, that its checkpoints are that run's: :func:`check_progress`), and nothing
in the folder is unpickled: a folder someone hands to ``--resume`` runs no code and gives no traceback."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import loads, read_document
from etmpc.common.errors import EtmpcError
from etmpc.learning.ppo_settings import checked_checkpoints
from etmpc.learning.resume import AGAIN, corrupt, numbers
from etmpc.policies.sb3 import read_description
from etmpc.systems import SystemKey

RESUME, NORMALIZE = "resume.json", "resume_normalize.json"  # in checkpoints/, while the run is under way
RESUME_FORMAT, FINISHED_FORMAT = "etmpc-ppo-resume", "etmpc-ppo-run"  # resume.json's, training.json's
RUNNING = ("obs_rms", "ret_rms")  # VecNormalize's running statistics, each a mean, a var and a count
STEPS = 2**62  # the most steps a run's files may count (checked_checkpoints')

# What resume.json and training.json hold (checks.typed_json's hints); the checkpoints are checked_checkpoints'.
_UNDER_WAY = dict(format=str, version=int, task=str, settings=dict, checkpoints=list)
_FINISHED = dict(_UNDER_WAY, workers=int, environment_steps=int, simulated_steps=int, wall_seconds=float, selected=str)
_FINISHED.update(objective_sense=str, stable_baselines3=str, torch=str, kernels=dict[str, str | None])
_OPTIONAL = ("kernels",)  # PyTorch's kernels in effect (etmpc.learning.kernels): not in a run made before them
_RUNNING_STATISTICS = dict(mean=list | float, var=list | float, count=float)


def read_state(out: Path) -> dict | None:
    """The state of the PPO run in ``out``: ``{"finished": training.json}`` for a finished run, ``resume.json``'s
    content for one under way, None for none; each field of its type, its checkpoint files the run's own
    ``checkpoints/step_N.zip`` (a path elsewhere is refused, never followed)."""
    finished, path = out / "training.json", out / "checkpoints" / RESUME
    found = finished if finished.exists() else path if path.exists() else None
    if found is None:
        return None
    state = read_document(
        found,
        FINISHED_FORMAT if found is finished else RESUME_FORMAT,
        missing=f"{found} went away while it was read; {AGAIN}",
        unreadable=f"{found} cannot be read ({{error}}); {AGAIN}",
        foreign=f"{found} is not a PPO run's state; {AGAIN}",
    )
    try:
        checks.typed_json(state, _FINISHED if found is finished else _UNDER_WAY, "", optional=_OPTIONAL, most=STEPS)
        if state["version"] != 1:
            raise checks.BadValue(f"version is {state['version']}, not 1")
        if found is finished and (state["workers"] < 1 or state["wall_seconds"] < 0 or state["simulated_steps"] < 0):
            raise checks.BadValue("its workers must be >= 1, its seconds and steps >= 0")
        if found is finished and state["objective_sense"] not in ("max", "min"):
            raise checks.BadValue(f"objective_sense is {state['objective_sense']!r}, not max or min")
    except checks.BadValue as exc:
        raise corrupt(found, exc) from None
    checked_checkpoints(state["checkpoints"], str(found))
    return {"finished": state} if found is finished else state


def state_file(out: Path, state: dict) -> Path:
    """The file :func:`read_state` read ``state`` from."""
    return out / "training.json" if "finished" in state else out / "checkpoints" / RESUME


def check_progress(out: Path, state: dict, milestones: list[int]) -> None:
    """That the checkpoints of ``state`` (:func:`read_state`'s, of the run asked for) are the run's: one at each of
    its ``milestones`` so far (at all of them for a finished run), each in the file of its steps, and a finished
    run's steps and choice those of its last and one of its checkpoints (with ``selected.zip`` beside them)."""
    saved, path = state.get("finished", state), state_file(out, state)
    entries = saved["checkpoints"]
    steps = [entry["timesteps"] for entry in entries]
    expected = milestones if "finished" in state else milestones[: len(steps)]
    if steps != expected:
        raise corrupt(path, f"its checkpoints are at {steps[:5]} steps, not the run's {expected[:5]}")
    for entry in entries:
        if entry["file"] != f"checkpoints/step_{entry['timesteps']:08d}.zip":
            raise corrupt(path, f"checkpoint {entry['file']} is not the file of its {entry['timesteps']} steps")
    if "finished" not in state:
        return
    if (saved["environment_steps"], saved["simulated_steps"]) != (steps[-1], entries[-1]["simulated_steps"]):
        raise corrupt(path, "environment_steps and simulated_steps must be its last checkpoint's")
    if saved["selected"] not in [entry["file"] for entry in entries] or not (out / "selected.zip").is_file():
        raise corrupt(path, f"selected is {saved['selected']!r}, not one of its checkpoints with selected.zip beside it")


def running_statistics(vec) -> dict:
    """``vec``'s (a VecNormalize's) running statistics as JSON, what :func:`restore_running` puts back: each a
    mean, a variance and a count."""
    return {
        name: {"mean": rms.mean.tolist(), "var": rms.var.tolist(), "count": float(rms.count)}
        for name in RUNNING
        for rms in [getattr(vec, name)]
    }


def restore_running(vec, path: Path) -> None:
    """Put the running statistics :meth:`~etmpc.learning.ppo.PpoLearner.save` wrote as JSON (:func:`running_statistics`)
    back into ``vec`` (a VecNormalize of the same shapes), each number checked: finite, a variance and a count >= 0."""
    try:
        data = loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path} cannot be read ({exc}); {AGAIN}") from None
    try:
        checks.typed_json(data, dict.fromkeys(RUNNING, dict), "")
        restored = {}
        for name in RUNNING:
            rms, values = getattr(vec, name), checks.typed_json(data[name], _RUNNING_STATISTICS, name)
            shape = np.shape(rms.mean)
            mean, var = (
                numbers(_listed(values[k]), f"{name}.{k}", smallest=0.0 if k == "var" else None) for k in ("mean", "var")
            )
            size = int(np.prod(shape))
            if mean.shape != (size,) or var.shape != mean.shape:
                raise checks.BadValue(f"{name} holds {mean.size} and {var.size} numbers, the environment's {size}")
            if values["count"] < 0:
                raise checks.BadValue(f"{name}.count is {values['count']}, not >= 0")
            restored[name] = (mean.reshape(shape), var.reshape(shape), float(values["count"]))
    except checks.BadValue as exc:
        raise corrupt(path, exc) from None
    for name, (mean, var, count) in restored.items():
        rms = getattr(vec, name)
        rms.mean, rms.var, rms.count = mean, var, count


def _listed(value) -> list:
    return value if isinstance(value, list) else [value]  # ret_rms keeps one mean and one var, not a list


def description(meta_file: Path, key: SystemKey, timesteps: int, settings: dict) -> dict:
    """The description beside a checkpoint (``checkpoints/step_N.json``, what ``sb3:`` reads), checked as ``sb3:``
    checks it (:func:`etmpc.policies.sb3.read_description`) and as this run's: ``key``'s task, the checkpoint's
    ``timesteps`` and the run's ``settings``."""
    _, _, _, meta = read_description(meta_file, key.task, f"checkpoint {meta_file}", f"{meta_file} is missing; {AGAIN}")
    if meta.get("timesteps") != timesteps or meta.get("settings") != settings:
        raise corrupt(meta_file, f"its timesteps and settings are not those of the run's checkpoint of {timesteps} steps")
    return meta
