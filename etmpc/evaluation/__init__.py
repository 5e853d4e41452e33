"""Measuring policies on stored episodes: test sets (:mod:`~etmpc.evaluation.testsets`), where
episodes run and how their draws are seeded (:mod:`~etmpc.evaluation.workers`; the worker processes,
local or Ray, :mod:`~etmpc.evaluation.backends`), ``etmpc evaluate`` (:mod:`~etmpc.evaluation.evaluate`)
and ``etmpc bench`` (:mod:`~etmpc.evaluation.bench`).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop`` and
``etmpc.policies``; not ``etmpc.views``, which stands above it: a recording is written by the recorder its
caller gives ``evaluate`` (``recorder=``; :func:`etmpc.evaluate` gives Rerun's).
"""
