"""``etmpc bench``: where the time of a step goes, measured on real episodes of the test set.

For each task, through the :class:`etmpc.loop.System` protocol only, in one process:

The step times are CPU seconds of the thread that plays (:data:`etmpc.loop.closed.cpu_clock`); the
episodes per second and the side-by-side solver comparisons below are wall time.

* MPC solve: the time of each recompute (the whole ``system.plan`` call) under ``always``:
  median and 90th percentile.
* Rest of a step on the ``dm_env`` path (:func:`etmpc.loop.run_episode`, what ``evaluate`` plays):
  step time minus the solve (plant, LQR, policy, bookkeeping), under ``always``, ``every:3``
  and ``never`` together.
* Rollout step: a step of :func:`etmpc.loop.play_on` (the fast path rollouts and the oracle
  simulate futures with) under ``never``, forced solves taken out; and the steps per second that
  makes.
* Episodes per second, single process, for ``always``, ``every:3`` and ``never``.
* Where a step under ``every:3`` goes: its share of the MPC's solves, the plant's own step
  (``env.physics.step``: MuJoCo's substeps, with what a task adds to each, such as the cart's bumpers), and
  the rest, Python around them (the task's bookkeeping, the feedback, the policy, the records). From those,
  the most a batch of episodes could gain that keeps every number (the same solves and physics, bit for
  bit): with none of the rest, and the solves and physics spread over every core, a step costs at least
  ``(solve + physics) / cores``.
* Reference solvers (``system.reference_solvers()``: do-mpc for the cart pendulum when installed,
  scipy's ``linprog`` for the battery): the very same OCP, solved at the same sequence of measured
  states in the same run, one solver after the other (so neither evicts the other's caches); the
  ratio of medians and how far the reference's objective is from ours.
* Before compiling (``system.interpreted()``, the cart pendulum only): the MPC as it was solved
  before it ran as compiled C (full multiple shooting in CasADi's virtual machine), on the same
  states: the speed-up and the objective gap.
"""

from __future__ import annotations

import os
import platform
import time

import numpy as np

from etmpc.common.wording import counted
from etmpc.evaluation import testsets as ts_mod
from etmpc.evaluation.bench_solvers import captured_problems, compare_interpreted, compare_reference, test_episode, timing_stats
from etmpc.common.errors import EtmpcError
from etmpc.loop import Snapshot, play_on, run_episode
from etmpc.loop.closed import cpu_clock
from etmpc.policies import parse_policy
from etmpc.systems import SystemKey, system_key
from etmpc.systems.capabilities import Bench, offers


def _play(system, env, testset, spec: str, episodes: int):
    policy = parse_policy(spec, system)
    start = time.perf_counter()
    trajectories = [
        run_episode(system, env, policy, np.random.default_rng(e), test_episode(system, testset, e)) for e in range(episodes)
    ]
    return trajectories, time.perf_counter() - start


class _PlantClock:
    """While in use, the CPU time of ``env``'s plant steps (``env.physics.step``, on :data:`cpu_clock`), summed
    in :attr:`seconds`: the step of this one environment is timed, not its class's."""

    def __init__(self, env):
        self.physics, self.seconds = env.physics, 0.0

    def __enter__(self) -> _PlantClock:
        step = self.physics.step

        def timed(*args, **kwargs):
            start = cpu_clock()
            try:
                return step(*args, **kwargs)
            finally:
                self.seconds += cpu_clock() - start

        self.physics.step = timed
        return self

    def __exit__(self, *exc) -> None:
        del self.physics.step  # the class's own again


def _step_budget(trajectories, plant_s: float, cores: int) -> dict:
    """Where the steps of ``trajectories`` went (ms a step, averaged over all of them): the solves, the plant
    (``plant_s`` in all), the rest; and ``batch_bound``, the most a batch that keeps the solves and the plant as
    they are could speed a step up, on one core and on ``cores``: the step over ``solve + plant``, spread."""
    steps = sum(t.steps for t in trajectories)
    total_s = sum(float(t.step_time_s[: t.steps].sum()) for t in trajectories)
    solve_s = sum(float(np.nansum(t.solve_time_s[: t.steps])) for t in trajectories)
    floor_s = solve_s + plant_s
    per_step = lambda seconds: seconds / steps * 1e3  # noqa: E731
    return {
        "policy": "every:3",
        "steps": steps,
        "step_ms": per_step(total_s),
        "solve_ms": per_step(solve_s),
        "plant_ms": per_step(plant_s),
        "rest_ms": per_step(total_s - floor_s),
        "cores": cores,
        "batch_bound": {"one_core": total_s / floor_s, "every_core": total_s * cores / floor_s},
    }


class _Snapshotter:
    """A policy that never recomputes and keeps a snapshot of the loop at its first decision."""

    spec, stochastic, simulates = "never", False, True

    def __init__(self):
        self.snapshot: Snapshot | None = None

    def decide(self, s, rng) -> bool:
        if self.snapshot is None:
            self.snapshot = Snapshot.take(s.context)
        return False


def _rollout_steps(system, env, testset, episodes: int, repeats: int = 5) -> dict:
    """CPU time per step of :func:`etmpc.loop.play_on` under ``never`` from step 1 of each
    episode (the plan made at step 0 kept, forced solves every N steps excluded): a rollout step
    without a solve, the fast path rollouts and the oracle simulate with."""
    never, twin = parse_policy("never", system), system.make_env()
    per_step, solve_s, steps = [], [0.0], 0

    class _Timed:  # system.plan timed, so that forced solves can be taken out
        def __getattr__(self, name):
            return getattr(system, name)

        def plan(self, *args):
            start = cpu_clock()
            plan = system.plan(*args)
            solve_s[0] += cpu_clock() - start
            return plan

    timed = _Timed()
    for e in range(episodes):
        snapshotter = _Snapshotter()
        run_episode(system, env, snapshotter, None, test_episode(system, testset, e))
        snapshot = snapshotter.snapshot
        assert snapshot is not None  # taken at the episode's first decision
        for _ in range(repeats):
            solve_s[0] = 0.0
            start = cpu_clock()
            play_on(timed, twin, snapshot, never, None, False)
            steps = system.episode_steps - snapshot.step
            per_step.append((cpu_clock() - start - solve_s[0]) / steps)
    median_s = float(np.median(per_step))
    return {
        "median_us": median_s * 1e6,
        "p90_us": float(np.percentile(per_step, 90) * 1e6),
        "steps_per_second": 1.0 / median_s,
        "samples": len(per_step),
    }


def benched(domain: str | SystemKey, episodes: int):
    """``domain``'s system and its stored test set, once it is known to hold ``episodes`` (else one line):
    ``etmpc bench`` checks every task's before it times the first."""
    system = system_key(domain).make()
    ts_mod.check_options_act(system_key(domain), takes_test_set=False)  # it plays the stored test set
    testset = ts_mod.load(ts_mod.default_path(system.domain, system.task), system.domain, system.task)
    if episodes > testset.episodes:
        raise EtmpcError(f"--episodes {episodes}: the {domain} test set has {testset.episodes} episodes")
    return system, testset


def run_bench(
    domain: str | SystemKey = "cart_pendulum", episodes: int = 10, references: bool = True, reference_solves: int = 200
) -> dict:
    """Time ``domain``'s solves and steps (a task's name, or a :class:`SystemKey` with its options) on its first test-set
    ``episodes``: what ``etmpc bench`` prints."""
    key = system_key(domain)
    system, testset = benched(key, episodes)
    env = system.make_env()
    _play(system, env, testset, "always", 1)  # warm up caches and lazy builds

    played = {spec: _play(system, env, testset, spec, episodes) for spec in ("always", "never")}
    with _PlantClock(env) as plant:
        played["every:3"] = _play(system, env, testset, "every:3", episodes)
    played = {spec: played[spec] for spec in ("always", "every:3", "never")}
    always = played["always"][0]
    solves = np.concatenate([t.solve_time_s[: t.steps] for t in always])
    solves = solves[~np.isnan(solves)]
    trajectories = [t for runs, _ in played.values() for t in runs]
    rest = np.concatenate([t.step_time_s[: t.steps] - np.nan_to_num(t.solve_time_s[: t.steps]) for t in trajectories])
    figures = {
        "domain": system.domain,
        "task": system.name,
        **({"options": dict(key.options)} if key.options else {}),
        "machine": {"processor": platform.processor() or platform.machine(), "python": platform.python_version()},
        "episodes": episodes,
        "mpc_solve": timing_stats(solves),
        "rest_of_step": {**timing_stats(rest), "median_us": float(np.median(rest) * 1e6)},
        "rollout_step": _rollout_steps(system, env, testset, episodes),
        "episodes_per_second": {spec: episodes / seconds for spec, (_, seconds) in played.items()},
        "step_budget": _step_budget(played["every:3"][0], plant.seconds, os.cpu_count() or 1),
        "solver_failures": int(sum(t.solver_failures for t in trajectories)),
        "references": [],
        "references_skipped": not references,
        "interpreted": None,
    }
    problems = captured_problems(system, env, testset, reference_solves)
    if references:
        figures["references"] = [compare_reference(system, ref, problems) for ref in system.reference_solvers()]
    if offers(system, Bench):  # a task that offers plan_cost and interpreted()
        figures["interpreted"] = compare_interpreted(system, problems)
    return figures


def _budget_lines(b: dict) -> list[str]:
    bound = b["batch_bound"]
    return [
        f"a step, {b['policy']}   {b['step_ms']:.3f} ms = solves {b['solve_ms']:.3f} + plant {b['plant_ms']:.3f} "
        f"+ the rest {b['rest_ms']:.3f} (Python around them)",
        f"    a batch that keeps the solves and the plant: at most {bound['one_core']:.1f}x on one core, "
        f"{bound['every_core']:.1f}x on {b['cores']} cores",
    ]


def format_bench(f: dict) -> str:
    lines = [
        f"{f.get('task', f['domain'])}{''.join(f' --option {k}={v}' for k, v in f.get('options', {}).items())}: "
        f"{counted(f['episodes'], 'test-set episode')} per policy, single process",
        f"MPC solve          median {f['mpc_solve']['median_ms']:.3f} ms   p90 {f['mpc_solve']['p90_ms']:.3f} ms   "
        f"({f['mpc_solve']['samples']} solves)",
        f"rest of a step     median {f['rest_of_step']['median_us']:.1f} us   p90 {f['rest_of_step']['p90_ms'] * 1e3:.1f} us"
        "   (dm_env path: run_episode, evaluate)",
        f"rollout step       median {f['rollout_step']['median_us']:.1f} us   p90 {f['rollout_step']['p90_us']:.1f} us"
        f"   = {f['rollout_step']['steps_per_second']:,.0f} steps/s   (fast path: play_on, no solve)",
        "episodes/s         " + "   ".join(f"{spec} {rate:.1f}" for spec, rate in f["episodes_per_second"].items()),
        *_budget_lines(f["step_budget"]),
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
        lines.append(
            "reference solvers  none run"
            + (" (--no-reference)" if f.get("references_skipped") else " (do-mpc is not installed: pip install 'etmpc[bench]')")
        )
    i = f.get("interpreted")
    if i is not None:
        lines += [
            f"before compiling   median {i['interpreted']['median_ms']:.3f} ms (full multiple shooting, CasADi VM) vs ours "
            f"{i['ours']['median_ms']:.3f} ms on the same {i['ours']['samples']} OCPs: ours {i['speedup_median']:.1f}x faster",
            f"    objective gap (before - ours)/|ours|: median {i['objective_gap_relative']['median']:.1e}, "
            f"max |.| {i['objective_gap_relative']['max_abs']:.1e}",
        ]
    return "\n".join(lines)
