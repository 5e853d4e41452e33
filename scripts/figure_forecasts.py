"""The paper's Figure 1: true production and price of a battery test-set episode, with the forecasts
given to the MPC at each of its computations under one or more recomputation policies.

    python scripts/figure_forecasts.py                                   # every:20, episode 0
    python scripts/figure_forecasts.py --policy every:20 --policy always --episode 3 --out fig1.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from etmpc.evaluation import testsets as testset
from etmpc.common.errors import EtmpcError
from etmpc.views.figures import forecast_figure, save_png_atomically
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", action="append", metavar="SPEC", help="recomputation policy (repeatable; default every:20)")
    parser.add_argument("--episode", type=int, default=0, help="test-set episode (default 0)")
    parser.add_argument("--seed", type=int, default=0, help="seed of a stochastic policy's draws")
    parser.add_argument("--out", type=Path, default=Path("results/figure1_battery_forecasts.png"))
    args = parser.parse_args(argv)

    system = make_system("battery")
    try:
        stored = testset.load(testset.default_path(system.domain, system.task), system.domain, system.task)
        episode = system.episode_from_arrays(stored.episode_arrays(args.episode))
        policies = [(spec, parse_policy(spec, system.error_weights)) for spec in (args.policy or ["every:20"])]
    except EtmpcError as exc:
        parser.error(str(exc))
    env = system.make_env()
    runs = [(spec, run_episode(system, env, policy, np.random.default_rng(args.seed), episode)) for spec, policy in policies]
    fig = forecast_figure(episode, runs, system.config.battery.interval_s, system.terminal_price)
    save_png_atomically(fig, args.out, dpi=120)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
