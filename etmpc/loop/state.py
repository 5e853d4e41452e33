"""What the loop shows a policy and what it asks of one (:class:`AugmentedState`, :class:`Policy`), and
the loop's state at a decision, for policies that simulate (:class:`DecisionContext`, :class:`Snapshot`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import dm_env
import numpy as np

from etmpc.control.plan import Plan


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


class Policy(Protocol):
    spec: str
    stochastic: bool
    # Optional ``observes = False``: decide never reads ``s.observation`` (the fast path of
    # etmpc.loop.play_on then skips making it). Without the attribute, a policy is assumed to read it.

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool: ...


@dataclass(frozen=True, eq=False)
class DecisionContext:
    """The loop's whole state at a decision, for policies that simulate futures (``rollout:``)."""

    system: Any
    env: dm_env.Environment
    step: int  # i: the decision is about the input of interval i
    plan: Plan
    age: int
    u_prev: np.ndarray
    timestep: dm_env.TimeStep
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
        x = context.system.state(context.timestep)
        return cls(
            env.physics.snapshot(),
            context.step,
            env.task.episode,
            context.plan,
            context.age,
            np.array(context.u_prev),
            x,
            context.timestep.observation,
            belief=context.belief,
        )
