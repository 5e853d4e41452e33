"""Recomputation policies: given the augmented state, decide whether to solve a new plan.

* :mod:`~etmpc.policies.fixed`: ``always``, ``never``, ``every:T``;
* :mod:`~etmpc.policies.threshold`: the event trigger ``threshold:X``;
* :mod:`~etmpc.policies.learned`: the logistic policy ``rl:PATH`` and its features;
* :mod:`~etmpc.policies.selftrigger`: the self-triggering policy ``self:PATH``;
* :mod:`~etmpc.policies.rollout`: ``rollout:BASE[:K[:H]]`` and the oracle ``oracle:BASE``, which
  simulate both answers with the loop;
* :mod:`~etmpc.policies.specs`: ``parse_policy``, which builds any of them from its spec.

A policy is anything with ``spec``, ``stochastic`` and ``decide(s, rng) -> bool`` (True: recompute
now), deciding from an :class:`AugmentedState`; both are the loop's (:mod:`etmpc.loop`), re-exported
here. When the plan runs out (age = N) the loop forces a recompute whatever the policy says.

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems`` and ``etmpc.loop``.
"""

from etmpc.loop import AugmentedState, Policy
from etmpc.policies.fixed import Always, Every, Never
from etmpc.policies.specs import parse_policy
from etmpc.policies.threshold import Threshold

__all__ = ["Always", "AugmentedState", "Every", "Never", "Policy", "Threshold", "parse_policy"]
