"""``kicks_noisy``: the kicks task with the controller reading the cart's position and the pole's angle, each
with Gaussian noise (1 cm, 10 mrad: an optical encoder's quantisation and a cheap potentiometer's noise, in
round figures), and neither velocity. An extended Kalman filter on the MPC's own predictor estimates the state
(:mod:`etmpc.systems.noisy`); the MPC, the LQR and the trigger see its estimate. The world, the episodes and
the price are kicks' (its test set's seed: scores pair with kicks' episode by episode); kicks' learned
policies play here too (``variant_of``), as learned on the exact state.
"""

from __future__ import annotations

from dataclasses import dataclass

from etmpc.control.sensing import Sensor
from etmpc.systems.cart_pendulum.kicks_system import EXOGENOUS_FEATURES, Config, KicksSystem, exogenous_features
from etmpc.systems.noisy import FILTER_FEATURES, WithFilterFeatures

#: What the controller reads: (cart position m, cart velocity, pole angle rad, pole rate), noise per entry.
SENSOR = Sensor(noise_std=(0.01, 0.0, 0.01, 0.0), measured=(True, False, True, False))


@dataclass(frozen=True)
class NoisyConfig(Config):
    sensor: Sensor = SENSOR  # the filter: kicks' (its process noise was chosen for this sensor)


class KicksNoisySystem(KicksSystem):
    Config = NoisyConfig
    task = "kicks_noisy"
    variant_of = "cart_pendulum/kicks"  # its world and episodes are kicks'; kicks' rl: policies play here too
    exogenous_feature_names = (*EXOGENOUS_FEATURES, *FILTER_FEATURES)
    exogenous_features = staticmethod(WithFilterFeatures(exogenous_features))
