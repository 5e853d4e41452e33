"""``etmpc bench``: where the time of a step goes, measured on real episodes of the test set.

For each system, through the :class:`etmpc.loop.System` protocol only:

* MPC solve: wall time of each recompute (the whole ``system.plan`` call) under ``always``.
* Rest of a step: step wall time minus the solve (plant, LQR, policy, bookkeeping), under
  ``always`` and ``never`` together.
* Episodes per second, single process, for ``always`` and ``never``.
* Reference solvers (``system.reference_solvers()``: do-mpc for the cart pendulum when installed,
  scipy's ``linprog`` for the battery): the very same OCP, solved at the same sequence of measured
  states in the same run, one solver after the other (so neither evicts the other's caches); the
  ratio of medians and how far the reference's objective is from ours.
* With ``--jit``: the system's MPC compiled by the C compiler (``system.compiled()``; several
  seconds to build per process, so not the default), on the same states.
"""

from __future__ import annotations

import platform
import time

import numpy as np

from etmpc import testset as ts_mod
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system


def _stats(values_s) -> dict:
    values_s = np.asarray(values_s)
    return {
        "median_ms": float(np.median(values_s) * 1e3),
        "p90_ms": float(np.percentile(values_s, 90) * 1e3),
        "samples": int(values_s.size),
    }


def _episode(system, testset, index: int):
    return system.episode_from_arrays(testset.episode_arrays(index))


def _play(system, env, testset, spec: str, episodes: int):
    policy = parse_policy(spec, system.error_weights)
    start = time.perf_counter()
    trajectories = [run_episode(system, env, policy, np.random.default_rng(e), _episode(system, testset, e)) for e in range(episodes)]
    return trajectories, time.perf_counter() - start


class _Capture:
    """The system, with every ``plan`` call's problem kept: (x, u_prev, continuing, timestep)."""

    def __init__(self, system, limit: int):
        self._system, self._limit, self.problems = system, limit, []

    def __getattr__(self, name):
        return getattr(self._system, name)

    def plan(self, x, u_prev, warm, age, timestep):
        if len(self.problems) < self._limit:
            self.problems.append((np.array(x), np.array(u_prev), warm is not None, timestep))
        return self._system.plan(x, u_prev, warm, age, timestep)


def _problems(system, env, testset, count: int) -> list:
    """The first ``count`` OCPs an ``always`` run meets on the test set (an untimed run)."""
    capture = _Capture(system, count)
    policy = parse_policy("always", system.error_weights)
    episode = 0
    while len(capture.problems) < count and episode < testset.episodes:
        run_episode(capture, env, policy, np.random.default_rng(episode), _episode(system, testset, episode))
        episode += 1
    return capture.problems


def _time_ours(system, problems) -> tuple[list[float], list[np.ndarray]]:
    """``system.plan`` on each problem, warm started from its own previous plan within an episode."""
    times, inputs, plan = [], [], None
    for x, u_prev, continuing, timestep in problems:
        warm = plan if continuing else None
        start = time.perf_counter()
        plan = system.plan(x, u_prev, warm, 1 if warm is not None else 0, timestep)
        times.append(time.perf_counter() - start)
        inputs.append(plan.inputs.ravel())
    return times, inputs


def _compare_reference(system, reference, problems) -> dict:
    ours_s, our_inputs = _time_ours(system, problems)
    theirs_s, gaps, failures = [], [], 0
    for (x, u_prev, continuing, timestep), ours in zip(problems, our_inputs):
        inputs, elapsed, ok = reference.solve(x, u_prev, timestep, continuing)
        theirs_s.append(elapsed)
        if not ok:
            failures += 1
            continue
        ours_cost = system.plan_cost(x, u_prev, timestep, ours)
        gaps.append((system.plan_cost(x, u_prev, timestep, inputs) - ours_cost) / max(abs(ours_cost), 1e-12))
    ours, theirs = _stats(ours_s), _stats(theirs_s)
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


def _compare_compiled(system, problems) -> dict:
    start = time.perf_counter()
    compiled = system.compiled()
    if compiled is None:
        return {"available": False}
    _time_ours(compiled, problems[:1])  # build any lazily compiled code before timing
    build_s = time.perf_counter() - start
    plain, _ = _time_ours(system, problems)
    fast, _ = _time_ours(compiled, problems)
    return {"available": True, "build_s": build_s, "interpreted": _stats(plain), "compiled": _stats(fast)}


def run_bench(domain: str = "cart_pendulum", episodes: int = 10, references: bool = True, jit: bool = False,
              reference_solves: int = 200) -> dict:
    system = make_system(domain)
    testset = ts_mod.load(ts_mod.default_path(system.domain, system.task), system.domain, system.task)
    episodes = min(episodes, testset.episodes)
    env = system.make_env()
    _play(system, env, testset, "always", 1)  # warm up caches and lazy builds

    always, always_s = _play(system, env, testset, "always", episodes)
    never, never_s = _play(system, env, testset, "never", episodes)
    solves = np.concatenate([t.solve_time_s[: t.steps] for t in always])
    solves = solves[~np.isnan(solves)]
    rest = np.concatenate([t.step_time_s[: t.steps] - np.nan_to_num(t.solve_time_s[: t.steps]) for t in always + never])
    figures = {
        "domain": system.domain,
        "machine": {"processor": platform.processor() or platform.machine(), "python": platform.python_version()},
        "episodes": episodes,
        "mpc_solve": _stats(solves),
        "rest_of_step": {**_stats(rest), "median_us": float(np.median(rest) * 1e6)},
        "episodes_per_second": {"always": episodes / always_s, "never": episodes / never_s},
        "solver_failures": int(sum(t.solver_failures for t in always + never)),
        "references": [],
        "jit": None,
    }
    problems = _problems(system, env, testset, reference_solves) if references or jit else []
    if references:
        figures["references"] = [_compare_reference(system, ref, problems) for ref in system.reference_solvers()]
    if jit:
        figures["jit"] = _compare_compiled(system, problems)
        if figures["jit"]["available"]:
            for ref in figures["references"]:
                ref["speedup_median_compiled"] = ref["reference"]["median_ms"] / figures["jit"]["compiled"]["median_ms"]
    return figures


def format_bench(f: dict) -> str:
    lines = [
        f"{f['domain']}: {f['episodes']} test-set episodes per policy, single process",
        f"MPC solve          median {f['mpc_solve']['median_ms']:.3f} ms   p90 {f['mpc_solve']['p90_ms']:.3f} ms   ({f['mpc_solve']['samples']} solves)",
        f"rest of a step     median {f['rest_of_step']['median_us']:.1f} us   p90 {f['rest_of_step']['p90_ms'] * 1e3:.1f} us",
        f"episodes/s         always {f['episodes_per_second']['always']:.1f}   never {f['episodes_per_second']['never']:.1f}",
        f"solver failures    {f['solver_failures']}",
    ]
    for r in f["references"]:
        lines += [
            f"{r['name']}: median {r['reference']['median_ms']:.3f} ms vs ours {r['ours']['median_ms']:.3f} ms "
            f"on the same {r['ours']['samples']} OCPs: ours {r['speedup_median']:.1f}x faster",
            f"    objective gap (reference - ours)/|ours|: median {r['objective_gap_relative']['median']:.1e}, "
            f"max |.| {r['objective_gap_relative']['max_abs']:.1e}; reference failures {r['reference_failures']}",
        ]
    if not f["references"]:
        lines.append("reference solvers  none run (skipped, or do-mpc not installed: pip install 'etmpc[bench]')")
    j = f.get("jit")
    if j is not None and not j["available"]:
        lines.append("compiled (--jit)   not applicable to this system's MPC")
    elif j is not None:
        lines.append(
            f"compiled (--jit)   median {j['compiled']['median_ms']:.3f} ms vs interpreted {j['interpreted']['median_ms']:.3f} ms "
            f"on the same OCPs (build {j['build_s']:.1f} s)"
        )
        lines += [f"    {r['name']} / compiled: {r['speedup_median_compiled']:.1f}x" for r in f["references"]]
    return "\n".join(lines)
