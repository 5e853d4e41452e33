"""What the loop shows a policy and what it asks of one (:class:`AugmentedState`, :class:`Policy`), and
the loop's state at a decision, for policies that simulate (:class:`DecisionContext`, :class:`Snapshot`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeAlias, runtime_checkable

import dm_env
import numpy as np

from etmpc.control.plan import Plan
from etmpc.control.timing import Iterations


# -- what the loop asks of a policy ------------------------------------------------------------------
@dataclass(frozen=True)
class AugmentedState:
    """What a policy sees at a decision (paper, section 2.2): ``s = [x_i, x_k, i - k]`` (the current
    state, the state the plan was made from, the plan's age), the plan's prediction ``x_hat_i`` (a
    function of ``s``, handed along for the event trigger), the kept plan, the task's observation and,
    for policies that simulate, the loop's whole state.

    Everything in it is read-only (:mod:`etmpc.common.frozen`): the arrays are read-only views, the
    plan a frozen value, the observation a frozen mapping. A policy that writes into what it is shown
    gets an error, never a changed run; to compute with a value, copy it (``np.array(s.x)``)."""

    x: np.ndarray  # x_i, measured now (with a sensor that is not exact: the filter's estimate)
    x_plan: np.ndarray  # x_k, measured (estimated) when the plan was made
    age: int  # i - k
    x_predicted: np.ndarray  # x_hat_i, the plan's prediction for now
    plan: Any = None  # the kept Plan (its inputs and the forecasts it was made with)
    observation: Mapping | None = None  # what the task shows now (for the exogenous features)
    context: Any = None  # a DecisionContext: the loop's whole state, for policies that simulate (simulates = True)
    # with a sensor that is not exact (etmpc.control.sensing), the filter's Belief after this step's reading:
    # x is its mean; its covariance and the reading's innovation say how much to trust it. None: x is the state
    belief: Any = None


#: A policy's answer at a decision: keep (False) or recompute (True); on a task with compute levels
#: (:mod:`etmpc.control.timing`), a level: ``KEEP`` (0), ``ITERATE`` (1, one SQP iteration) or ``SOLVE`` (2), or
#: ``Iterations(k)`` (at most k SQP iterations). numpy's bools and integers are answers alike
#: (:func:`~etmpc.control.timing.level_of` reads every one).
Decision: TypeAlias = bool | int | np.bool_ | np.integer | Iterations


class Policy(Protocol):
    """What the loop asks of a policy: its spec, whether it draws from ``rng``, and its decision at ``s``.
    ``rng`` is None where the caller gives none (a deterministic policy never reads it)."""

    @property
    def spec(self) -> str: ...
    @property
    def stochastic(self) -> bool: ...

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision: ...


def drawing(rng: np.random.Generator | None) -> np.random.Generator:
    """``rng``, for a policy that draws from it: a stochastic policy is always played with a generator
    (:mod:`etmpc.evaluation` seeds one per episode and pass); only a deterministic one may be given None."""
    assert rng is not None, "a stochastic policy is played with a generator"
    return rng


# -- what a policy may declare beyond Policy: each a protocol, absent on most policies ----------------------
@runtime_checkable
class Simulates(Protocol):
    """``simulates``: True if the policy simulates the loop (``rollout:``, the oracle): it is shown the loop's
    whole state (:attr:`AugmentedState.context`). Without it, a policy is shown none."""

    simulates: bool


@runtime_checkable
class Observes(Protocol):
    """``observes``: False if ``decide`` never reads ``s.observation`` (the light mode of
    :func:`~etmpc.loop.play.play_on` then skips making it). Without it, a policy is assumed to read it."""

    observes: bool


@runtime_checkable
class Announces(Protocol):
    """``announce(plan) -> steps``: a self-trigger's, what it announces at each solve: how many steps the plan
    will be kept (recorded with the episode, :class:`~etmpc.loop.records.EpisodeRecord`)."""

    def announce(self, plan: Plan) -> int: ...


@runtime_checkable
class Clairvoyant(Protocol):
    """``clairvoyant``: True for an oracle, which knows each episode's future: a reference, not a policy."""

    clairvoyant: bool


# The four reads below are where etmpc reads these members of a policy. Each reads its member by name, as declared
# by its protocol, rather than by isinstance against it: a runtime-checkable protocol's isinstance costs about
# 12 us against 0.1 us (play_on asks observes() at every future it plays), and from Python 3.12 on it looks
# members up statically, missing one a policy provides through __getattr__.
def simulates(policy: object) -> bool:
    """Whether ``policy`` simulates the loop (:class:`Simulates`; False if it does not say)."""
    return bool(getattr(policy, "simulates", False))


def observes(policy: object) -> bool:
    """Whether ``policy`` reads the observation (:class:`Observes`; True if it does not say)."""
    return bool(getattr(policy, "observes", True))


def announcer(policy: object) -> Callable[[Plan], int] | None:
    """``policy``'s ``announce`` (:class:`Announces`), or None if it announces nothing."""
    announce: Callable[[Plan], int] | None = getattr(policy, "announce", None)
    return announce


def clairvoyant(policy: object) -> bool:
    """Whether ``policy`` is an oracle (:class:`Clairvoyant`; False if it does not say)."""
    return bool(getattr(policy, "clairvoyant", False))


@dataclass(frozen=True, eq=False)
class DecisionContext:
    """The loop's whole state at a decision, for policies that simulate futures (``rollout:``)."""

    system: Any
    env: dm_env.Environment
    step: int  # i: the decision is about the input of interval i
    plan: Plan
    age: int
    u_prev: np.ndarray
    timestep: dm_env.TimeStep | None  # None in the light mode (etmpc.loop.modes), which shows no policy a context
    belief: Any = None  # the filter's Belief (etmpc.control.sensing), where the sensor is not exact


@dataclass(frozen=True, eq=False)
class Snapshot:
    """A running episode, frozen at a decision: the plant, the task's position in its episode and the
    controller's memory. :func:`play_on` continues from it exactly."""

    physics: Any  # the physics' own snapshot (see each Physics.snapshot)
    step: int
    episode: Any  # the episode the task was playing
    plan: Plan
    age: int
    u_prev: np.ndarray
    x: np.ndarray
    observation: Mapping
    pending: Any = None  # a solve in flight (ClosedLoop.pending): none at a decision, where snapshots are taken
    belief: Any = None  # the filter's Belief, where the sensor is not exact (x is the plant's state all the same)

    @property
    def seen(self) -> np.ndarray:
        """What the controller sees of the state: the filter's estimate, or the state itself."""
        return self.x if self.belief is None else self.belief.mean

    @classmethod
    def take(cls, context: DecisionContext) -> Snapshot:
        env = context.env
        timestep = context.timestep
        assert timestep is not None  # a context is made by a recording loop, which has a TimeStep
        x = context.system.state(timestep)
        return cls(
            env.physics.snapshot(),
            context.step,
            env.task.episode,
            context.plan,
            context.age,
            np.array(context.u_prev),
            x,
            timestep.observation,
            belief=context.belief,
        )
