"""``sb3:`` on a task with compute levels (``cart_pendulum/kicks_levels``: keep, one SQP iteration, a full
solve, ``Discrete(3)``): a three-action network read as data decides as SB3's ``predict(deterministic=True)``
does (torch's argmax: a tie is the lowest action), near ties included; a model whose actions are not
its task's is refused in one line; a model of ``cart_pendulum/kicks`` (two actions) plays on its
variants with time in the loop, answering keep or a full solve."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

import gymnasium  # noqa: E402

from etmpc.cli import main  # noqa: E402
from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.envs.gym import trigger_spaces  # noqa: E402
from etmpc.evaluation.evaluate import evaluate  # noqa: E402
from etmpc.learning.ppo_settings import save_model  # noqa: E402
from etmpc.policies import parse_policy  # noqa: E402
from etmpc.policies.sb3 import TOLERANCE, Network, SB3Policy, load_sb3  # noqa: E402

from tests.conftest import REPO

KICKS, LATE, LEVELS = "cart_pendulum/kicks", "cart_pendulum/kicks_late", "cart_pendulum/kicks_levels"
SIZE = 18  # the kicks tasks' observation
KICKS_MODEL = REPO / "policies" / "cart_pendulum" / "kicks" / "ppo.zip"  # two actions, trained on kicks


class _Spaces(gymnasium.Env):
    """An environment with the trigger environment's spaces, for building a model (never stepped)."""

    def __init__(self, actions: int):
        self.observation_space, self.action_space = trigger_spaces(SIZE, actions)

    def reset(self, *, seed=None, options=None):
        return np.zeros(SIZE, np.float32), {}

    def step(self, action):
        return np.zeros(SIZE, np.float32), 0.0, True, False, {}


def _saved(directory: Path, name: str, actions: int, edit=None):
    """A PPO ``MlpPolicy`` with ``actions`` actions (its action layer edited in place by ``edit``), saved
    with etmpc's :func:`save_model`, without a description: ``(model, path)``."""
    from stable_baselines3 import PPO

    model = PPO(
        "MlpPolicy", _Spaces(actions), seed=0, device="cpu", n_steps=8, batch_size=8, policy_kwargs={"net_arch": [16, 16]}
    )
    if edit is not None:
        with torch.no_grad():
            edit(model.policy.action_net.weight, model.policy.action_net.bias, torch.Generator().manual_seed(1))
    path = directory / f"{name}.zip"
    save_model(model, path)
    return model, path


def _observations(count: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 2.0, size=(count, SIZE)).astype(np.float32)


def _compared(model, network: Network, observations) -> tuple[list[int], list[int], int]:
    """SB3's deterministic action and the numpy network's on each observation, and how many of the
    numpy decisions were made again exactly (the best two logits within TOLERANCE)."""
    theirs = [int(model.predict(x, deterministic=True)[0]) for x in observations]
    ours = [network.action(x) for x in observations]
    close = 0
    for x in observations:
        logits = np.sort(network.logits(x))
        close += logits[-1] - logits[-2] <= TOLERANCE
    return theirs, ours, close


def _random(weight, bias, generator):
    weight.copy_(torch.randn(weight.shape, generator=generator))
    bias.copy_(torch.randn(bias.shape, generator=generator) * 0.3)


def test_a_three_action_network_decides_as_sb3s_predict_on_random_observations(tmp_path):
    torch.set_num_threads(1)
    model, path = _saved(tmp_path, "random", 3, _random)
    policy = load_sb3(str(path), LEVELS)
    assert policy.network.actions == 3 and not policy.normalises
    theirs, ours, _ = _compared(model, policy.network, _observations(1500, 0))
    assert ours == theirs and set(ours) == {0, 1, 2}


def _near_tie(same: list[tuple[int, int]], biases: tuple[float, float, float]):
    """Small random action rows, row ``b`` a copy of row ``a`` for each ``(a, b)`` in ``same``, and
    ``biases``: two copied rows' logits are their biases' difference apart at every observation (8e-7:
    within TOLERANCE, far above float32's rounding of logits near 0.05; 0: an exact tie)."""

    def edit(weight, bias, generator):
        weight.copy_(0.05 * torch.randn(weight.shape, generator=generator))
        for a, b in same:
            weight[b] = weight[a]
        bias.copy_(torch.tensor(biases))

    return edit


@pytest.mark.parametrize(
    "case, edit, chosen",
    [
        ("1-ahead-of-0", _near_tie([(0, 1)], (0.0, 8e-7, 0.0)), {1, 2}),
        ("0-ahead-of-1", _near_tie([(0, 1)], (8e-7, 0.0, 0.0)), {0, 2}),
        ("2-ahead-of-1", _near_tie([(1, 2)], (0.0, 0.0, 8e-7)), {0, 2}),
        ("0-ties-1", _near_tie([(0, 1)], (0.0, 0.0, 0.0)), {0, 2}),
        ("1-ties-2", _near_tie([(1, 2)], (0.0, 0.0, 0.0)), {0, 1}),
        ("0-ties-2", _near_tie([(0, 2)], (0.0, 0.0, 0.0)), {0, 1}),
        ("all-tie", _near_tie([(0, 1), (0, 2)], (0.0, 0.0, 0.0)), {0}),
    ],
)
def test_near_ties_are_decided_exactly_and_a_tie_is_the_lowest_action_as_torchs_argmax_gives(case, edit, chosen, tmp_path):
    torch.set_num_threads(1)
    model, path = _saved(tmp_path, case, 3, edit)
    network = load_sb3(str(path), LEVELS).network
    theirs, ours, close = _compared(model, network, _observations(300, 1))
    assert ours == theirs
    assert close > 50  # decided by the exact sums, many times
    assert set(ours) == chosen  # of two rows 8e-7 apart the lower logit's, of two tied the higher action's, never


def test_a_tie_by_hand_goes_to_the_lowest_action_and_a_nan_observation_keeps():
    network = Network([], (np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3)))
    assert network.action(np.array([1.0, 1.0, 1.0], dtype=np.float32)) == 0
    assert network.action(np.array([0.0, 1.0, 1.0], dtype=np.float32)) == 1
    assert network.action(np.array([0.0, 1.0, 1 + 2**-23], dtype=np.float32)) == 2  # larger by one ulp: exact
    assert network.action(np.array([0.0, 1.0, 1 + 10 * TOLERANCE], dtype=np.float32)) == 2
    assert network.action(np.array([0.0, np.nan, 1.0], dtype=np.float32)) == 0


def _one_line(call) -> str:
    with pytest.raises(EtmpcError) as refused:
        call()
    message = str(refused.value)
    assert len(message.splitlines()) == 1, message
    return message


def _describe(model: Path, task: str) -> None:
    """The shipped kicks model's description beside ``model``, naming ``task``."""
    meta = json.loads(KICKS_MODEL.with_suffix(".json").read_text())
    model.with_suffix(".json").write_text(json.dumps(dict(meta, task=task)))


def test_a_model_whose_actions_are_not_its_tasks_is_refused_in_one_line(tmp_path, capsys):
    _, three = _saved(tmp_path, "three", 3)
    _, two = _saved(tmp_path, "two", 2)
    says = _one_line(lambda: load_sb3(str(three), KICKS))
    assert says == (
        f"sb3:{three} takes observations of shape (18,) and '3' actions; the trigger environment has (18,) "
        "and 2 (keep, recompute) on cart_pendulum/kicks"
    )
    says = _one_line(lambda: load_sb3(str(two), LEVELS))
    assert "and '2' actions; the trigger environment has (18,) and 3 (keep, one SQP iteration, a full solve) on " in says
    assert main(["evaluate", "--task", KICKS, "--policy", f"sb3:{three}", "--episodes", "1", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "and '3' actions" in err and "Traceback" not in err, err
    # With a description: a levels model plays on its own task alone; a two-action one that says it
    # was trained on kicks_levels is refused, and so is a three-action one that says kicks.
    _describe(three, LEVELS)
    assert load_sb3(str(three), LEVELS).network.actions == 3
    for task in (KICKS, LATE):
        assert _one_line(lambda: load_sb3(str(three), task)).endswith(f"was trained on {LEVELS!r}, not {task!r}")
    _describe(two, LEVELS)
    assert "and '2' actions" in _one_line(lambda: load_sb3(str(two), LEVELS))
    _describe(three, KICKS)
    assert "and '3' actions" in _one_line(lambda: load_sb3(str(three), LEVELS))


class _Recorded:
    """A policy's answers, recorded (a policy object beside the spec, in the same evaluation)."""

    stochastic = False
    spec = "recorded"

    def __init__(self, policy: SB3Policy):
        self.policy, self.answers = policy, []

    def decide(self, s, rng):
        answer = self.policy.decide(s, rng)
        self.answers.append(answer)
        return answer


def test_a_kicks_model_plays_on_kicks_with_time_in_the_loop_answering_keep_or_solve():
    """Its world and observation are kicks'; on kicks_levels its recompute is a full solve."""
    shipped = load_sb3(str(KICKS_MODEL), KICKS)
    for task in (LATE, LEVELS):
        policy = parse_policy(f"sb3:{KICKS_MODEL}", task)
        assert isinstance(policy, SB3Policy) and policy.network.actions == 2 and policy.task == KICKS
        np.testing.assert_array_equal(policy.network.head[0], shipped.network.head[0])
    recorded = _Recorded(load_sb3(str(KICKS_MODEL), LEVELS))
    result = evaluate(task=LEVELS, policies=[recorded, f"sb3:{KICKS_MODEL}"], episodes=1, workers=1, progress=False)
    runs = [(r.objective, r.recomputes) for r in result.runs]
    assert runs[0] == runs[1] and runs[0][1] > 0
    assert {type(a) for a in recorded.answers} == {bool} and set(recorded.answers) == {True, False}
