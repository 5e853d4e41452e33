"""The trigger problem as an environment, for any learner: one control interval of the loop per
step, keep (0) or recompute (1). :mod:`~etmpc.envs.trigger` is the ``dm_env.Environment``;
:mod:`~etmpc.envs.gym` its ``gymnasium.Env``, registered for every task on ``import etmpc`` as
``etmpc/<domain>-<task>-v0`` (:mod:`~etmpc.envs.registration`, which loads nothing heavy).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop``,
``etmpc.policies``, ``etmpc.views`` and ``etmpc.evaluation``.
"""
