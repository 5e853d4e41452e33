"""Experiments built from evaluations: the price sweep and its trade-off curve (``etmpc sweep``)."""
