"""Whole studies built from evaluations and training runs: ``etmpc reproduce``, the paper's
experiments with their report (:mod:`~etmpc.experiments.reproduce`, :mod:`~etmpc.experiments.summary`,
:mod:`~etmpc.experiments.report`), and ``etmpc sweep``, the trade-off curve over prices of a
recompute (:mod:`~etmpc.experiments.sweep`, :mod:`~etmpc.experiments.pareto`); and the studies behind the
results pages, ``etmpc study NAME`` (:mod:`~etmpc.experiments.studies`, one module each, sharing one runner).

This package may import every floor below it: ``etmpc.common`` up to ``etmpc.learning``.
"""
