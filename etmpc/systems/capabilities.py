"""What a task may offer beyond what every task writes, as protocols a type checker sees.

Each capability is a :class:`~typing.Protocol` whose annotated members a system sets (on
:class:`~etmpc.systems.base.SystemBase` they are ``None``: a task that does not offer it leaves them so).
:func:`offers` asks whether a system offers one, and narrows its type where it does; :func:`require` says in
one line which task lacks what a feature needs::

    if offers(system, Rollouts):
        future = system.sample_future(episode, step, rng)  # a type checker knows it is there
    require(system, Experiments, "etmpc sweep").benchmark.prices

A capability's name in messages is its class name in words (``TimeInTheLoop``: "time in the loop").
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeGuard, TypeVar

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.systems.benchmark import Benchmark

if TYPE_CHECKING:  # a capability is a protocol class: a form of a type (PEP 747), not a class one may instantiate
    from typing_extensions import TypeForm


class Experiments(Protocol):
    """etmpc reproduce, sweep and the leaderboard's rows: prices, thresholds, lookahead (``benchmark.json``)."""

    benchmark: Benchmark


class Rollouts(Protocol):
    """rollout:, DPI and the self-trigger's training: ``(episode, step, rng) -> episode``, with what a controller
    cannot know at the decision of ``step`` redrawn."""

    sample_future: Callable[[Any, int, np.random.Generator], Any]


class ExogenousFeatures(Protocol):
    """What the learned policy's "error" features add: ``(s) -> array``, the values of
    ``exogenous_feature_names``."""

    exogenous_features: Callable[[Any], np.ndarray]


class Scene(Protocol):
    """A 3-D scene for etmpc render and the recordings' video: the MJCF camera that films it (with ``show``)."""

    camera: str


class Bench(Protocol):
    """What etmpc bench compares the MPC with: ``(x, u_prev, timestep, inputs) -> the OCP's objective of an input
    sequence`` (with ``reference_solvers`` and ``interpreted``)."""

    plan_cost: Callable[..., float]


class Failures(Protocol):
    """How often an episode failed (falls, ...), reported beside the mean objective: ``(trajectory, episode) ->
    int``, counted from what it played, never decreasing as the episode goes on; ``failure_name`` says what one
    is called."""

    failures: Callable[[Any, Any], int]


class RewardFailures(Protocol):
    """Failures read off a stretch of rewards alone, ``(rewards) -> int`` (a fall's or a step's own reward says it
    was one): what a failure cost in learning counts in a simulated future (DPI's ``failure_cost``)."""

    failures_in_rewards: Callable[[np.ndarray], int]


class SafetyMargin(Protocol):
    """How near a safety failure a state is, for shields (``shield:``): ``(x) -> float``, the margin (in
    ``margin_unit``) the state keeps one control interval on at its current rate: at most 0 is a failure. A
    task may also declare its own rule, ``shield`` (a :class:`ShieldRule`, chosen on training-distribution
    episodes), which ``shield:BASE`` plays."""

    safety_margin: Callable[[np.ndarray], float]


@dataclass(frozen=True)
class ShieldRule:
    """A shield's rule: compute when the kept plan is ``max_age`` steps old, when the state's safety margin
    is below ``margin`` (None: not read), or when the state has left the plan's prediction by more than
    ``deviation``, measured as the threshold trigger measures it (``|W (x_i - x_hat_i)|``, the task's
    ``error_weights``; None: not read). A deviation is given only after a margin (``AGE:MARGIN:DEVIATION``)."""

    max_age: int
    margin: float | None = None
    deviation: float | None = None

    def __post_init__(self):
        if not isinstance(self.max_age, int) or self.max_age < 1:
            raise EtmpcError(f"a shield's age must be a whole number of steps >= 1, got {self.max_age!r}")
        if self.margin is not None and not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin)):
            raise EtmpcError(f"a shield's margin must be a finite number, got {self.margin!r}")
        if self.deviation is not None:
            if not (isinstance(self.deviation, (int, float)) and math.isfinite(self.deviation) and self.deviation > 0):
                raise EtmpcError(f"a shield's deviation must be a finite number > 0, got {self.deviation!r}")
            if self.margin is None:
                raise EtmpcError("a shield's deviation comes after its margin: AGE:MARGIN:DEVIATION")

    @property
    def text(self) -> str:
        """How a spec writes it: ``AGE``, ``AGE:MARGIN`` or ``AGE:MARGIN:DEVIATION``."""
        numbers = [f"{v:g}" for v in (self.margin, self.deviation) if v is not None]
        return ":".join([str(self.max_age), *numbers])


class TimeInTheLoop(Protocol):
    """Compute levels, work-priced solves and delay compensation: SQP iterations from the shifted plan
    (``iterate(..., limit=1)``: at most ``limit``, a Plan whose ``iterations`` says how many) and the predictor's
    states under given inputs (``predict``)."""

    iterate: Callable[..., Any]
    predict: Callable[[np.ndarray, np.ndarray], np.ndarray]


#: Every capability, in the order tests and docs list them.
CAPABILITIES: tuple[type, ...] = (
    Experiments,
    Rollouts,
    ExogenousFeatures,
    Scene,
    Bench,
    Failures,
    RewardFailures,
    SafetyMargin,
    TimeInTheLoop,
)

C = TypeVar("C")


def members(capability: type) -> tuple[str, ...]:
    """The members a system sets to offer ``capability`` (its annotated names)."""
    return tuple(capability.__annotations__)


def feature(capability: type) -> str:
    """``capability``'s name in messages: ``TimeInTheLoop`` -> ``time in the loop``."""
    return re.sub(r"(?<!^)(?=[A-Z])", " ", capability.__name__).lower()


def offers(system: Any, capability: TypeForm[C]) -> TypeGuard[C]:
    """Whether ``system`` (an instance or its class) offers ``capability``: every member set, none ``None``."""
    assert isinstance(capability, type)  # a capability is one of the protocol classes above
    return all(getattr(system, member, None) is not None for member in members(capability))


def require(system: Any, capability: TypeForm[C], what: str) -> C:
    """``system``, if it offers ``capability``, which ``what`` needs; else one line naming the task and what it lacks."""
    assert isinstance(capability, type)  # a capability is one of the protocol classes above
    if not offers(system, capability):
        raise EtmpcError(
            f"{what} needs {feature(capability)} ({', '.join(members(capability))}), which task {system.name} does not offer"
        )
    return system
