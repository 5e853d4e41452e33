"""The studies behind the results pages, one module each, run by ``etmpc study NAME`` and sharing one runner
(:mod:`~etmpc.experiments.studies.runner`: their common options, their JSON and page, what made them).

Each study plays policies on training-distribution episodes or the stored test sets and writes a page of
``docs/results/`` (or a figure of the docs); ``etmpc study --list`` lists them. This module only names them:
a study's module is imported when it runs, so that listing them loads nothing heavy.

This package may import every floor below it: ``etmpc.common`` up to ``etmpc.views``.
"""

from __future__ import annotations

import importlib
from typing import NamedTuple, cast

from etmpc.experiments.studies.runner import Study


class Entry(NamedTuple):
    """A registered study: its module (in this package) and what it makes, in one line."""

    module: str
    summary: str


#: Every study, by the name ``etmpc study NAME`` takes.
STUDIES = {
    "estimators": Entry("estimators", "the noisy variants' filters, chosen on training episodes: results/estimators.md"),
    "failure-cost": Entry(
        "failure_cost", "safety in learning, its weight chosen on validation episodes: results/failure_cost.md"
    ),
    "gpomdp": Entry("gpomdp", "why the paper's learner loses: its gradient, an ablation and a fix: results/gpomdp.md"),
    "learners": Entry("learners", "DPI and PPO compared over training seeds, and the policies they ship: results/learners.md"),
    "levels": Entry("levels", "what a trigger that chooses how much to compute gains, and a learner could: results/levels.md"),
    "quadrotor-flight": Entry("quadrotor_flight", "the quadrotor page's flight figure: one episode under two triggers"),
    "robustness": Entry("robustness", "the triggers against sensor noise and gusts: results/robustness.md"),
    "safety": Entry(
        "safety", "the shipped learners' failures against the best fixed schedule, on fresh episodes: results/safety.md"
    ),
    "shields": Entry("shields", "each safety task's shield rule, chosen on validation episodes: results/shields.md"),
    "solvers": Entry("solvers", "the MPC's two solver routes side by side, on the same episodes: solvers.md"),
    "timing": Entry("timing", "time in the loop: how the ranking of triggers changes when a solve takes time: results/timing.md"),
}


def load(name: str) -> Study:
    """The module of the study registered as ``name`` (a ``KeyError`` if none is)."""
    module = importlib.import_module(f"{__name__}.{STUDIES[name].module}")
    return cast(Study, module)  # a study module defines arguments() and run(): tests/experiments/test_studies.py
