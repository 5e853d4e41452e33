"""What plays :class:`~etmpc.loop.closed.ClosedLoop`: :func:`run_episode` (one whole episode under a policy,
every step recorded and timed) and :func:`play_on` (a snapshot of a running episode continued in the light
mode, for policies that simulate futures). Both play its :meth:`~etmpc.loop.closed.ClosedLoop.step`, so their
numbers are the same, bit for bit (see :mod:`etmpc.loop`)."""

from __future__ import annotations

import math
from typing import Any

import dm_env
import numpy as np

from etmpc.common.progress import EpisodeSteps
from etmpc.control.plan import Plan
from etmpc.loop.closed import ClosedLoop, cpu_clock
from etmpc.loop.records import Continuation, Trajectory
from etmpc.loop.state import Policy, Snapshot, observes, simulates
from etmpc.systems.base import System


def run_episode(
    system: System, env: dm_env.Environment, policy: Policy, rng: np.random.Generator | None = None, episode: Any = None
) -> Trajectory:
    """Play one episode (a stored one if given, else one drawn by the task) under ``policy``."""
    loop = ClosedLoop(system, env).reset(episode)
    shows_context = simulates(policy)  # a policy that simulates the loop is shown its whole state
    steps = EpisodeSteps(len(loop.trajectory.rewards))  # a long episode (a rollout's) says where it is, on stderr
    while not loop.done:
        started = cpu_clock()
        s = loop.augmented_state(shows_context)
        answer = False if s is None else policy.decide(s, rng)  # a level on a task with compute levels
        if s is not None:
            loop.trajectory.decide_time_s[loop.step_index] = cpu_clock() - started
        loop.step(answer, started)
        steps.update()
    return loop.trajectory


def play_on(
    system: System,
    env: dm_env.Environment,
    snapshot: Snapshot,
    policy: Policy,
    rng: np.random.Generator | None,
    first: bool,
    episode: Any = None,
    first_plan: Plan | None = None,
    stop: int | None = None,
    trace: Continuation | None = None,
    failure_cost: float = 0.0,
    start: np.ndarray | None = None,
) -> float:
    """Continue ``snapshot`` in ``env`` (a twin of the one it was taken in) and return the policy's
    return from the snapshot's step on: the sum of :meth:`ClosedLoop.step`'s rewards (the price of
    each recompute taken off), plus ``system.truncation_value`` of the last state when the play
    stops before the episode's end.

    The first decision is ``first`` (recompute or keep; a level on a task with compute levels), the
    later ones ``policy``'s. ``episode``
    replaces the episode being played from the snapshot's step on (a sampled future); ``first_plan``
    is the plan a recompute at the first step gives, when the caller has solved it already (it is
    the same for every future). ``stop`` is the step to stop before (default: the episode's end). A
    plant that fails (non-finite state) returns ``-inf``. ``trace``, if given (a new :class:`Continuation`),
    is filled step by step. ``failure_cost``: the task's failures in the play (``system.failures_in_rewards``)
    cost this much each, taken off the return. ``start``: the plant's state instead of the snapshot's (the other physics kept).

    Plays :class:`ClosedLoop` in its light mode (a policy that never reads the observation sets
    ``observes = False``): the same numbers as :func:`run_episode`, bit for bit (tests/loop/test_rollout.py).
    """
    loop = ClosedLoop(system, env, records=False).resume(snapshot, episode, start)
    end = system.episode_steps if stop is None else min(stop, system.episode_steps)
    observation = observes(policy)  # the observation is made only when someone reads it
    total = 0.0
    rewards: list[float] | None = [] if failure_cost else None  # a failure cost counts the play's failures from its rewards
    while loop.step_index < end:
        if loop.step_index == snapshot.step:
            added = loop.step(first, solved=first_plan)
        else:
            s = loop.augmented_state(observes=observation)
            added = loop.step(False if s is None else policy.decide(s, rng))
        if loop.failed:
            return -math.inf
        total += added
        if rewards is not None:
            rewards.append(loop.reward)
        if trace is not None:
            trace.added.append(added)
            trace.recomputed.append(loop.recomputed)
            if loop.levels:
                trace.levels.append(loop.level)
            trace.after.append((loop.x, loop.plan, loop.age, loop.u_prev, loop.pending, loop.belief))
    if end < system.episode_steps:
        total += system.truncation_value(loop.x)
    if not failure_cost:
        return total
    failures = system.failures_in_rewards
    assert failures is not None  # a failure cost needs RewardFailures (the rollout policy requires it)
    return total - failure_cost * failures(np.array(rewards))
