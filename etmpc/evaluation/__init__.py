"""Measuring policies on stored episodes: test sets (:mod:`~etmpc.evaluation.testsets`), where
episodes run and how their draws are seeded (:mod:`~etmpc.evaluation.workers`; the worker processes,
local or Ray, :mod:`~etmpc.evaluation.backends`), ``etmpc evaluate`` (:mod:`~etmpc.evaluation.evaluate`), ``etmpc render``
(:mod:`~etmpc.evaluation.render`) and ``etmpc bench`` (:mod:`~etmpc.evaluation.bench`).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop``,
``etmpc.policies`` and ``etmpc.views``.
"""
