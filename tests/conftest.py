import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from etmpc.evaluation import testsets as testset  # noqa: E402
from etmpc.loop import ClosedLoop  # noqa: E402
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


@pytest.fixture
def features_while_kept():
    """``(features, last state)``: a task's exogenous features at each of ``steps`` decisions while
    the plan made at step 0 of ``episode`` is kept (the first at step 1)."""

    def play(system, episode, steps: int = 4):
        loop = ClosedLoop(system, system.make_env()).reset(episode)
        loop.step(True)  # the plan, made at step 0
        seen = []
        for _ in range(steps):
            s = loop.augmented_state()
            seen.append(system.exogenous_features(s))
            loop.step(False)
        return seen, s

    return play
