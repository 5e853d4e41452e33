"""The quadrotor page's flight figure: one stored test-set episode under two triggers, side by side in time.

    etmpc study quadrotor-flight [--episode 59] [--policy every:7 --policy rl:policies/quadrotor/waypoints/learned.json]
                                 [--out docs/tasks/quadrotor_flight.png]

Three panels on one time axis: the drone's distance from its waypoint (the waypoint changes drawn as
dotted lines), its altitude with the waypoint's and the ground's, and when each trigger computed a plan.
Each episode is played as ``etmpc evaluate`` plays it (``play_test_episode``: the stored episode, the
policy's draws of seed 0); the legend gives each one's objective, computations and failures.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import scores
from etmpc.evaluation.workers import play_test_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system
from etmpc.systems.quadrotor.task import GROUND_M  # a step below it is a failure
from etmpc.views import figures

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def _short(spec: str) -> str:
    """A spec with its file's folders dropped (``rl:policies/quadrotor/waypoints/learned.json`` as ``rl:learned.json``)."""
    kind, _, rest = spec.partition(":")
    return f"{kind}:{Path(rest).name}" if "/" in rest else spec


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episode", type=int, default=59, help="the stored test-set episode (default 59)")
    parser.add_argument(
        "--policy",
        action="append",
        default=None,
        help=f"a trigger (repeatable, at most {len(COLOURS)}; default: every:7 and the shipped DPI)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/tasks/quadrotor_flight.png"),
        help="the figure (default docs/tasks/quadrotor_flight.png)",
    )


def run(args: argparse.Namespace) -> None:
    specs = args.policy or ["every:7", "rl:policies/quadrotor/waypoints/learned.json"]
    if len(specs) > len(COLOURS):
        raise EtmpcError(f"at most {len(COLOURS)} policies")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    system = make_system("quadrotor")
    dt = system.control_interval_s
    fig, (distance, altitude, computed) = plt.subplots(
        3, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1]}
    )
    target = None
    for row, (spec, colour) in enumerate(zip(specs, COLOURS)):
        played = play_test_episode(system.name, parse_policy(spec, system), 0, 0, args.episode)
        traj = played.trajectory
        target = played.episode.target
        steps = traj.steps
        position = traj.states[1 : steps + 1, :3]  # the state after each interval
        t = dt * np.arange(1, steps + 1)
        failures = system.failures(traj, played.episode)
        objective, _ = scores(system, traj)
        label = f"{_short(spec)}: objective {objective:.1f}, {traj.recomputes} computations, {failures} failure steps"
        distance.plot(t, np.linalg.norm(position - target[:steps], axis=1), color=colour, label=label)
        altitude.plot(t, position[:, 2], color=colour)
        made = dt * np.flatnonzero(traj.recompute[:steps])
        computed.vlines(made, row + 0.1, row + 0.9, color=colour, linewidth=1.2)
    assert target is not None  # every episode played has its waypoints, and at least one was played
    changes = dt * (np.flatnonzero(np.any(np.diff(target, axis=0) != 0, axis=1)) + 1)
    for ax in (distance, altitude, computed):
        for c in changes:
            ax.axvline(c, color="0.6", linestyle=":", linewidth=1)
    altitude.step(dt * np.arange(len(target)), target[:, 2], where="post", color="black", linestyle="--", label="waypoint")
    altitude.axhline(GROUND_M, color="saddlebrown", linewidth=1, label="ground")
    distance.set_ylabel("distance from\nwaypoint (m)")
    altitude.set_ylabel("altitude z (m)")
    computed.set_yticks([i + 0.5 for i in range(len(specs))], [_short(s) for s in specs])
    computed.set_ylim(0, len(specs))
    computed.set_xlabel("time (s); dotted: the waypoint changes")
    distance.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=8, frameon=False)
    altitude.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"quadrotor, stored test-set episode {args.episode}")
    for ax in (distance, altitude):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    figures.save_png_atomically(fig, args.out, dpi=110)
    print(f"wrote {args.out}")
