"""Sample efficiency: the steps a learner run simulated, counted from its files, are the steps its
simulations really took (counted here at the plant, one call per control interval)."""

import json

import pytest

from etmpc.experiments import efficiency
from etmpc.learning import dpi
from etmpc.learning.config import TrainConfig
from etmpc.learning.train import train
from etmpc.systems import make_system
from etmpc.systems.cart_pendulum.task import Balance


@pytest.mark.slow
def test_dpis_count_is_every_interval_its_loop_and_rollouts_simulated(tmp_path, monkeypatch):
    calls = []
    original = Balance.after_step

    def counted(self, physics):  # every simulated control interval, the loop's and the rollouts' alike
        calls.append(1)
        return original(self, physics)

    monkeypatch.setattr(Balance, "after_step", counted)
    system = make_system("cart_pendulum")
    steps = system.episode_steps
    config = TrainConfig(
        "cart_pendulum",
        seeds=(0,),
        episodes=2,
        eval_every=2,
        eval_episodes=1,
        normalisation_episodes=1,
        algorithm="dpi",
        features="error",
        validation_episodes=1,
        dpi=dpi.Settings(futures=2, horizon=5, states_per_episode=3, bases=("always", "every:3"), selection_episodes=1),
    )
    train(config, tmp_path, workers=1, progress=False)
    checkpoint = json.loads((tmp_path / "checkpoint.json").read_text())
    curve = json.loads((tmp_path / "curve.json").read_text())
    baselines = {"runs": [{"policy": "always", "episode": 0, "objective": 1.0, "finite": True}]}
    points = efficiency.dpi_points(checkpoint, curve, baselines, "always", "min", steps)
    # What train also played, which is no learning: the test-set curve (2 evaluations of 1 episode) and
    # the validation episode that chooses the seed.
    reporting = 2 * steps + 1 * steps
    assert points[-1]["simulated_steps"] - points[0]["simulated_steps"] > 2 * steps  # the rollouts are in it
    assert points[-1]["simulated_steps"] + reporting == len(calls)
    assert points[0]["simulated_steps"] == (1 + 2) * steps  # normalisation, then the choice of pi_0 among 2 bases
