"""What a system provides: the contract between a task's folder and the rest of etmpc.

A *system* is one task as the control loop sees it: the dm-control environment (plant and task), the
MPC that makes plans, the feedback that corrects them, and the objective. :class:`System`
(:mod:`etmpc.systems.protocol`, re-exported here) lists what the rest of etmpc reads of one: the members
every task writes (:data:`REQUIRED`, eight), those :class:`SystemBase`, which every system subclasses,
derives from them with defaults a task may override (:data:`DERIVED`) or reads off the task's Config
(:data:`SETTINGS`), and each optional capability (:data:`OPTIONAL`), an attribute that is ``None`` when
the task does not offer it (:mod:`etmpc.systems.capabilities`: a 3-D scene, sampled futures for rollouts,
failures, ...): a feature that needs one says so in one line.
``docs/adding-a-task.md`` says in which order a newcomer writes them.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, cached_property
from typing import Any

import dm_env
import numpy as np

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.control.plan import Plan
from etmpc.control.sensing import ExtendedKalmanFilter, FilterSettings, Sensor
from etmpc.control.timing import Latency, checked_latency
from etmpc.systems.benchmark import Benchmark, read_benchmark  # noqa: F401 (Benchmark: the systems' API)
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.protocol import (  # noqa: F401 (re-exported: where tests, docs and plugins import them from)
    DERIVED,
    OPTIONAL,
    REQUIRED,
    SETTINGS,
    Feedback,
    System,
)
from etmpc.systems.space import Space


class _StoredBenchmark:
    """The task's :class:`Benchmark`, on the class and its instances: data beside its test set,
    ``benchmark.json`` in its folder of its domain's data (None where there is none), read once."""

    def __get__(self, system, cls) -> Benchmark | None:
        return _benchmark(cls.domain, cls.task)


@cache
def _benchmark(domain: str, task: str) -> Benchmark | None:
    from etmpc.systems.registry import spec

    path = spec(f"{domain}/{task}").data_file("benchmark.json")
    if not path.is_file():
        return None
    return read_benchmark(path)


class _Name:
    """The task's id, ``DOMAIN/TASK`` (:class:`~etmpc.systems.registry.TaskSpec`), on the class and its
    instances (asked of the registry once per task: the trigger environment reads it at every step)."""

    def __get__(self, system, cls) -> str:
        return _canonical(cls.domain, cls.task)


@cache
def _canonical(domain: str, task: str) -> str:
    from etmpc.systems.registry import canonical

    return canonical(f"{domain}/{task}")


class _Declared:
    """What a task declares once, where its dm-control factory is added to its domain's suite
    (:func:`~etmpc.systems.episodes.add_task`): ``steps``, ``interval_s`` or ``episode``, on the class and its
    instances. A system that sets its own (an older plugin's, the battery's from its parameters) keeps it."""

    def __init__(self, attribute: str):
        self.attribute = attribute

    def __set_name__(self, owner, name: str):
        self.name = name

    def __get__(self, system, cls):
        value = getattr(_suite_entry(cls.domain, cls.task), self.attribute, None)
        if value is None:
            where = f"task {cls.domain}/{cls.task}"
            raise AttributeError(f"{where} declares no {self.attribute} (add_task's), and its system no {self.name}")
        return value


@cache
def _suite_entry(domain: str, task: str):
    """Task ``domain/task``'s dm-control factory, asked of its domain's suite once (the loop reads the episode's
    length at every step)."""
    from etmpc.systems.registry import domain as domain_of

    return domain_of(domain).SUITE[task]


class SystemBase:
    """The base of every system: what :data:`DERIVED` lists, from the members a task writes, and every
    capability of :mod:`~etmpc.systems.capabilities` as ``None``. A task overrides what differs for it."""

    # -- what every task writes (REQUIRED): declared here for the type checker, set by each task ----------------
    Config: type
    domain: str
    task: str
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    feedback: Feedback
    make_env: Callable[..., dm_env.Environment]  # (random=None) -> the dm-control environment
    plan: Callable[..., Plan]  # (x, u_prev, warm, age, timestep) -> a Plan
    config: Any  # the Config the system was made with

    name = _Name()  # how files, folders and commands name the task
    episode_steps = _Declared("steps")  # the episode, as the task's suite entry declares it
    control_interval_s = _Declared("interval_s")
    Episode = _Declared("episode")
    objective_sense = "min"  # "min": the objective is a cost; "max": a profit

    # -- optional capabilities (etmpc.systems.capabilities): None where the task offers none -----------------------
    benchmark = _StoredBenchmark()  # benchmark.json beside its test set
    exogenous_feature_names: tuple[str, ...] = ()
    exogenous_features: Callable[[Any], np.ndarray] | None = None  # (s) -> array: the values of exogenous_feature_names
    camera: str | None = None  # the MJCF camera that films the scene
    space: Space | None = None  # where the scene sits in 3-D, for the recordings' 3-D view (etmpc.views.space)
    failure_name: str | None = None  # what a failure is called ("falls")
    # (trajectory, episode) -> int: the failures of an episode so far, counted from what it played (the loop's
    # Trajectory, its first trajectory.steps rows: rewards, states, inputs, recomputes) and the episode it
    # played; each step judged on the steps up to it, so that the count never decreases as the episode goes on
    failures: Callable[[Any, Any], int] | None = None
    # (rewards) -> int: failures read off a stretch of rewards alone (the same count)
    failures_in_rewards: Callable[[np.ndarray], int] | None = None
    # (x) -> the state's margin to a safety failure one interval on (at most 0: a failure), and the task's own
    # shield rule (capabilities.ShieldRule): what shield: plays around a policy
    safety_margin: Callable[[np.ndarray], float] | None = None
    margin_unit: str | None = None
    shield: ShieldRule | None = None
    # (x, u_prev, timestep, inputs) -> the OCP's objective of an input sequence
    plan_cost: Callable[..., float] | None = None
    # () -> the same system with its MPC not compiled (None: it has no other way to run)
    interpreted: Callable[[], SystemBase] | None = None
    # (x, u_prev, warm, age, timestep, limit=1) -> a Plan from at most ``limit`` SQP iterations (Plan.iterations),
    # for compute levels
    iterate: Callable[..., Plan] | None = None
    # (x, inputs) -> the predictor's states from x under inputs (N+1 rows), for delay compensation
    predict: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None

    # the task this one plays with time in the loop (its world, episodes and learned policies), if any
    variant_of: str | None = None

    # -- time in the loop (etmpc.control.timing): a Config's latency and compute_levels, if it has them ----------
    # Read here for every task, and checked here once (the registry reads both when it makes a system, so a
    # bad Config is refused then, not in the middle of an episode): no task's Config checks them itself.
    @cached_property
    def latency(self) -> Latency:
        """How many control intervals a solve takes (the Config's ``latency``; none by default): a
        :class:`Latency` shorter than the horizon (:func:`~etmpc.control.timing.checked_latency`)."""
        return checked_latency(getattr(self.config, "latency", Latency()), self.horizon)

    @cached_property
    def compute_levels(self) -> bool:
        """A decision is one of keep, one SQP iteration, a full solve (the Config's ``compute_levels``);
        a recompute is then priced per SQP iteration (its work). False: keep or solve, priced per solve. A bool,
        never read by its truth (``"no"`` would turn levels on)."""
        return checks.argument("compute_levels", checks.flag, getattr(self.config, "compute_levels", False))

    @cached_property
    def counts_iterations(self) -> bool:
        """The MPC reports each solve's SQP iterations (Plan.iterations): for a price or a delay per iteration."""
        return self.compute_levels or self.latency.counts_work

    # -- what the controller measures (etmpc.control.sensing): a Config's sensor and estimator, if it has them ----
    @cached_property
    def sensor(self) -> Sensor:
        """What the controller reads of the state (the Config's ``sensor``; exact by default)."""
        sensor = getattr(self.config, "sensor", Sensor())
        if not isinstance(sensor, Sensor):
            raise EtmpcError(f"task {self.name}'s Config gives a sensor of type {type(sensor).__name__}, not a Sensor")
        return sensor

    @cached_property
    def estimator(self) -> ExtendedKalmanFilter | None:
        """The filter between the sensor and the controller: none for an exact sensor (the controller reads the
        state itself), else an extended Kalman filter on the MPC's predictor (``model.discrete``) with the
        Config's ``estimator`` settings (:class:`~etmpc.control.sensing.FilterSettings`)."""
        if self.sensor.exact:
            return None
        predictor = getattr(getattr(self, "model", None), "discrete", None)
        if predictor is None:
            raise EtmpcError(f"task {self.name} has no predictor (model.discrete) for an estimator: its sensor must be exact")
        settings = getattr(self.config, "estimator", FilterSettings())
        try:
            return ExtendedKalmanFilter(predictor, self.sensor, settings)
        except checks.BadValue as exc:
            raise checks.BadValue(f"task {self.name}: {exc}") from None

    # -- derived from the members the task writes (a task may set its own in __init__) --------------------
    @cached_property
    def horizon(self) -> int:
        """N: a plan's length; the loop forces a recompute when a plan is N steps old."""
        return self.config.horizon

    @cached_property
    def recompute_price(self) -> float:
        """Charged per recompute (per SQP iteration on a task with compute levels) in the policy's objective."""
        return self.config.recompute_price

    @cached_property
    def u_min(self) -> np.ndarray:
        return np.full(len(self.input_names), -np.inf)

    @cached_property
    def u_max(self) -> np.ndarray:
        return np.full(len(self.input_names), np.inf)

    @cached_property
    def error_weights(self) -> np.ndarray:
        """The diagonal of W in ``threshold:X``'s ``||W (x - x_hat)||``."""
        return np.ones(len(self.state_names))

    def state(self, timestep: dm_env.TimeStep) -> np.ndarray:
        """x from an observation: its entries named as :attr:`state_names`."""
        obs = timestep.observation
        return np.array([obs[name] for name in self.state_names], dtype=float)

    def measure(self, physics: Any) -> np.ndarray:
        """The same x read off the physics (no observation made), bit for bit."""
        return physics.state()

    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray:
        """The environment's action for input ``u``."""
        return u

    # -- the world, read through one reference ----------------------------------------------------------
    @cached_property
    def world(self) -> Any:
        """The task as the world: the dm-control ``Task`` of an environment made once. Its laws are the
        world's, not the controller's: how an episode's random future is drawn (``draw_episode``) and,
        where the task offers it, redrawn past a step from what a controller knows there
        (``resample_episode``), what episodes are drawn from (``episode_parameters``) and their
        exogenous signals (``signals``). The system reads them through this one reference."""
        return self.make_env().task

    def draw_episode(self, rng: np.random.Generator) -> Any:
        """A new episode, drawn by the task from ``rng``."""
        return self.world.draw_episode(rng)

    @property
    def sample_future(self) -> Callable[[Any, int, np.random.Generator], Any] | None:
        """``(episode, step, rng) -> episode`` with what a controller cannot know at the decision of
        ``step`` redrawn: the task's ``resample_episode``, or None where the task offers none."""
        return getattr(self.world, "resample_episode", None)

    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> Any:
        return self.Episode.from_arrays(arrays)

    def episode_parameters(self) -> dict:
        """What episodes are drawn from, kept in a test set's metadata (the task's, if it says)."""
        parameters = getattr(self.world, "episode_parameters", None)
        return {} if parameters is None else parameters()

    def signals(self, episode: Any) -> dict[str, np.ndarray]:
        """The exogenous inputs per step, by name with unit, for recordings and figures (the task's)."""
        signals = getattr(self.world, "signals", None)
        return {} if signals is None else signals(episode)

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.pop("world", None)  # an environment: each process makes its own
        return state

    def truncation_value(self, x: np.ndarray) -> float:
        """What a simulation stopped early adds for the state it ends in."""
        return 0.0

    def show(self, physics: Any, x: np.ndarray) -> None:
        """Put state ``x`` into the physics for drawing (with a ``camera``)."""
        physics.set_state_vector(x)
        physics.forward()

    def reference_solvers(self) -> list:
        """Other solvers of the same OCP, for etmpc bench."""
        return []


def system_type(task: str) -> type[SystemBase]:
    """Task ``task``'s system class as a :class:`SystemBase` (what every task's system subclasses:
    docs/adding-a-task.md), for the class-level members it declares (``name``, ``state_names``, ``Config``,
    ``benchmark``, ``shield``, ``variant_of``, ...). The registry gives the class as it is registered
    (:func:`etmpc.systems.registry.system_class`); this is where a class that is not one is refused."""
    from etmpc.systems.registry import system_class

    cls = system_class(task)
    if not (isinstance(cls, type) and issubclass(cls, SystemBase)):
        raise EtmpcError(
            f"task {task!r}: its system class {cls!r} does not subclass etmpc.systems.base.SystemBase (see docs/adding-a-task.md)"
        )
    return cls
