"""One test-set episode under a recomputation policy, played exactly as `etmpc evaluate` plays it
(repeat 0 of the seed): every state with every plan's prediction, the recompute steps, the applied
and planned inputs with their bounds, and the episode's exogenous signals.

    python scripts/figure_trajectory.py cart_pendulum --policy every:3
    python scripts/figure_trajectory.py battery --policy threshold:0.05 --episode 7 --out traj.png
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import scores
from etmpc.views.figures import write_trajectory_png
from etmpc.policies import parse_policy
from etmpc.systems import check_name, names
from etmpc.evaluation.workers import context, play_test_episode


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line on stderr, exit code 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def slug(spec: str) -> str:
    """A file-name part for a policy spec: every:3 -> every-3, rl:runs/c/seed0/last.json -> rl-runs-c-seed0-last."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", spec.removesuffix(".json")).strip("-.") or "policy"


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(description=__doc__.splitlines()[0])
    parser.add_argument("task", help=f"system: {' | '.join(names())}")
    parser.add_argument("--policy", required=True, metavar="SPEC", help="always | never | every:T | threshold:X | rl:PATH")
    parser.add_argument("--episode", type=int, default=0, help="test-set episode (default 0)")
    parser.add_argument("--seed", type=int, default=0, help="seed of a stochastic policy's draws, as in evaluate (default 0)")
    parser.add_argument("--out", type=Path, default=None, metavar="PNG",
                        help="default results/trajectory_<task>_<policy>_ep<I>.png")
    args = parser.parse_args(argv)

    try:
        check_name(args.task)
        system = context(args.task)[0]
        policy = parse_policy(args.policy, system.error_weights, system.domain)
        played = play_test_episode(args.task, policy, args.seed, 0, args.episode)  # as evaluate plays it
    except EtmpcError as exc:
        parser.error(str(exc))
    out = args.out or Path("results") / f"trajectory_{args.task}_{slug(args.policy)}_ep{args.episode}.png"
    if out.exists() and out.is_dir():
        parser.error(f"--out {out} is a directory")

    traj, episode = played.trajectory, played.episode
    objective, control = scores(system, traj)
    what = "cost" if system.objective_sense == "min" else "profit"
    title = (f"{system.domain} test-set episode {args.episode}, policy {args.policy}: {what} {objective:.5g} "
             f"({control:.5g} without computations), {traj.recomputes} computations")
    try:
        write_trajectory_png(out, system, traj, title, system.signals(episode))
    except OSError as exc:
        parser.error(f"cannot write {out}: {exc.strerror or exc}")
    print(f"episode {args.episode} under {args.policy}: objective {objective!r}, {traj.recomputes} computations, "
          f"{traj.solver_failures} solver failures")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
