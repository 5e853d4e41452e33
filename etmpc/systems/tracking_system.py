"""The base of a tracking task's system (the quadrotor's ``waypoints``, the reacher's ``jumps``, the cart
pendulum's ``kicks``): what :class:`~etmpc.systems.gauss_newton.GaussNewtonSystem` leaves to each task and the
three write alike.

* its Config is read once: ``self.config``, the task's ``Config()`` unless one is given;
* ``threshold:X`` weighs the prediction error by ``sqrt(Q)``, Q the Config's ``feedback_state_weights``;
* an episode's failures are read off its rewards (the task's ``failures_in_rewards``).

A task's system builds its predictor (``self.model``) and its input bounds in its ``__init__`` after this one's.
This module may import ``etmpc.common``, ``etmpc.control`` and the modules of ``etmpc.systems`` beside it.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property
from typing import Any

import numpy as np

from etmpc.systems.gauss_newton import GaussNewtonSystem


class TrackingSystem(GaussNewtonSystem):
    """A tracking task's system (see the module's docstring); a subclass sets ``failures_in_rewards`` to its
    task's count of failures in a stretch of rewards."""

    Config: type  # the frozen settings the system is built from: Config() is the task's default
    failures_in_rewards: Callable[[np.ndarray], int]  # every tracking task counts its failures in its rewards

    def __init__(self, config: Any = None):
        self.config = self.Config() if config is None else config

    @cached_property
    def error_weights(self) -> np.ndarray:
        """The diagonal of W in ``threshold:X``'s ``||W (x - x_hat)||``: ``sqrt(Q)`` of the LQR along each plan."""
        return np.sqrt(np.asarray(self.config.feedback_state_weights))

    def failures(self, trajectory: Any, episode: Any) -> int:
        """The episode's failures so far, from its rewards (the task's ``failures_in_rewards``)."""
        return self.failures_in_rewards(trajectory.rewards[: trajectory.steps])
