"""The recompute decision as an environment, for any learner: one control interval of the loop per
step, keep (0) or recompute (1). :mod:`~etmpc.envs.trigger` is the ``dm_env.Environment``;
:mod:`~etmpc.envs.gym` its ``gymnasium.Env``, registered for every task on ``import etmpc`` as
``etmpc/<domain>-<task>-v0`` (:mod:`~etmpc.envs.registration`, which loads nothing heavy; each spec's
``max_episode_steps``, the task's episode length, is read when first asked: :mod:`~etmpc.envs.envspec`).
:mod:`~etmpc.envs.rendering` draws a step (``render_mode="rgb_array"``) or shows it (``"human"``).
:mod:`~etmpc.envs.normalization` carries a trained policy's frozen observation normalisation as JSON
(``gymnasium.make(ID, normalize="policies/<task>/ppo.json")``, and :func:`save_normalization`, which
writes it for one's own ``VecNormalize``).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop``,
``etmpc.policies``, ``etmpc.views`` and ``etmpc.evaluation``.
"""

__all__ = ["Normalization", "save_normalization"]


def __getattr__(name: str):
    """``save_normalization`` and ``Normalization``, imported when first asked for (``import etmpc``
    registers the environments through this package without loading them)."""
    if name in __all__:
        from etmpc.envs.normalization import Normalization, save_normalization

        return {"Normalization": Normalization, "save_normalization": save_normalization}[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
