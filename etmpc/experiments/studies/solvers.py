"""The MPC's two solver routes side by side: every re-plan's CPU time, iterations and failures, and what
the closed loop scores, on the same stored test-set episodes, in one run.

    etmpc study solvers [TASK ...] [--episodes 20] [--policy always] [--json docs/results/solvers.json]

Each task (default: every task whose MPC is a Gauss-Newton one: ``cart_pendulum``, ``cart_pendulum/kicks``,
``reacher``, ``quadrotor``) is played under ``--policy`` on the first ``--episodes`` episodes of its stored
test set by two controllers that differ only in their ``SolverSettings``: ``sqpmethod`` (CasADi's SQP on the
multiple-shooting NLP, its QPs by qrqp) and ``condensed`` (``etmpc.control.condensed``: a Gauss-Newton SQP on the
inputs alone, its dense QPs by DAQP). The task's own route is played as it ships; the other is the task's
settings with the route swapped (the quadrotor's sqpmethod route is the one it flew through version 0,
``TRACKING_SOLVER``). The two alternate episode by episode, so that whatever else the machine does falls on
both. Each compiled MPC solves once before timing (its lazy build is not a re-plan).

A re-plan's time is the controller's thread CPU time for it (``Trajectory.solve_time_s``, as the score card's
``cpu_ms.solve``); ``failed`` counts plans the loop could not use, ``short`` plans returned before the
solver's own convergence test passed (the condensed route still flies them: each is a descent from the
warm start). ``--json`` writes everything with the commit and the machine; ``--page`` also writes the
docs' solver page from it (``docs/solvers.md``).
"""

from __future__ import annotations

import argparse
import json
import platform
from dataclasses import replace
from pathlib import Path

import numpy as np

from etmpc.common import outputs
from etmpc.common.errors import EtmpcError
from etmpc.experiments.studies import runner

TASKS = ("cart_pendulum", "cart_pendulum/kicks", "reacher", "quadrotor")
ROUTES = ("sqpmethod", "condensed")
CONVERGED = "condensed, v1's stop"  # the quadrotor's condensed route stopped as in its version 1
V1_STOPPING = {"max_iterations": 100, "step_tolerance": 1e-3}


def variants(task: str) -> dict:
    """``route -> system`` for ``task``: the task as it ships, and its settings with the route swapped."""
    from etmpc.systems import make_system
    from etmpc.systems.gauss_newton import TRACKING_SOLVER

    shipped = make_system(task)
    own = shipped.config.solver
    if own.route == "condensed":
        other = (
            replace(TRACKING_SOLVER, compiled=own.compiled) if task.startswith("quadrotor") else replace(own, route="sqpmethod")
        )
    else:
        other = replace(own, route="condensed")
    swapped = type(shipped)(replace(shipped.config, solver=other))
    found = {own.route: shipped, other.route: swapped}
    if task.startswith("quadrotor"):  # its stopping rule since v2 against v1's: solved to convergence
        found[CONVERGED] = type(shipped)(replace(shipped.config, solver=replace(own, **V1_STOPPING)))
    return found


def counted(system) -> list:
    """Wrap ``system.mpc``'s solve and iterate to keep each plan's ``(success, converged, iterations)``."""
    mpc = system.mpc
    kept = []
    for name in ("solve", "iterate"):
        method = getattr(mpc, name)

        def wrapper(*args, _method=method, **kwargs):
            plan = _method(*args, **kwargs)
            kept.append((plan.success, plan.status == "converged", plan.iterations))
            return plan

        setattr(mpc, name, wrapper)
    return kept


def play(task: str, episodes: int, policy_spec: str) -> dict:
    from etmpc.evaluation import testsets
    from etmpc.evaluation.evaluate import scores
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy
    from etmpc.systems.registry import parse

    systems = variants(task)
    domain, name = parse(task)
    testset = testsets.load(testsets.default_path(domain, name), domain, name)
    setups = {}
    for route, system in systems.items():
        env = system.make_env()
        first = env.reset()
        system.plan(system.state(first), np.zeros(len(system.u_min)), None, 0, first)  # the compiled MPC's lazy build
        setups[route] = (system, env, parse_policy(policy_spec, system), counted(system))
    times: dict[str, list[float]] = {route: [] for route in systems}
    objective: dict[str, list[float]] = {route: [] for route in systems}
    solver_failures = {route: 0 for route in systems}
    failures = {route: 0 for route in systems}
    for i in range(min(episodes, testset.episodes)):
        for route, (system, env, policy, _) in setups.items():
            episode = system.episode_from_arrays(testset.episode_arrays(i))
            traj = run_episode(system, env, policy, np.random.default_rng(i), episode)
            solved = traj.solve_time_s[: traj.steps]
            times[route].extend(solved[solved > 0].tolist())
            objective[route].append(scores(system, traj)[0])
            solver_failures[route] += traj.solver_failures
            if system.failures is not None:
                failures[route] += system.failures(traj, episode)
    result = {}
    for route, (system, _, _, kept) in setups.items():
        t = np.array(times[route]) * 1e3
        iterations = np.array([k[2] for k in kept], dtype=float)
        result[route] = {
            "settings": {k: v for k, v in vars(system.config.solver).items() if not isinstance(v, tuple) or v},
            "replans": int(t.size),
            "ms": {
                "median": float(np.median(t)),
                "mean": float(t.mean()),
                "p99": float(np.quantile(t, 0.99)),
                "max": float(t.max()),
            },
            "iterations": {
                "median": float(np.median(iterations)),
                "mean": float(iterations.mean()),
                "max": int(iterations.max()),
            },
            "failed": int(sum(not k[0] for k in kept)),
            "short": int(sum(k[0] and not k[1] for k in kept)),
            "solver_failures": solver_failures[route],
            "objective_mean": float(np.mean(objective[route])),
            "task_failures": failures[route],
        }
    return result


def machine() -> dict:
    """The machine (``etmpc reproduce``'s description of it), the Python and the checkout's commit."""
    from etmpc.experiments.report import machine as described

    return described() | runner.made() | {"python": platform.python_version()}


# Published figures of the field's solvers, quoted from their sources: not measured here.
QUOTED = (
    (
        "acados SQP_RTI with HPIPM, nonlinear least squares, from Python",
        "hexarotor, 13 states, 6 inputs, N = 20",
        "about 2 ms per step on average, spikes above 7 ms",
        "a desktop PC",
        "acados forum, thread 1467",
    ),
    (
        "acados against CasADi + Ipopt (safe-control-gym)",
        "3-D quadrotor, figure-8 tracking",
        "full SQP at least 10x, SQP_RTI about 100x faster than Ipopt",
        "not stated",
        "safe-control-gym, pull request 175",
    ),
    (
        "DAQP (dual active set), linear MPC",
        "Crazyflie 2.1, 12 states, 4 inputs",
        "500 Hz on the flight controller, faster than TinyMPC there",
        "STM32F405, 168 MHz",
        "arXiv 2603.09342",
    ),
    ("Tiny LB-MPC", "Crazyflie 2.1 (53 g)", "100 Hz on board", "Teensy 4.0", "arXiv 2410.23634"),
)


def page(report: dict) -> str:
    """The docs' solver page from a report of :func:`main`."""
    m = report["machine"]
    lines = [
        "# The MPC's solve: two routes, measured side by side",
        "",
        runner.generated("solvers"),
        "",
        "Every task whose MPC is a Gauss-Newton one can solve its OCP by two routes (`SolverSettings.route`):",
        "",
        "* **`sqpmethod`**: CasADi's SQP on the multiple-shooting NLP, its QPs by `qrqp` (CasADi's sparse active-set",
        "  method), a failed warm solve retried cold. The cart pendulum's tasks and the reacher's fly it.",
        "* **`condensed`** (`etmpc.control.condensed`): the OCP made stage-separable (the previous input carried in the",
        "  state), condensed onto its inputs by a backward recursion in generated C, each QP a dense one with bounds",
        "  only, solved by [DAQP](https://github.com/darnstrom/daqp) (a dual active-set method, in C). Every iterate is",
        "  a plan the predictor flies; it is warm started by the kept plan flown under its own feedback gains. The",
        "  quadrotor flies it (since `quadrotor/waypoints` v1; at most 10 QPs a re-plan since v2).",
        "",
        f"Measured with `{report['command']}` at commit `{m['commit']}` on {m['cpu']} ({m['cores']} cores),",
        f"Python {m['python']}: each task's first {report['episodes']} stored test-set episodes under `{report['policy']}`,",
        "played by both routes in turn, episode by episode. A re-plan's time is the thread's CPU time for it",
        "(the score card's `cpu_ms.solve`); *failed*: plans the loop could not use; *short*: plans returned before",
        "the solver's convergence test passed; *objective*: the closed loop's mean per episode.",
        "",
        "| task | route | re-plans | median ms | mean ms | p99 ms | max ms | QPs median / mean / max | failed | short "
        "| objective | task failures |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for task, routes in report["tasks"].items():
        for route, r in routes.items():
            ms = r["ms"]
            it = r["iterations"]
            qps = "(not counted)" if it["max"] < 0 else f"{it['median']:.0f} / {it['mean']:.1f} / {it['max']}"
            lines.append(
                f"| {task} | {route} | {r['replans']} | {ms['median']:.2f} | {ms['mean']:.2f} | {ms['p99']:.2f} | "
                f"{ms['max']:.1f} | {qps} | {r['failed']} | {r['short']} | {r['objective_mean']:.4f} | {r['task_failures']} |"
            )
    lines += ["", "Per task, the condensed route against `sqpmethod`, on the same episodes:", ""]
    for task, routes in report["tasks"].items():
        if not set(ROUTES) <= set(routes):
            continue
        old = routes["sqpmethod"]
        new = routes["condensed"]
        change = (new["objective_mean"] - old["objective_mean"]) / abs(old["objective_mean"])
        lines.append(
            f"* **{task}**: {old['ms']['mean'] / new['ms']['mean']:.1f}x the speed in mean, "
            f"{old['ms']['median'] / new['ms']['median']:.1f}x in median; the closed loop's cost "
            f"{change:+.2%} ({new['objective_mean']:.4f} against {old['objective_mean']:.4f}), "
            f"{new['task_failures']} task failures against {old['task_failures']}."
        )
    for task, routes in report["tasks"].items():
        if CONVERGED in routes and "condensed" in routes:
            full = routes[CONVERGED]
            new = routes["condensed"]
            change = (new["objective_mean"] - full["objective_mean"]) / abs(full["objective_mean"])
            lines += [
                "",
                f"**The quadrotor's stopping rule.** Since version 2 a re-plan stops after at most "
                f"{new['settings']['max_iterations']} QPs, or when a step moves no thrust by more than "
                f"{100 * new['settings']['step_tolerance']:.1f} % of its range; "
                f"version 1 solved to {100 * V1_STOPPING['step_tolerance']:.1f} % "
                f"with up to {V1_STOPPING['max_iterations']} QPs (the row `{CONVERGED}`). "
                "On the same episodes, the "
                f"stopped plans fly a closed loop whose cost differs by {100 * change:+.3f} % from the converged ones' "
                f"({new['objective_mean']:.4f} against {full['objective_mean']:.4f}; task failures {new['task_failures']} "
                f"against {full['task_failures']}), while the re-plan is {full['ms']['mean'] / new['ms']['mean']:.2f}x "
                f"as fast in mean, {full['ms']['median'] / new['ms']['median']:.2f}x in median and "
                f"{full['ms']['p99'] / new['ms']['p99']:.2f}x at the 99th percentile. A plan stopped at the cap ("
                f"{new['short']} of {new['replans']}, *short*) is still a descent from the warm start, and is flown, as the",
                "real-time iteration flies its one iteration.",
            ]
    lines += [
        "",
        "A task flies the condensed route only where it is faster *and* flies as well: the quadrotor. On the",
        "cart pendulum it is no faster. On the kicks and the reacher it is faster, but its plans are not those of",
        "multiple shooting: single shooting can settle in another local optimum of a nonconvex OCP (the cart's has one",
        "with the pole swung over the top: `tests/control/test_condensed.py`), and the closed loop pays for it in its",
        "cost and its failures, so both keep `sqpmethod`.",
        "",
        "`sqpmethod` does not report its iterations per solve here (one compiled call runs the whole SQP).",
        "",
        "## The field's figures (quoted, not measured here)",
        "",
        "Published by others, on other problems and other hardware; quoted as their sources give them.",
        "",
        "| solver | problem | time | hardware | source |",
        "|---|---|---|---|---|",
        *[f"| {' | '.join(row)} |" for row in QUOTED],
        "",
    ]
    return "\n".join(lines)


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("tasks", nargs="*", default=list(TASKS), help=f"the tasks (default: {', '.join(TASKS)})")
    parser.add_argument("--episodes", type=int, default=20, help="the first N stored test-set episodes (default 20)")
    parser.add_argument("--policy", default="always", help="the policy both routes play (default always)")
    parser.add_argument("--json", type=Path, help="write the measurements here")
    parser.add_argument("--page", type=Path, help="also write the docs' solver page here (docs/solvers.md)")


def run(args: argparse.Namespace) -> None:
    if args.episodes < 1:
        raise EtmpcError("--episodes must be at least 1")
    results = {}
    for task in args.tasks:
        results[task] = play(task, args.episodes, args.policy)
        for route, r in results[task].items():
            ms = r["ms"]
            it = r["iterations"]
            print(
                f"{task:22s} {route:9s} median {ms['median']:6.2f} ms  mean {ms['mean']:6.2f}  p99 {ms['p99']:6.2f}  "
                f"max {ms['max']:7.2f}  iterations {it['median']:.0f}/{it['mean']:.1f}/{it['max']}  failed {r['failed']}  "
                f"short {r['short']}  objective {r['objective_mean']:.4f}  task failures {r['task_failures']}",
                flush=True,
            )
    report = {"command": args.command, "policy": args.policy, "episodes": args.episodes, "machine": machine(), "tasks": results}
    if args.json:
        outputs.write_text(args.json, json.dumps(report, indent=1) + "\n")
    if args.page:
        outputs.write_text(args.page, page(report))
