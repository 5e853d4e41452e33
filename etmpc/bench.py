"""``etmpc bench``: where the time of a step goes, measured on real episodes of the test set.

* MPC solve: wall time of each recompute (the whole ``system.plan`` call) under ``always``.
* Rest of a step: step wall time minus the solve (physics, LQR, policy, bookkeeping), under
  ``always`` and ``never`` together.
* Episodes per second, single process, for ``always`` and ``never``.
* do-mpc (when installed): the very same OCP solved by do-mpc/Ipopt at the same sequence of
  measured states, in the same run, each solver warm started from its own previous solution;
  the ratio of medians and how far its objective is from ours.
* With ``--jit``: the same MPC with its CasADi functions compiled by the C compiler (CasADi's
  JIT; several seconds to build per process, so not the default), on the same states.
"""

from __future__ import annotations

import importlib.util
import platform
import time

import numpy as np

from etmpc import testset as ts_mod
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system


def _stats(values_s: np.ndarray) -> dict:
    values_s = np.asarray(values_s)
    return {
        "median_ms": float(np.median(values_s) * 1e3),
        "p90_ms": float(np.percentile(values_s, 90) * 1e3),
        "samples": int(values_s.size),
    }


def _play(system, env, testset, spec: str, episodes: int):
    policy = parse_policy(spec, system.error_weights)
    start = time.perf_counter()
    trajectories = [
        run_episode(system, env, policy, np.random.default_rng(e), system.episode_from_arrays(testset.episode_arrays(e)))
        for e in range(episodes)
    ]
    return trajectories, time.perf_counter() - start


def _same_states(trajectories, max_solves: int) -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """(measured state, last applied input, continuing the same episode) of an ``always`` run."""
    return [
        (traj.states[i], traj.applied[i - 1] if i else np.zeros(1), i > 0)
        for traj in trajectories
        for i in range(traj.steps)
    ][:max_solves]


def _time_ours(mpc, problems) -> tuple[list[float], list[np.ndarray]]:
    times, inputs, plan = [], [], None
    for x, u_prev, continuing in problems:
        warm = plan if continuing else None
        start = time.perf_counter()
        plan = mpc.solve(x, u_prev, warm, 1 if warm is not None else 0)
        times.append(time.perf_counter() - start)
        inputs.append(plan.inputs.ravel())
    return times, inputs


def _compare_jit(system, trajectories, max_solves: int = 200) -> dict:
    """The same MPC with its CasADi functions compiled by the system's C compiler."""
    from dataclasses import replace

    from etmpc.cart_pendulum.system import CartPendulumSystem

    start = time.perf_counter()
    jitted = CartPendulumSystem(replace(system.config, solver=replace(system.config.solver, jit=True))).mpc
    build_s = time.perf_counter() - start
    problems = _same_states(trajectories, max_solves)
    plain, _ = _time_ours(system.mpc, problems)
    compiled, _ = _time_ours(jitted, problems)
    return {"build_s": build_s, "interpreted": _stats(plain), "compiled": _stats(compiled)}


def _compare_do_mpc(system, trajectories, max_solves: int = 200) -> dict:
    """Both solvers over the same sequence of measured states, one solver after the other (so
    neither evicts the other's caches), each warm started from its own previous solution."""
    from etmpc.bench_dompc import DoMpcReference

    config = system.config
    reference = DoMpcReference(
        system.model.discrete, config.horizon, config.input_change_weight, float(system.u_min[0]), float(system.u_max[0])
    )
    problems = _same_states(trajectories, max_solves)
    ours_s, our_inputs = _time_ours(system.mpc, problems)
    theirs_s, gaps, failures = [], [], 0
    for (x, u_prev, _), ours in zip(problems, our_inputs):
        inputs, elapsed, ok = reference.solve(x, float(u_prev[0]))
        theirs_s.append(elapsed)
        failures += not ok
        ours_cost = _ocp_cost(system, x, u_prev, ours)
        gaps.append((_ocp_cost(system, x, u_prev, inputs) - ours_cost) / max(abs(ours_cost), 1e-12))
    ours, theirs = _stats(ours_s), _stats(theirs_s)
    return {
        "ours": ours,
        "do_mpc": theirs,
        "speedup_median": theirs["median_ms"] / ours["median_ms"],
        "do_mpc_failures": failures,
        "objective_gap_relative": {"median": float(np.median(gaps)), "max_abs": float(np.max(np.abs(gaps)))},
    }


def _ocp_cost(system, x0: np.ndarray, u_prev: np.ndarray, inputs: np.ndarray) -> float:
    """The cart-pendulum OCP objective of an input sequence, rolled out through the predictor."""
    states = system.mpc.rollout(x0, inputs.reshape(-1, 1))
    du = np.diff(np.concatenate([np.atleast_1d(u_prev), inputs]))
    return float(np.sum(states[:, 2] ** 2) + system.config.input_change_weight * np.sum(du**2))


def run_bench(domain: str = "cart_pendulum", episodes: int = 10, do_mpc: bool = True, jit: bool = False) -> dict:
    system = make_system(domain)
    testset = ts_mod.load(ts_mod.default_path(system.domain, system.task), system.domain, system.task)
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
    }
    if do_mpc and importlib.util.find_spec("do_mpc") is not None:
        figures["do_mpc"] = _compare_do_mpc(system, always)
    else:
        figures["do_mpc"] = None
    figures["jit"] = _compare_jit(system, always) if jit else None
    if jit and figures["do_mpc"] is not None:
        figures["do_mpc"]["speedup_median_compiled"] = figures["do_mpc"]["do_mpc"]["median_ms"] / figures["jit"]["compiled"]["median_ms"]
    return figures


def format_bench(f: dict) -> str:
    lines = [
        f"{f['domain']}: {f['episodes']} test-set episodes per policy, single process",
        f"MPC solve          median {f['mpc_solve']['median_ms']:.3f} ms   p90 {f['mpc_solve']['p90_ms']:.3f} ms   ({f['mpc_solve']['samples']} solves)",
        f"rest of a step     median {f['rest_of_step']['median_us']:.1f} us   p90 {f['rest_of_step']['p90_ms'] * 1e3:.1f} us",
        f"episodes/s         always {f['episodes_per_second']['always']:.1f}   never {f['episodes_per_second']['never']:.1f}",
        f"solver failures    {f['solver_failures']}",
    ]
    d = f.get("do_mpc")
    if d is None:
        lines.append("do-mpc             not installed (pip install 'etmpc[bench]') or skipped")
    else:
        lines += [
            f"do-mpc (same OCP)  median {d['do_mpc']['median_ms']:.3f} ms vs ours {d['ours']['median_ms']:.3f} ms "
            f"on the same {d['ours']['samples']} states: {d['speedup_median']:.1f}x faster",
            f"                   objective gap (do-mpc - ours)/ours: median {d['objective_gap_relative']['median']:.1e}, "
            f"max |.| {d['objective_gap_relative']['max_abs']:.1e}; do-mpc failures {d['do_mpc_failures']}",
        ]
    j = f.get("jit")
    if j is not None:
        lines.append(
            f"compiled (--jit)   median {j['compiled']['median_ms']:.3f} ms vs interpreted {j['interpreted']['median_ms']:.3f} ms "
            f"on the same states (build {j['build_s']:.1f} s)"
            + (f"; do-mpc / compiled: {d['speedup_median_compiled']:.1f}x" if d is not None else "")
        )
    return "\n".join(lines)
