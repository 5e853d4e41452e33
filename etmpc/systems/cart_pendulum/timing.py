"""The kicks task with time in the loop (:mod:`etmpc.control.timing`): the same world, episodes and
MPC as ``kicks``, with a controller whose solves take time.

* ``kicks_late``: every solve delivers its plan one control interval (0.1 s) after it started, from
  the state measured then; the kept plan and its feedback run meanwhile. The price stays 0.1 per solve.
* ``kicks_levels``: at a decision the policy keeps the plan, makes one SQP iteration from the shifted
  plan (a real-time iteration) or solves to convergence. Each is priced 0.05 per SQP iteration and
  takes ``ceil(iterations x 30 ms / 0.1 s)`` intervals, on a notional embedded target where one
  Gauss-Newton SQP iteration of this OCP (N = 20, four states, full multiple shooting) takes 30 ms.
  That figure is an assumption of the task, not a measurement (a desktop core is two orders of
  magnitude faster). A full solve takes more iterations after a jump or from a cold start.

Their test sets are ``kicks``' episodes (the same seed), so a policy's score with and without
latency is paired episode by episode.
"""

from __future__ import annotations

from dataclasses import dataclass

from etmpc.control.timing import Latency
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.cart_pendulum.kicks_system import Config, KicksSystem

#: The target platform of ``kicks_levels``: the time one SQP iteration takes there (an assumption).
PLATFORM = "a notional embedded target"


@dataclass(frozen=True)
class LateConfig(Config):
    latency: Latency = Latency(intervals=1)


@dataclass(frozen=True)
class LevelsConfig(Config):
    latency: Latency = Latency(iteration_s=0.03, platform=PLATFORM)
    compute_levels: bool = True
    recompute_price: float = 0.05  # per SQP iteration


class KicksLateSystem(KicksSystem):
    Config = LateConfig
    task = "kicks_late"
    variant_of = "cart_pendulum/kicks"  # its world, episodes and rl: policies are kicks'
    shield = ShieldRule(10)  # shield:BASE's rule, chosen on validation episodes: etmpc study shields


class KicksLevelsSystem(KicksSystem):
    Config = LevelsConfig
    task = "kicks_levels"
    variant_of = "cart_pendulum/kicks"
    # shield:BASE's rule, certified on 1,000 validation episodes (etmpc study shields --select certify): the cheapest
    # rule under which both shipped learners fail at most 0.05 more per episode than iterate:1 (95 %, paired); its
    # deviation is the event trigger's (threshold:0.3:iterate), which the learners then only add to
    shield = ShieldRule(10, 1.1, 0.3)
