"""The jumps task with time in the loop (:mod:`etmpc.control.timing`): the same world, episodes and
MPC as ``jumps``, with every solve delivering its plan one control interval after it
started, from the state measured then (``jumps_late``; an interval is 0.1 s). The kept plan and its feedback run meanwhile;
the price stays 0.1 per solve. Its test set is ``jumps``' episodes (the same seed), so a policy's
score with and without latency is paired episode by episode.
"""

from __future__ import annotations

from dataclasses import dataclass

from etmpc.control.timing import Latency
from etmpc.systems.reacher.system import Config, ReacherSystem


@dataclass(frozen=True)
class LateConfig(Config):
    latency: Latency = Latency(intervals=1)


class JumpsLateSystem(ReacherSystem):
    Config = LateConfig
    task = "jumps_late"
    variant_of = "reacher"  # its world, episodes and rl: policies are jumps'
