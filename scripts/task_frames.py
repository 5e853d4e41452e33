"""The suite's pictures for the README and the docs (docs/tasks/<task>.png): a frame of each task with a
3-D scene, drawn mid-episode from its camera while ``every:3`` plays stored episode 0, and for the
battery (no scene) its episode's prices and production.

    MUJOCO_GL=egl python scripts/task_frames.py [--out docs/tasks] [--step 30] [--task TASK ...]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from etmpc.evaluation.workers import play_test_episode  # noqa: E402
from etmpc.policies import parse_policy  # noqa: E402
from etmpc.systems import folder_name, make_system, names  # noqa: E402
from etmpc.views.video import render_frames  # noqa: E402

PICTURE = {"cart_pendulum": "cart_pendulum", "cart_pendulum/kicks": "kicks", "battery": "battery", "reacher": "reacher"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/tasks"))
    parser.add_argument("--step", type=int, default=30, help="the step drawn (default 30)")
    parser.add_argument("--task", action="append", help="draw only these tasks (repeatable; default: every task)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for task in args.task or names():
        system = make_system(task)
        played = play_test_episode(task, parse_policy("every:3", system), 0, 0, 0)
        path = args.out / f"{PICTURE.get(task, folder_name(task))}.png"
        if system.camera is not None:
            frame = render_frames(system, system.make_env(), played.trajectory.states[args.step : args.step + 1], 480, 360)[0]
            plt.imsave(path, frame)
        else:
            signals = system.signals(played.episode)
            fig, axes = plt.subplots(len(signals), 1, figsize=(4.8, 3.6), sharex=True)
            for ax, (name, values) in zip(axes, signals.items()):
                ax.plot(values, lw=1)
                ax.set_ylabel(name.replace("_", " "), fontsize=7)
                ax.tick_params(labelsize=7)
            axes[-1].set_xlabel("step", fontsize=7)
            fig.tight_layout()
            fig.savefig(path, dpi=100)
            plt.close(fig)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
