import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from etmpc.evaluation import testsets as testset  # noqa: E402
from etmpc.systems.battery.system import BatterySystem  # noqa: E402
from etmpc.systems.cart_pendulum.system import CartPendulumSystem  # noqa: E402


@pytest.fixture(scope="session")
def cart_system():
    return CartPendulumSystem()


@pytest.fixture(scope="session")
def cart_testset(cart_system):
    return testset.load(testset.default_path("cart_pendulum", "balance"), "cart_pendulum", "balance")


@pytest.fixture(scope="session")
def battery_system():
    return BatterySystem()


@pytest.fixture(scope="session")
def battery_testset(battery_system):
    return testset.load(testset.default_path("battery", "trading"), "battery", "trading")
