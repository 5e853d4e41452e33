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

from dataclasses import dataclass
from typing import Any, Protocol

import dm_env
import numpy as np

from etmpc.control.lqr import ErrorFeedback
from etmpc.control.plan import Plan


@dataclass(frozen=True)
class Benchmark:
    """How the experiments measure a task (``etmpc reproduce`` and ``etmpc sweep``), kept with it."""

    prices: tuple[float, ...]  # the sweep's prices of a computation, in the objective's unit
    sweep_thresholds: tuple[float, ...]  # threshold:X levels that span the periodic schedules' rates
    report_thresholds: tuple[float, ...]  # the few threshold:X levels in reproduce's table of fixed policies
    periods: tuple[int, ...] = (2, 3, 4, 5, 7, 10, 15)  # every:T in that table, beside always and never
    objective_unit: str = "-"  # the objective's unit, for recordings and figures
    # The sweep's size: test-set episodes, rollout futures, and whether a self-trigger is trained at
    # each price (a task whose simulated steps cost more can ask for less).
    sweep_episodes: int = 20
    sweep_futures: int = 4
    sweep_self_trigger: bool = True
    # The most steps a rollout looks ahead (the rollout meter's H and the DPI labels'): on a task whose
    # events come often, a long lookahead sums their random timing, the same for both answers only in
    # distribution, into noise that swamps the price of a computation.
    lookahead: int = 20

    def capped(self, horizon: int | None) -> int:
        """A rollout's horizon ``horizon`` (None: to the episode's end) within the task's ``lookahead``."""
        return self.lookahead if horizon is None else min(horizon, self.lookahead)

    def baselines(self) -> list[str]:
        """Reproduce's fixed policies: always, never, every:T and threshold:X."""
        return (["always", "never"] + [f"every:{t}" for t in self.periods]
                + [f"threshold:{x:g}" for x in self.report_thresholds])


class System(Protocol):
    """A task as the control loop sees it (``cart_pendulum/system.py`` and ``battery/system.py`` are two).

    Members by the feature that needs them. Everything under **the loop** is required; a system
    leaves out a group whose feature it does not offer, and that feature says so in one line.
    """

    # -- the loop (etmpc.loop): required --------------------------------------------------------
    Config: type  # the frozen settings it is built from: Config() is the paper's, with a recompute_price field
    domain: str  # the domain's name in the registry (etmpc.systems.DOMAINS)
    task: str  # the task's name in its domain's SUITE and SYSTEMS
    name: str  # DOMAIN for a domain's default task, else DOMAIN/TASK: how files and commands name it
    objective_sense: str  # "min": the objective is a cost; "max": a profit
    recompute_price: float  # charged per computation in the policy's objective
    episode_steps: int
    control_interval_s: float
    horizon: int  # N: a plan's length; the loop forces a recompute when a plan is N steps old
    state_names: tuple[str, ...]  # x, with units in the names (etmpc.views.blueprint reads them)
    input_names: tuple[str, ...]  # u, likewise
    u_min: np.ndarray
    u_max: np.ndarray
    feedback: ErrorFeedback  # the correction -K (x - x_hat) added to the planned input while a plan is kept

    def make_env(self, random: Any = None) -> dm_env.Environment: ...  # the dm-control environment (plant and task)
    def state(self, timestep: dm_env.TimeStep) -> np.ndarray: ...  # x from an observation
    def measure(self, physics: Any) -> np.ndarray: ...  # the same x, read off the physics (no observation made)
    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan: ...
    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray: ...  # the environment's action for input u

    # -- test sets (etmpc.evaluation.testsets) and everything that replays them: required ---------
    def draw_episode(self, rng: np.random.Generator) -> Any: ...  # everything random about an episode
    def episode_parameters(self) -> dict: ...  # what episodes are drawn from (kept in the test set)
    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> Any: ...  # a stored episode back

    # -- the event trigger threshold:X --------------------------------------------------------------
    error_weights: np.ndarray  # diagonal of W in ||W (x - x_hat)||

    # -- recordings and figures (etmpc.views) ------------------------------------------------------
    def signals(self, episode: Any) -> dict[str, np.ndarray]: ...  # exogenous inputs per step, by name with unit

    # -- experiments (etmpc reproduce, etmpc sweep) ---------------------------------------------------
    benchmark: Benchmark  # prices, threshold levels and the objective's unit

    # -- rollout:, oracle:, DPI and the self-trigger's training (futures simulated with the loop) -----
    def sample_future(self, episode: Any, step: int, rng: np.random.Generator) -> Any: ...  # what is unknown at step, redrawn
    def truncation_value(self, x: np.ndarray) -> float: ...  # reward for the state a truncated rollout ends in

    # -- optional ------------------------------------------------------------------------------------
    # exogenous_feature_names: tuple[str, ...] and exogenous_features(s) -> array: what the learned
    #     policy's "error" features add for this task (the battery's prices and production);
    # camera: str and show(physics, x): a 3-D scene for `etmpc render` (the cart pendulum's);
    # failure_name: str and failures(rewards) -> int: how often an episode failed (a fall, say), counted
    #     from its rewards and reported beside the mean objective;
    # plan_cost, reference_solvers() and interpreted(): what `etmpc bench` compares the MPC with.


#: The members each feature needs (tests/test_systems.py checks every registered system against it).
FEATURES: dict[str, tuple[str, ...]] = {
    "loop": ("Config", "domain", "task", "name", "objective_sense", "recompute_price", "episode_steps", "control_interval_s",
             "horizon", "state_names", "input_names", "u_min", "u_max", "feedback", "make_env", "state", "measure",
             "plan", "action"),
    "test sets": ("draw_episode", "episode_parameters", "episode_from_arrays"),
    "threshold policy": ("error_weights",),
    "recordings": ("signals",),
    "experiments": ("benchmark",),
    "rollouts": ("sample_future", "truncation_value"),
    "exogenous features": ("exogenous_feature_names", "exogenous_features"),
    "render": ("camera", "show"),
    "bench": ("plan_cost", "reference_solvers", "interpreted"),
    "failures": ("failure_name", "failures"),
}
REQUIRED = ("loop", "test sets", "threshold policy", "recordings", "experiments", "rollouts")


def provides(system: Any, feature: str) -> bool:
    """Whether ``system`` (an instance or its class) has every member ``feature`` needs."""
    return all(hasattr(system, member) for member in FEATURES[feature])
