"""A trigger of your own, evaluated against the built-in ones on the stored test set.

    make example                          # from a fresh clone: sets up .venv, then runs this file
    python examples/my_trigger.py [--episodes N] [--workers W]

A policy is anything with ``spec``, ``stochastic`` and ``decide(s, rng) -> bool`` (True: recompute
now). ``s`` is what the loop shows it (``etmpc.loop.AugmentedState``): the state now (``s.x``), the
plan's prediction for now (``s.x_predicted``), the plan's age (``s.age``), the plan itself and the
task's observation. The same trigger from the command line, in this folder:

    etmpc evaluate --task cart_pendulum --policy every:3 --policy threshold:0.3 --policy py:my_trigger:AngleOrAge \\
        --against every:3

``DriftOrAge`` below reads nothing task-specific: ``etmpc score --policy py:my_trigger:DriftOrAge`` scores it on
every task of the suite against the stored references.
"""

import argparse
from dataclasses import dataclass

import numpy as np

import etmpc
from etmpc.evaluation.compare import format_against
from etmpc.evaluation.evaluate import format_table


@dataclass(frozen=True)
class AngleOrAge:
    """Recompute when the pole's angle has drifted from the plan's prediction, or the plan is old."""

    spec: str = "py:my_trigger:AngleOrAge"
    stochastic: bool = False  # decide draws nothing from the generator it is given
    angle_rad: float = 0.04
    max_age: int = 6

    def decide(self, s, rng) -> bool:
        return bool(abs(s.x[2] - s.x_predicted[2]) > self.angle_rad or s.age >= self.max_age)


@dataclass(frozen=True)
class DriftOrAge:
    """For any task: recompute when the state has drifted from the plan's prediction by more than
    ``relative`` of its size, or the plan is old. Score it on the whole suite, in this folder:

        etmpc score --policy py:my_trigger:DriftOrAge
    """

    spec: str = "py:my_trigger:DriftOrAge"
    stochastic: bool = False
    relative: float = 0.05
    max_age: int = 6

    def decide(self, s, rng) -> bool:
        drift = float(np.linalg.norm(s.x - s.x_predicted))
        return bool(drift > self.relative * (1.0 + float(np.linalg.norm(s.x_predicted))) or s.age >= self.max_age)


def main() -> None:
    parser = argparse.ArgumentParser(description="a trigger of your own against the built-in ones")
    parser.add_argument("--episodes", type=int, default=None, help="first N test-set episodes (default: all 100)")
    parser.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    args = parser.parse_args()
    result = etmpc.evaluate(
        "cart_pendulum", ["every:3", "threshold:0.3", AngleOrAge()], episodes=args.episodes, workers=args.workers, progress=False
    )
    print(format_table(result))
    print(format_against(result.to_json(), "every:3"))


if __name__ == "__main__":
    main()
