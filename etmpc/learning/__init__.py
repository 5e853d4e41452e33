"""Learning policies. Every learner is a :class:`~etmpc.learning.base.Learner` (one interface: setup,
learn with a budget and a callback, the policy, state for resume), registered by name in
:data:`~etmpc.learning.base.LEARNERS` (``learners()``: gpomdp, dpi, self, ppo, then any other defined),
and trained by one runner (:func:`etmpc.learning.runner.run`: seeds, checkpoints and resume,
validation selection, cost). The learners: GPOMDP, the paper's policy gradient
(:mod:`~etmpc.learning.gpomdp`), and direct policy iteration (:mod:`~etmpc.learning.dpi`), both run
over seeds in phases with checkpoints and exact resume (:mod:`~etmpc.learning.phased`,
:mod:`~etmpc.learning.phased_settings`, :mod:`~etmpc.learning.curve`, :mod:`~etmpc.learning.config`,
:mod:`~etmpc.learning.jobs`, :mod:`~etmpc.learning.checkpoint`, :mod:`~etmpc.learning.train`); the
self-triggering policy (:mod:`~etmpc.learning.selftrigger`, :mod:`~etmpc.learning.selftrigger_labels`); PPO
from Stable-Baselines3 (:mod:`~etmpc.learning.ppo`, :mod:`~etmpc.learning.ppo_settings`,
:mod:`~etmpc.learning.ppo_model`, :mod:`~etmpc.learning.ppo_state`, :mod:`~etmpc.learning.hyperparams`).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop``,
``etmpc.policies``, ``etmpc.evaluation`` and ``etmpc.envs``; not ``etmpc.views``, which stands above it: a
run's recordings and learning curve are drawn by what its caller gives it (``recorder``, ``curve_png``).
"""
