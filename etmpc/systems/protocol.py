"""What the rest of etmpc reads of a system: :class:`System`, the protocol a type checker holds every task
to, and the names of its members by where they come from: what every task writes (:data:`REQUIRED`), what
:class:`~etmpc.systems.base.SystemBase` derives from them (:data:`DERIVED`) or reads off the task's Config
(:data:`SETTINGS`), and the optional capabilities (:data:`OPTIONAL`, :mod:`etmpc.systems.capabilities`).
:mod:`etmpc.systems.base` re-exports them all.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import dm_env
import numpy as np

from etmpc.control.plan import Plan
from etmpc.control.sensing import ExtendedKalmanFilter, Sensor
from etmpc.control.timing import Latency
from etmpc.systems.benchmark import Benchmark
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.space import Space


class Feedback(Protocol):
    """The correction added to the planned input while a plan is kept (``ErrorFeedback``, ``PlanFeedback``)."""

    def correction(self, x: np.ndarray, x_planned: np.ndarray, plan: Any = None, age: int = 0) -> np.ndarray: ...


class System(Protocol):
    """What the loop, the evaluation, the environments and the policies read of a system: the members every
    task writes (:data:`REQUIRED`; ``cart_pendulum/system.py`` and ``battery/system.py`` are two), those
    :class:`SystemBase` derives from them (:data:`DERIVED`) or reads off the task's Config (:data:`SETTINGS`),
    and the optional capabilities (:data:`OPTIONAL`, :mod:`etmpc.systems.capabilities`), ``None`` where the
    task does not offer them: ``offers(system, Rollouts)`` narrows one to what it is.

    Each is read-only here (a property), so that a task may write it as a class attribute, a cached property
    or a method. ``tests/systems/test_protocol.py`` holds this list to the three tuples and the tuples to it."""

    # -- what every task writes (REQUIRED) --------------------------------------------------------------
    @property
    def Config(self) -> type: ...  # the frozen settings; Config() is the default, with fields horizon and recompute_price
    @property
    def domain(self) -> str: ...  # the domain's name in the registry (etmpc.systems.registry)
    @property
    def task(self) -> str: ...  # the task's name in its domain's SUITE and SYSTEMS
    @property
    def state_names(self) -> tuple[str, ...]: ...  # x, with units in the names (etmpc.views.blueprint reads them)
    @property
    def input_names(self) -> tuple[str, ...]: ...  # u, likewise
    @property
    def feedback(self) -> Feedback: ...  # the correction added to the planned input while a plan is kept

    def make_env(self, random: Any = None) -> dm_env.Environment: ...  # the dm-control environment (plant and task)
    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan: ...

    # -- what SystemBase derives from them (DERIVED) ----------------------------------------------------
    @property
    def name(self) -> str: ...  # DOMAIN/TASK
    @property
    def episode_steps(self) -> int: ...
    @property
    def control_interval_s(self) -> float: ...
    @property
    def Episode(self) -> Any: ...  # the task's episode class (from_arrays)
    @property
    def horizon(self) -> int: ...  # N
    @property
    def recompute_price(self) -> float: ...
    @property
    def objective_sense(self) -> str: ...  # "min" or "max"
    @property
    def u_min(self) -> np.ndarray: ...
    @property
    def u_max(self) -> np.ndarray: ...
    @property
    def error_weights(self) -> np.ndarray: ...

    def state(self, timestep: dm_env.TimeStep) -> np.ndarray: ...
    def measure(self, physics: Any) -> np.ndarray: ...
    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray: ...
    def draw_episode(self, rng: np.random.Generator) -> Any: ...
    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> Any: ...
    def episode_parameters(self) -> dict: ...
    def signals(self, episode: Any) -> dict[str, np.ndarray]: ...
    def truncation_value(self, x: np.ndarray) -> float: ...
    def show(self, physics: Any, x: np.ndarray) -> None: ...
    def reference_solvers(self) -> list: ...

    # -- what SystemBase reads off the Config (SETTINGS) -----------------------------------------------
    @property
    def config(self) -> Any: ...  # the Config it was made with
    @property
    def latency(self) -> Latency: ...
    @property
    def compute_levels(self) -> bool: ...
    @property
    def counts_iterations(self) -> bool: ...
    @property
    def sensor(self) -> Sensor: ...
    @property
    def estimator(self) -> ExtendedKalmanFilter | None: ...
    @property
    def variant_of(self) -> str | None: ...  # the task this one plays with time in the loop, if any

    # -- optional capabilities (OPTIONAL, etmpc.systems.capabilities): None where the task offers none ---
    @property
    def benchmark(self) -> Benchmark | None: ...
    @property
    def sample_future(self) -> Callable[[Any, int, np.random.Generator], Any] | None: ...
    @property
    def exogenous_feature_names(self) -> tuple[str, ...]: ...
    @property
    def exogenous_features(self) -> Callable[[Any], np.ndarray] | None: ...
    @property
    def camera(self) -> str | None: ...
    @property
    def space(self) -> Space | None: ...
    @property
    def failure_name(self) -> str | None: ...
    @property
    def failures(self) -> Callable[[Any, Any], int] | None: ...
    @property
    def failures_in_rewards(self) -> Callable[[np.ndarray], int] | None: ...
    @property
    def safety_margin(self) -> Callable[[np.ndarray], float] | None: ...
    @property
    def margin_unit(self) -> str | None: ...
    @property
    def shield(self) -> ShieldRule | None: ...
    @property
    def plan_cost(self) -> Callable[..., float] | None: ...
    @property
    def interpreted(self) -> Callable[[], System] | None: ...
    @property
    def iterate(self) -> Callable[..., Plan] | None: ...
    @property
    def predict(self) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None: ...


#: The members every task writes (:class:`System`).
REQUIRED = ("Config", "domain", "task", "state_names", "input_names", "feedback", "make_env", "plan")
#: What :class:`SystemBase` derives from them, each a default a task may override.
DERIVED = (
    "name",
    "episode_steps",  # the three from the task's suite entry (add_task): declared once, there
    "control_interval_s",
    "Episode",
    "horizon",
    "recompute_price",
    "objective_sense",
    "u_min",
    "u_max",
    "error_weights",
    "state",
    "measure",
    "action",
    "draw_episode",
    "episode_from_arrays",
    "episode_parameters",
    "signals",
    "truncation_value",
    "show",
    "reference_solvers",
)
#: What :class:`SystemBase` reads off the task's Config (or holds for it), checked once.
SETTINGS = ("config", "latency", "compute_levels", "counts_iterations", "sensor", "estimator", "variant_of")
#: The optional capabilities (:mod:`etmpc.systems.capabilities`), each ``None`` (or empty) where the task offers none.
OPTIONAL = (
    "benchmark",
    "sample_future",
    "exogenous_feature_names",
    "exogenous_features",
    "camera",
    "space",
    "failure_name",
    "failures",
    "failures_in_rewards",
    "safety_margin",
    "margin_unit",
    "shield",
    "plan_cost",
    "interpreted",
    "iterate",
    "predict",
)
