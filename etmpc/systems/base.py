"""What a system provides, by feature: the contract between a task's folder and the rest of etmpc.

A *system* is one task as the control loop sees it: the dm-control environment (plant and task), the
MPC that makes plans, the feedback that corrects them, and the objective. :class:`System` lists its
members, grouped by the feature that needs them; a system leaves out what its features do not need
(a task without exogenous signals has no ``exogenous_features``; one without a 3-D scene no
``scene``). ``tests/test_systems.py`` lists what every registered system provides, and
``docs/adding-a-task.md`` says in which order a newcomer writes them.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

from typing import Any, Protocol

import dm_env
import numpy as np

from etmpc.control.lqr import ErrorFeedback
from etmpc.control.plan import Plan


class System(Protocol):
    """What the control loop needs from a system (see ``etmpc/cart_pendulum/system.py`` and
    ``etmpc/battery/system.py``)."""

    domain: str
    task: str
    objective_sense: str  # "min": the objective is a cost; "max": a profit
    recompute_price: float  # charged per computation in the policy's objective
    episode_steps: int
    control_interval_s: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    u_min: np.ndarray
    u_max: np.ndarray
    error_weights: np.ndarray  # diagonal of W for the threshold policy
    feedback: ErrorFeedback

    def make_env(self, random: Any = None) -> dm_env.Environment: ...
    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> Any: ...
    def state(self, timestep: dm_env.TimeStep) -> np.ndarray: ...
    def measure(self, physics: Any) -> np.ndarray: ...  # the same x, read off the physics (no observation made)
    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan: ...
    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray: ...

    # Not used by the loop: test sets (etmpc.evaluation.testsets), `etmpc bench` and recordings.
    def draw_episode(self, rng: np.random.Generator) -> Any: ...
    def signals(self, episode: Any) -> dict[str, np.ndarray]: ...  # exogenous inputs per step (recordings)
    def episode_parameters(self) -> dict: ...
    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float: ...
    def reference_solvers(self) -> list: ...  # objects with .name and .solve(x, u_prev, timestep, continuing)
    def interpreted(self) -> System | None: ...  # the same system with its MPC in CasADi's VM, if it is compiled

    # Used by the rollout policies (etmpc.policies.rollout).
    def sample_future(self, episode: Any, step: int, rng: np.random.Generator) -> Any: ...  # see its docstrings
    def truncation_value(self, x: np.ndarray) -> float: ...  # reward for the state a truncated rollout ends in
