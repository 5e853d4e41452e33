"""One-step prediction error of the MPC's analytic model against the MuJoCo plant, both settings.

    python scripts/model_mismatch.py [--samples 500] [--seed 0]
"""

from __future__ import annotations

import argparse

from etmpc.systems.cart_pendulum.mismatch import table
from etmpc.systems.cart_pendulum.model import STATE_NAMES

UNITS = ("m", "m/s", "rad", "rad/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rows = table(args.samples, args.seed)
    print(f"one-step (0.1 s) prediction error, no disturbance, {args.samples} random states and inputs")
    print(f"{'plant':<12}{'stat':<6}" + "".join(f"{f'{n} ({u})':>30}" for n, u in zip(STATE_NAMES, UNITS)))
    for row in rows:
        for stat in ("rms", "max"):
            print(f"{row['plant']:<12}{stat:<6}" + "".join(f"{v:>30.2e}" for v in row[stat]))


if __name__ == "__main__":
    main()
