"""PPO on a task with compute levels (``cart_pendulum/kicks_levels``, ``Discrete(3)``: keep, one SQP
iteration, a full solve): a tiny run finishes, with its reward taken against ``iterate:T``; its
``sb3:`` policy answers levels, and plays one SQP iteration where its network says so."""

import io
import json
import zipfile

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from etmpc.control.timing import ITERATE, KEEP, SOLVE  # noqa: E402
from etmpc.evaluation.evaluate import evaluate  # noqa: E402
from etmpc.learning.ppo import PpoSettings, train_ppo  # noqa: E402
from etmpc.loop import ClosedLoop  # noqa: E402
from etmpc.policies.sb3 import SB3Policy, load_sb3  # noqa: E402
from etmpc.systems import system_key  # noqa: E402

LEVELS = "cart_pendulum/kicks_levels"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo_levels")
    settings = PpoSettings(
        timesteps=512, checkpoints=2, validation_episodes=1, n_steps=128, batch_size=128, n_epochs=1, reward_baseline="iterate:3"
    )
    return out, train_ppo(LEVELS, out, settings, workers=1)


def test_a_tiny_run_on_a_task_with_compute_levels_finishes_with_a_three_action_model(run):
    out, result = run
    assert result["task"] == LEVELS and result["environment_steps"] == 512 and len(result["checkpoints"]) == 2
    assert (out / "selected.zip").read_bytes() == (out / result["selected"]).read_bytes()
    meta = json.loads((out / "selected.json").read_text())
    assert meta["task"] == LEVELS and meta["settings"]["reward_baseline"] == "iterate:3"
    with zipfile.ZipFile(out / "selected.zip") as saved:
        assert json.loads(saved.read("data"))["action_space"]["n"] == "3"
    assert load_sb3(str(out / "selected.zip"), LEVELS).network.actions == 3


def _answers(policy: SB3Policy) -> list:
    """The policy's answers at every unforced decision of a training-distribution episode it plays."""
    system = system_key(LEVELS).make()
    loop, answers = ClosedLoop(system, system.make_env()).reset(system.draw_episode(np.random.default_rng(0))), []
    while not loop.done:
        s = loop.augmented_state()
        if s is not None:
            answers.append(policy.decide(s, None))
        loop.step(answers[-1] if s is not None else KEEP)
    return answers


def _leaning_to(model, path, action: int):
    """A copy of ``model`` (and its description) at ``path``, its action layer's bias moved far towards ``action``."""
    with zipfile.ZipFile(model) as source, zipfile.ZipFile(path, "w") as target:
        for info in source.infolist():
            content = source.read(info)
            if info.filename == "policy.pth":
                state = torch.load(io.BytesIO(content), weights_only=True)
                state["action_net.bias"][action] += 1e3
                buffer = io.BytesIO()
                torch.save(state, buffer)
                content = buffer.getvalue()
            target.writestr(info, content)
    path.with_suffix(".json").write_text(model.with_suffix(".json").read_text())
    return path


def test_its_sb3_policy_answers_levels_and_plays_an_sqp_iteration_where_its_network_says_so(run, tmp_path):
    out, _ = run
    answers = _answers(load_sb3(str(out / "selected.zip"), LEVELS))
    assert len(answers) > 10 and {type(a) for a in answers} == {int} and set(answers) <= {KEEP, ITERATE, SOLVE}
    # The same network leaning to each action: the sb3: spec keeps, iterates or solves at every decision.
    specs = {
        level: f"sb3:{_leaning_to(out / 'selected.zip', tmp_path / f'{level}.zip', level)}" for level in (KEEP, ITERATE, SOLVE)
    }
    assert set(_answers(load_sb3(specs[ITERATE][4:], LEVELS))) == {ITERATE}
    fixed = {KEEP: "never", ITERATE: "iterate:1", SOLVE: "always"}
    result = evaluate(task=LEVELS, policies=[*specs.values(), *fixed.values()], episodes=1, workers=1, progress=False)
    runs = {r.policy: (r.objective, r.recomputes) for r in result.runs}
    assert [runs[specs[level]] for level in fixed] == [runs[fixed[level]] for level in fixed]
    assert len({runs[spec] for spec in specs.values()}) == 3
