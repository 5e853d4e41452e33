"""etmpc: a benchmark for event-triggered model predictive control.

An MPC makes plans, an LQR corrects prediction errors while a plan is kept, and a policy (the paper's
recomputation policy) decides when to recompute. The package is built in floors, each importing only the
ones below it (docs/architecture.md; import-linter checks it):

* ``etmpc.common``: errors, safe file writing, where the data lives, exact sums;
* ``etmpc.control``: the parts of a controller: plan, MPC, compiled code, LQR;
* ``etmpc.systems``: the tasks: one folder per domain, the registry, what a system provides;
* ``etmpc.loop``: Algorithm 1, the closed loop that plays a system under a policy;
* ``etmpc.policies``: when to recompute: fixed, threshold, learned, self-triggering, rollout;
* ``etmpc.evaluation``: test sets, workers, ``evaluate``, ``bench``;
* ``etmpc.envs``: the recompute decision as a ``dm_env`` and ``gymnasium`` environment, for any learner;
* ``etmpc.learning``: GPOMDP, DPI, training runs, the self-trigger's training;
* ``etmpc.views``: recordings, figures, video and ``render``, drawn from what the floors below produce;
* ``etmpc.experiments``: ``reproduce`` and its report, the price ``sweep``;
* ``etmpc.cli``: the ``etmpc`` command.

The Python surface: :func:`etmpc.evaluate` (policies on a stored test set), :func:`etmpc.score` (policies
on every task against the suite's references: the scorecard), :mod:`etmpc.suite` (the
tasks as dm-control environments) and :mod:`etmpc.systems` (the tasks as the loop plays them).
"""

import os

# Headless rendering by default (dm-control chooses its OpenGL backend when first imported);
# set MUJOCO_GL yourself to choose another backend.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.2.0"
__all__ = ["evaluate", "score"]


def _register_environments() -> None:
    """The recompute decision of every task as a gymnasium environment, ``etmpc/<domain>-<task>-v0``."""
    from importlib.util import find_spec

    if find_spec("gymnasium") is None:  # a dependency; an install without it still imports
        return
    import warnings

    from etmpc.envs.registration import register
    from etmpc.systems.registry import domains

    with warnings.catch_warnings():  # a broken task plugin is warned of when the registry is next asked (the
        warnings.simplefilter("ignore", RuntimeWarning)  # command line's first act), not while etmpc imports
        register()
    domains.cache_clear()


_register_environments()


def __getattr__(name: str):
    """``etmpc.evaluate`` is :func:`etmpc.evaluation.evaluate.evaluate` with its recordings (``record=PATH.rrd``)
    written by :class:`etmpc.views.recording.Recorder`, imported when first asked for (so ``import etmpc``
    loads neither MuJoCo nor CasADi)."""
    if name == "evaluate":
        from functools import partial, update_wrapper

        from etmpc.evaluation.evaluate import evaluate
        from etmpc.views.recording import Recorder

        globals()["evaluate"] = update_wrapper(partial(evaluate, recorder=Recorder), evaluate)
        return globals()["evaluate"]
    if name == "score":
        from etmpc.evaluation.scorecard import score

        return score
    raise AttributeError(f"module 'etmpc' has no attribute {name!r}")
