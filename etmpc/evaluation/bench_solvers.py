"""``etmpc bench``'s solver comparisons: the very OCPs an ``always`` run meets, solved by our MPC and by each
reference solver (``system.reference_solvers()``) one after the other, or by the MPC as it ran before it was
compiled (``system.interpreted()``): the ratio of median times and the objective gap. Also the timing
statistics and the test-set episode that :mod:`etmpc.evaluation.bench` shares with them."""

from __future__ import annotations

import time

import dm_env
import numpy as np

from etmpc.control.plan import Plan
from etmpc.loop import run_episode
from etmpc.policies import parse_policy

# An OCP as an ``always`` run met it: (x, u_prev, continuing: warm started from the previous plan, timestep).
Problem = tuple[np.ndarray, np.ndarray, bool, dm_env.TimeStep]


def timing_stats(values_s) -> dict:
    values_s = np.asarray(values_s)
    return {
        "median_ms": float(np.median(values_s) * 1e3),
        "p90_ms": float(np.percentile(values_s, 90) * 1e3),
        "samples": int(values_s.size),
    }


def test_episode(system, testset, index: int):
    return system.episode_from_arrays(testset.episode_arrays(index))


class _Capture:
    """The system, with every ``plan`` call's problem kept: (x, u_prev, continuing, timestep)."""

    def __init__(self, system, limit: int):
        self._system = system
        self._limit = limit
        self.problems: list[Problem] = []

    def __getattr__(self, name):
        return getattr(self._system, name)

    def plan(self, x, u_prev, warm, age, timestep):
        if len(self.problems) < self._limit:
            self.problems.append((np.array(x), np.array(u_prev), warm is not None, timestep))
        return self._system.plan(x, u_prev, warm, age, timestep)


def captured_problems(system, env, testset, count: int) -> list[Problem]:
    """The first ``count`` OCPs an ``always`` run meets on the test set (an untimed run)."""
    capture = _Capture(system, count)
    policy = parse_policy("always", system)
    episode = 0
    while len(capture.problems) < count and episode < testset.episodes:
        run_episode(capture, env, policy, np.random.default_rng(episode), test_episode(system, testset, episode))
        episode += 1
    return capture.problems


def _time_ours(system, problems: list[Problem]) -> tuple[list[float], list[np.ndarray]]:
    """``system.plan`` on each problem, warm started from its own previous plan within an episode."""
    times: list[float] = []
    inputs: list[np.ndarray] = []
    plan: Plan | None = None
    for x, u_prev, continuing, timestep in problems:
        warm = plan if continuing else None
        start = time.perf_counter()
        plan = system.plan(x, u_prev, warm, 1 if warm is not None else 0, timestep)
        times.append(time.perf_counter() - start)
        inputs.append(plan.inputs.ravel())
    return times, inputs


def compare_reference(system, reference, problems: list[Problem]) -> dict:
    """Our solver against ``reference`` on the same OCPs: times, failures and how far its objective is from ours."""
    ours_s, our_inputs = _time_ours(system, problems)
    theirs_s: list[float] = []
    gaps: list[float] = []
    failures = 0
    for (x, u_prev, continuing, timestep), our_u in zip(problems, our_inputs):
        inputs, elapsed, ok = reference.solve(x, u_prev, timestep, continuing)
        theirs_s.append(elapsed)
        if not ok:
            failures += 1
            continue
        ours_cost = system.plan_cost(x, u_prev, timestep, our_u)
        gaps.append((system.plan_cost(x, u_prev, timestep, inputs) - ours_cost) / max(abs(ours_cost), 1e-12))
    ours, theirs = timing_stats(ours_s), timing_stats(theirs_s)
    return {
        "name": reference.name,
        "ours": ours,
        "reference": theirs,
        "speedup_median": theirs["median_ms"] / ours["median_ms"],
        "reference_failures": failures,
        "objective_gap_relative": {
            "median": float(np.median(gaps)) if gaps else float("nan"),
            "max_abs": float(np.max(np.abs(gaps))) if gaps else float("nan"),
        },
    }


def compare_interpreted(system, problems: list[Problem]) -> dict | None:
    """Our solver against the same OCPs solved as before it was compiled (``system.interpreted()``)."""
    if system.interpreted is None:  # no other way it runs (the battery's LP is solved inside HiGHS)
        return None
    before = system.interpreted()
    _time_ours(before, problems[:1])  # build lazily constructed solvers before timing
    ours_s, ours_inputs = _time_ours(system, problems)
    theirs_s, theirs_inputs = _time_ours(before, problems)
    gaps = []
    for (x, u_prev, _, timestep), our_u, their_u in zip(problems, ours_inputs, theirs_inputs):
        ours_cost = system.plan_cost(x, u_prev, timestep, our_u)
        gaps.append((system.plan_cost(x, u_prev, timestep, their_u) - ours_cost) / max(abs(ours_cost), 1e-12))
    ours, theirs = timing_stats(ours_s), timing_stats(theirs_s)
    return {
        "ours": ours,
        "interpreted": theirs,
        "speedup_median": theirs["median_ms"] / ours["median_ms"],
        "objective_gap_relative": {"median": float(np.median(gaps)), "max_abs": float(np.max(np.abs(gaps)))},
    }
