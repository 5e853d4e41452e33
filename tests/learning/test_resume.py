"""A resumed run is the run it claims to be, and its saved state is read as data: every learner refuses, in one
line and before any work, to resume a run (under way or finished) of another task, price, options or settings; and
each field of each learner's saved state (checkpoint.json, resume.json, resume_normalize.json, training.json, a
self-trigger's selected.json) is checked as it is read, a bad one named with its file."""

import copy
import json
import shutil

import pytest

from etmpc.common.errors import EtmpcError
from etmpc.learning.base import learner_class
from etmpc.learning.checkpoint import state_from_json
from etmpc.learning.runner import run
from etmpc.systems import system_key
from tests.learning.test_learners import SEEDS, TINY, _stopped_ppo_run, files, tiny

TASK = {"gpomdp": "battery", "dpi": "battery", "self": "cart_pendulum", "ppo": "battery"}
SHOWN = {"battery": "battery/trading", "cart_pendulum": "cart_pendulum/balance"}
OPTION = {"battery": ("battery.compute_power_kw", "0.5"), "cart_pendulum": ("disturbances.angular_std_rad_s2", "0.5")}
AGAIN = "; start the run again in another --out"


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """``finished(name)``: a tiny finished run of learner ``name`` (trained once per module), to be copied."""
    made = {}

    def get(name: str):
        if name not in made:
            if name == "ppo":
                pytest.importorskip("stable_baselines3")
            made[name] = tmp_path_factory.mktemp(name) / "run"
            run(tiny(name), TASK[name], made[name], SEEDS[name], progress=False)
        return made[name]

    return get


def _resume(name, out, key=None, **settings):
    cls = learner_class(name)
    return run(cls(cls.Settings(**{**TINY[name], **settings})), key or TASK[name], out, SEEDS[name], resume=True, progress=False)


@pytest.mark.parametrize("name", ["gpomdp", "dpi", "self", "ppo"])
def test_every_learner_refuses_to_resume_a_finished_run_of_another_task_price_options_or_settings(name, finished, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished(name), out)
    before, task = files(out), TASK[name]
    option = OPTION[task]
    asked = [
        (system_key(task, 0.5), {}, f"holds a {name} run on {SHOWN[task]}, not {SHOWN[task]}@0.5; resume it with that task"),
        (system_key(task, None, (option,)), {}, f"holds a {name} run on {SHOWN[task]}, not {SHOWN[task]} --option {option[0]}"),
        (None, {"validation_episodes": 3}, "different settings (validation_episodes: "),
    ]
    for key, settings, says in asked:
        with pytest.raises(EtmpcError) as refused:
            _resume(name, out, key, **settings)
        assert says in str(refused.value) and "choose another --out" in str(refused.value)
    assert files(out) == before  # nothing trained, nothing written
    _resume(name, out)  # the run asked for: resumed (finished, it writes nothing again)
    assert files(out) == before


def test_a_stopped_ppo_run_resumes_only_as_the_run_it_was_its_state_read_field_by_field(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    from etmpc.learning.ppo_state import description

    _stopped_ppo_run(tmp_path, monkeypatch)
    out = tmp_path / "cut"
    resume, normalize = out / "checkpoints" / "resume.json", out / "checkpoints" / "resume_normalize.json"
    state, statistics = json.loads(resume.read_text()), json.loads(normalize.read_text())
    before = files(out)
    with pytest.raises(EtmpcError, match=r"resume.json holds a ppo run made with different settings \(n_epochs: 1 in"):
        _resume("ppo", out, n_epochs=2)
    [entry] = state["checkpoints"]
    doctored = [
        (resume, {k: v for k, v in state.items() if k != "task"}, "has no field 'task'"),  # once, not checked at all
        (resume, dict(state, task=7), "task must be text, got 7"),
        (resume, dict(state, checkpoints=[dict(entry, wall_seconds=float("inf"))]), "checkpoints[0].wall_seconds must be"),
        (resume, dict(state, checkpoints=[dict(entry, simulated_steps=-1)]), "checkpoints[0]: its steps are 256 and -1"),
        (
            resume,
            dict(state, checkpoints=[dict(entry, timesteps=128)]),
            "its checkpoints are at [128] steps, not the run's [256]",
        ),
        (resume, dict(state, version=True), "version must be a whole number"),
        (normalize, {"obs_rms": statistics["obs_rms"]}, "has no field 'ret_rms'"),
        (normalize, _edit(statistics, "obs_rms", "mean", 0, "1.5"), "obs_rms.mean[0] is '1.5', not a number"),
        (normalize, _edit(statistics, "obs_rms", "var", 0, -1.0), "obs_rms.var[0] is -1.0, below the 0"),
        (normalize, _edit(statistics, "obs_rms", "mean", None, [0.0]), "obs_rms holds 1 and "),
        (normalize, _edit(statistics, "ret_rms", "count", None, True), "ret_rms.count must be a number (finite), got True"),
    ]
    for path, content, says in doctored:
        original = path.read_text()
        path.write_text(json.dumps(content).replace("Infinity", "1e999"))  # 1e999: a JSON number read as inf
        with pytest.raises(EtmpcError) as refused:
            _resume("ppo", out)
        message = str(refused.value)
        assert says in message and message.startswith(str(path)) and message.endswith(AGAIN), (says, message)
        path.write_text(original)
    assert files(out) == before
    meta = out / entry["file"].replace(".zip", ".json")
    key, settings = system_key("battery"), state["settings"]
    assert description(meta, key, 256, settings)["timesteps"] == 256  # the checkpoint's description, as choose reads it
    with pytest.raises(EtmpcError, match=r"step_00000256.json is corrupt \(its timesteps and settings are not"):
        description(meta, key, 512, settings)
    meta.write_text(json.dumps(dict(json.loads(meta.read_text()), observation_mean="x")))
    with pytest.raises(EtmpcError, match="observation_mean is not a list of numbers"):
        description(meta, key, 256, settings)


def _edit(data: dict, record: str, field: str, index, value) -> dict:
    edited = copy.deepcopy(data)
    if index is None:
        edited[record][field] = value
    else:
        edited[record][field][index] = value
    return edited


def test_a_finished_ppo_runs_training_json_is_read_field_by_field(finished, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished("ppo"), out)
    path = out / "training.json"
    state = json.loads(path.read_text())
    last = state["checkpoints"][-1]
    doctored = [
        (dict(state, wall_seconds="12 s"), "wall_seconds must be a number (finite), got '12 s'"),  # printed as a number
        ({k: v for k, v in state.items() if k != "task"}, "has no field 'task'"),
        (dict(state, torch=2), "torch must be text, got 2"),
        (dict(state, workers=0), "its workers must be >= 1"),
        (dict(state, objective_sense="best"), "objective_sense is 'best', not max or min"),
        (dict(state, environment_steps=4096), "environment_steps and simulated_steps must be its last checkpoint's"),
        (dict(state, selected="checkpoints/step_00000128.zip"), "selected is 'checkpoints/step_00000128.zip', not one"),
        (dict(state, checkpoints=state["checkpoints"][:1]), "its checkpoints are at [256] steps, not the run's [256, 512]"),
        (dict(state, checkpoints=[*state["checkpoints"][:-1], dict(last, validation_objective=None)]), "validation_objective"),
        (
            dict(state, checkpoints=[*state["checkpoints"][:-1], dict(last, file="checkpoints/step_00000256.zip")]),
            "is not the file",
        ),
    ]
    before = files(out)
    for content, says in doctored:
        path.write_text(json.dumps(content))
        with pytest.raises(EtmpcError) as refused:
            _resume("ppo", out)
        message = str(refused.value)
        assert says in message and message.startswith(str(path)) and message.endswith(AGAIN), (says, message)
    path.write_bytes(before["training.json"])
    (out / "selected.zip").unlink()
    with pytest.raises(EtmpcError, match="not one of its checkpoints with selected.zip beside it"):
        _resume("ppo", out)
    assert files(out) == {k: v for k, v in before.items() if k != "selected.zip"}


def test_a_finished_self_trigger_runs_policy_file_is_read_field_by_field(finished, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished("self"), out)
    path = out / "selected.json"
    policy = json.loads(path.read_text())
    hyper = policy["hyperparameters"]
    doctored = [
        (dict(policy, candidates=["1", *policy["candidates"][1:]]), "candidates must be a list of a whole number"),
        ({k: v for k, v in policy.items() if k != "hyperparameters"}, "has no field 'hyperparameters'"),
        (dict(policy, hyperparameters=dict(hyper, labelled_solves="4")), "hyperparameters.labelled_solves must be"),
        (dict(policy, hyperparameters=dict(hyper, chosen="ridge 7")), "its choice 'ridge 7' or base"),
        (dict(policy, hyperparameters={k: v for k, v in hyper.items() if k != "system"}), "has no field 'system'"),
        (dict(policy, theta=[[0.0]]), "has inconsistent or non-finite parameters"),
    ]
    before = files(out)
    for content, says in doctored:
        path.write_text(json.dumps(content))
        with pytest.raises(EtmpcError) as refused:
            _resume("self", out)
        assert says in str(refused.value) and "\n" not in str(refused.value), (says, str(refused.value))
    path.write_text(before["selected.json"].decode())
    assert files(out) == before


# -- checkpoint.json (GPOMDP, DPI): each field, by its place -------------------------------------------------------
def _set(path: str, value):
    """A doctoring of a checkpoint: the field at ``path`` (``curve.0.objective``) set to ``value`` (DELETE: removed)."""

    def edit(data):
        *parents, last = path.split(".")
        for part in parents:
            data = data[int(part)] if isinstance(data, list) else data[part]
        last = int(last) if isinstance(data, list) else last
        if value is DELETE:
            del data[last]
        else:
            data[last] = value

    return edit


DELETE = object()
CHECKPOINT_CASES = [
    ("gpomdp", _set("curve.0.objective", "x"), "curve[0].objective must be a number (finite), got 'x'"),
    ("gpomdp", _set("curve.0.episodes", True), "curve[0].episodes must be a whole number"),
    ("gpomdp", _set("curve.1", DELETE), "curve must hold a point per seed at each milestone so far"),
    ("gpomdp", _set("learners.0.theta.2", "1"), "learners.0.theta[2] is '1', not a number"),
    ("gpomdp", _set("learners.0.theta", [0.0]), "learners.0.theta holds 1 numbers, not the run's"),
    ("gpomdp", _set("learners.0.baseline_mean.0", float("inf")), "learners.0.baseline_mean[0] is inf, not a finite number"),
    ("gpomdp", _set("learners.0.value_gram", [[0.0]]), "learners.0.value_gram holds 1 x 1 numbers"),
    ("gpomdp", _set("learners.0.episodes", "4"), "learners.0.episodes must be a whole number"),
    ("gpomdp", _set("learners.0.episodes", 3), "learners.0.episodes is 3, not one of the run's milestones"),
    ("gpomdp", _set("learners.0.settings.discount", 0.5), "learners.0.settings are not the run's"),
    ("gpomdp", _set("learners.0.extra", 1), "learners.0 has a field it must not have, 'extra'"),
    ("gpomdp", _set("best.0.objective", None), "best.0.objective must be a number (finite), got None"),
    ("gpomdp", _set("best.0.theta", DELETE), "best.0 has no field 'theta'"),
    ("gpomdp", _set("best.1", DELETE), "learners and best must hold one entry per seed"),
    ("gpomdp", _set("training.0.return", "x"), "training[0].return must be a number (finite) or null"),
    ("gpomdp", _set("training.0.seed", 9), "training must hold an entry per seed and episode so far"),
    ("gpomdp", _set("validation", {"0": "x", "1": 0.5}), "validation must be an object of a number (finite)"),
    ("gpomdp", _set("validation", {"7": 0.5}), "validation must score each of the run's candidates"),
    ("gpomdp", _set("base", "always"), "base is 'always', not one of the run's first schedules"),
    ("gpomdp", _set("config.episodes", "4"), "config: episodes must be a whole number"),
    ("gpomdp", _set("policy.domain", "cart_pendulum/balance"), "policy: not a policy of battery/trading's decisions"),
    ("gpomdp", _set("policy.theta.0", "x"), "policy: theta[0] is 'x', not a number"),
    ("gpomdp", _set("curve", {}), "the checkpoint.curve must be a list, got {}"),
    ("dpi", _set("learners.0.data.1.0.0", "x"), "learners.0.data[1][0][0] is 'x', not a number"),
    ("dpi", _set("learners.0.data.1.2", None), "learners.0.data[1][2] is None, not a number"),
    ("dpi", _set("learners.0.data.0", [1, 2]), "learners.0.data[0] must be a label [phi, q_keep, q_recompute, step]"),
    ("dpi", _set("learners.0.data.0.3", 1.5), "learners.0.data[0] must be a label"),
    ("dpi", _set("learners.0.data.0.0", [0.0]), "learners.0.data[0][0] holds 1 numbers, not the run's"),
    ("dpi", _set("learners.0.iterations", 5), "learners.0 must have made 2 iterations at 2 episodes"),
    ("dpi", _set("learners.0.history.0.episodes", 7), "learners.0.history[0].episodes must be 1"),
    ("dpi", _set("learners.0.history.1.theta_level", [0.0]), "learners.0.history[1].theta_level must be there only with"),
    ("dpi", _set("base", "every:9"), "base is 'every:9', not one of the run's first schedules"),
]


@pytest.mark.parametrize("name, edit, says", CHECKPOINT_CASES, ids=[f"{c[0]}-{c[2][:40]}" for c in CHECKPOINT_CASES])
def test_each_field_of_a_training_checkpoint_is_checked_as_it_is_read(name, edit, says, finished):
    data = json.loads((finished(name) / "checkpoint.json").read_text())
    state_from_json(copy.deepcopy(data), "checkpoint c.json")  # as the run wrote it: read
    edit(data)
    with pytest.raises(EtmpcError) as refused:
        state_from_json(data, "checkpoint c.json")
    message = str(refused.value)
    assert message.startswith("checkpoint c.json is corrupt (") and says in message and message.endswith(AGAIN), message


def test_a_checkpoint_with_text_in_its_learning_curve_is_one_line_on_resume_and_changes_nothing(finished, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished("gpomdp"), out)
    data = json.loads((out / "checkpoint.json").read_text())
    data["curve"][0]["objective"] = "0.5"
    (out / "checkpoint.json").write_text(json.dumps(data))
    before = files(out)
    with pytest.raises(EtmpcError) as refused:
        _resume("gpomdp", out)
    assert str(refused.value) == (
        f"checkpoint {out / 'checkpoint.json'} is corrupt (curve[0].objective must be a number (finite), got '0.5')" + AGAIN
    )
    assert files(out) == before
