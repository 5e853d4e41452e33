"""``waypoints_noisy``: the waypoints task with the controller reading the drone's position (2 cm: a motion-capture
or UWB fix), its attitude (10 mrad) and its body rates (a gyro, 0.02 rad/s), each with Gaussian noise, and not its
velocity. An extended Kalman filter on the MPC's own predictor estimates the state (:mod:`etmpc.systems.noisy`);
the MPC, the LQR, the trigger and the shield see its estimate. The world, the episodes and the price are
waypoints' (its test set's seed: scores pair with waypoints' episode by episode); waypoints' learned policies play
here too (``variant_of``), as learned on the exact state.
"""

from __future__ import annotations

from dataclasses import dataclass

from etmpc.control.sensing import Sensor
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.noisy import FILTER_FEATURES, WithFilterFeatures
from etmpc.systems.quadrotor.system import Config, QuadrotorSystem

#: What the controller reads, per state (position m, attitude rad, velocity m/s, body rates rad/s).
SENSOR = Sensor(noise_std=(0.02,) * 3 + (0.01,) * 3 + (0.0,) * 3 + (0.02,) * 3, measured=(True,) * 6 + (False,) * 3 + (True,) * 3)


@dataclass(frozen=True)
class NoisyConfig(Config):
    sensor: Sensor = SENSOR  # the filter: waypoints' (its process noise was chosen for this sensor)


class WaypointsNoisySystem(QuadrotorSystem):
    Config = NoisyConfig
    task = "waypoints_noisy"
    variant_of = "quadrotor/waypoints"  # its world and episodes are waypoints'; waypoints' rl: policies play here too
    exogenous_feature_names = (*QuadrotorSystem.exogenous_feature_names, *FILTER_FEATURES)
    exogenous_features = staticmethod(WithFilterFeatures(QuadrotorSystem.exogenous_features))
    # shield:BASE's rule on 1,000 validation episodes (etmpc study shields): no rule is certified within 0.05
    # failures per episode of every:7 (crashes that count tens of steps widen every interval), so the budget chose
    # it: the safest rule costing the learners at most 1 %; waypoints' 10:0.25 was no safer than no shield here
    shield = ShieldRule(15, 0.25)
