"""Learning recomputation policies: GPOMDP, the paper's policy gradient (:mod:`~etmpc.learning.gpomdp`),
direct policy iteration (:mod:`~etmpc.learning.dpi`), a training run over seeds with checkpoints
and resume (:mod:`~etmpc.learning.config`, :mod:`~etmpc.learning.jobs`,
:mod:`~etmpc.learning.checkpoint`, :mod:`~etmpc.learning.train`), and the self-triggering policy's
training (:mod:`~etmpc.learning.selftrigger`).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop``,
``etmpc.policies``, ``etmpc.views`` and ``etmpc.evaluation``.
"""
