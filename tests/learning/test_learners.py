"""The learner interface: every registered learner runs a tiny budget through the one runner and
resumes; a learner that claims exact resume ends where an uninterrupted run does; a new learner is one
class and the runner, the registry and settings files find it."""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.learning import base
from etmpc.learning.base import Learner, learner_class, learners, load_settings, shipped
from etmpc.learning.runner import run
from etmpc.systems import system_key

TINY = {
    "gpomdp": dict(episodes=4, eval_every=2, eval_episodes=2, normalisation_episodes=2, validation_episodes=2),
    "dpi": dict(
        episodes=2,
        eval_every=1,
        eval_episodes=2,
        normalisation_episodes=2,
        validation_episodes=2,
        futures=1,
        horizon=3,
        states_per_episode=2,
        bases=("always", "every:3"),
        selection_episodes=2,
    ),
    "self": dict(
        bases=("every:3", "every:8"),
        selection_episodes=2,
        episodes=2,
        solves_per_episode=2,
        futures=1,
        horizon=2,
        ridges=(0.1,),
        validation_episodes=2,
    ),
    "ppo": dict(timesteps=512, checkpoints=2, validation_episodes=1, n_steps=128, batch_size=128, n_epochs=1),
}
SEEDS = {"gpomdp": (0, 1), "dpi": (0, 1), "self": None, "ppo": (3,)}


def files(out: Path) -> dict:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def tiny(name: str):
    cls = learner_class(name)
    return cls(cls.Settings(**TINY[name]))


def test_the_registry_holds_the_four_learners_in_order_and_the_leaderboards_shipped_ones():
    assert list(learners())[:4] == ["gpomdp", "dpi", "self", "ppo"]
    assert [entry for entry, *_ in shipped()] == ["GPOMDP (shipped)", "DPI (shipped)", "PPO (shipped)"]
    assert [(file, prefix) for _, file, prefix, _ in shipped()] == [
        ("gpomdp.json", "rl:"),
        ("learned.json", "rl:"),
        ("ppo.zip", "sb3:"),
    ]
    with pytest.raises(EtmpcError, match="unknown algorithm"):
        learner_class("nonsense")
    # Given no seeds, a run takes the learner's own: etmpc train's 0-4, PPO's settings.seed.
    assert learner_class("dpi")().default_seeds() == (0, 1, 2, 3, 4)
    assert learner_class("ppo")(learner_class("ppo").Settings(seed=7)).default_seeds() == (7,)


@pytest.mark.parametrize("name", ["gpomdp", "dpi", "self", "ppo"])
def test_every_learner_runs_through_the_runner_and_a_finished_run_resumes_to_the_same_files(name, tmp_path):
    if name == "ppo":
        pytest.importorskip("stable_baselines3")
    out = tmp_path / "run"
    done = run(tiny(name), "battery" if name != "self" else "cart_pendulum", out, SEEDS[name], workers=1, progress=False)
    kind = learner_class(name).policy_kind
    assert done.policy.startswith(f"{kind}:") and Path(done.policy.split(":", 1)[1]).is_file()
    before = files(out)
    with pytest.raises(EtmpcError, match="--resume"):
        run(tiny(name), "battery" if name != "self" else "cart_pendulum", out, SEEDS[name], progress=False)
    again = run(tiny(name), "battery" if name != "self" else "cart_pendulum", out, SEEDS[name], resume=True, progress=False)
    assert again.policy == done.policy and files(out) == before  # nothing is trained again


@pytest.mark.parametrize("name", [n for n in ("gpomdp", "dpi", "self", "ppo")])
def test_a_run_stopped_after_its_first_milestone_resumes_and_ends_as_claimed(name, tmp_path, monkeypatch):
    if name == "ppo":
        pytest.importorskip("stable_baselines3")
    task = "battery" if name != "self" else "cart_pendulum"
    run(tiny(name), task, tmp_path / "whole", SEEDS[name], progress=False)

    class Stop(Exception):
        pass

    cls = learner_class(name)
    learn, calls = cls.learn, []

    def learn_once(self, budget, callback):  # the first milestone is learnt and saved; the second is killed
        calls.append(budget)
        if len(calls) > 1:
            raise Stop
        learn(self, budget, callback)

    monkeypatch.setattr(cls, "learn", learn_once)
    if name == "self":  # one pass (one milestone): nothing to stop between milestones
        run(tiny(name), task, tmp_path / "cut", SEEDS[name], progress=False)
        assert files(tmp_path / "cut") == files(tmp_path / "whole")
        return
    with pytest.raises(Stop):
        run(tiny(name), task, tmp_path / "cut", SEEDS[name], progress=False)
    monkeypatch.setattr(cls, "learn", learn)
    run(tiny(name), task, tmp_path / "cut", SEEDS[name], resume=True, progress=False)
    whole, cut = files(tmp_path / "whole"), files(tmp_path / "cut")
    assert sorted(whole) == sorted(cut)  # the same files, the resume state removed
    if cls.resumes_exactly:
        assert whole == cut
    else:  # PPO: continued from its last checkpoint, which is the uninterrupted run's, byte for byte
        first = sorted(f for f in whole if f.startswith("checkpoints/step_"))[:2]
        assert {f: whole[f] for f in first} == {f: cut[f] for f in first}
        training = json.loads(cut["training.json"])
        assert training["environment_steps"] == 512 and len(training["checkpoints"]) == 2


def test_settings_files_set_fields_by_name_and_refuse_unknown_ones(tmp_path):
    path = tmp_path / "dpi.yml"
    path.write_text("episodes: 6\nbases: [always, every:4]\nfutures: 2\n")
    settings = load_settings(learner_class("dpi"), path)
    assert settings.episodes == 6 and settings.bases == ("always", "every:4") and settings.futures == 2
    path.write_text("episode: 6\n")
    with pytest.raises(EtmpcError, match="unknown setting 'episode'"):
        load_settings(learner_class("dpi"), path)
    path.write_text('{"learning_rate": -1}')
    json_path = path.rename(tmp_path / "g.json")
    with pytest.raises(EtmpcError, match="learning rate"):
        load_settings(learner_class("gpomdp"), json_path)
    assert load_settings(learner_class("gpomdp"), None) == learner_class("gpomdp").Settings()


def test_seeds_are_checked_against_what_the_learner_takes(tmp_path):
    with pytest.raises(EtmpcError, match="no seed"):
        run(tiny("self"), "cart_pendulum", tmp_path / "a", (0,), progress=False)
    with pytest.raises(EtmpcError, match="one seed at a time"):
        run(tiny("ppo"), "battery", tmp_path / "b", (0, 1), progress=False)
    with pytest.raises(EtmpcError, match="distinct"):
        run(tiny("gpomdp"), "battery", tmp_path / "c", (1, 1), progress=False)
    assert not any(tmp_path.iterdir())


@dataclass(frozen=True)
class EverySettings:
    periods: tuple[int, ...] = (2, 3, 4)
    validation_episodes: int = 2

    def __post_init__(self):
        if not self.periods or min(self.periods) < 1:
            raise EtmpcError("periods must be >= 1")


@pytest.fixture
def new_learner():
    """A learner defined here and nowhere else: it picks the best every:T on validation episodes."""

    class BestPeriod(Learner):
        name = "best-period-test"
        Settings = EverySettings
        policy_kind = "rl"
        resumes_exactly = True

        def owns(self, name):
            return name == "state.json"

        def saved_state(self):
            path = self.out / "state.json"
            return json.loads(path.read_text()) if path.exists() else None

        def setup(self):
            self.seen, self.pick = [], None

        def milestones(self):
            return list(range(1, len(self.settings.periods) + 1))

        @property
        def done(self):
            return len(self.seen)

        def learn(self, budget, callback):
            self.seen = list(self.settings.periods[:budget])
            callback(1)

        def save(self):
            (self.out / "state.json").write_text(json.dumps(self.state()))

        def state(self):
            return {"seen": self.seen, "pick": self.pick}

        def load_state(self, state):
            self.seen, self.pick = state["seen"], state["pick"]

        @property
        def chosen(self):
            return self.pick is not None

        def candidates(self):
            return {f"every:{t}": f"every:{t}" for t in self.seen}

        def choose(self, scores):
            from etmpc.learning.runner import best

            self.pick = list(self.candidates())[best(scores, self.key.make().objective_sense)]

        def policy(self):
            return self.pick

    yield BestPeriod
    base.LEARNERS.pop(BestPeriod.name)  # registered while the test runs only (reproduce would train it)


def test_a_new_learner_is_one_class_and_the_runner_trains_chooses_and_resumes_it(new_learner, tmp_path):
    assert learner_class("best-period-test") is new_learner and "best-period-test" in learners()
    (tmp_path / "s.yml").write_text("periods: [3, 5]\n")
    settings = load_settings(new_learner, tmp_path / "s.yml")
    assert settings.periods == (3, 5)
    done = run("best-period-test", "battery", tmp_path / "run", workers=1, progress=False, settings=settings)
    assert done.policy in ("every:3", "every:5") and done.learner.seen == [3, 5]
    from etmpc.learning.runner import validate
    from etmpc.evaluation.backends import make_backend

    with make_backend("local", 1) as pool:
        means = validate(pool, done.learner.key, ["every:3", "every:5"], 2)
    assert done.policy == ("every:3", "every:5")[int(np.argmax(means))]  # battery: profit, higher is better
    again = run(new_learner(settings), "battery", tmp_path / "run", resume=True, progress=False)
    assert again.policy == done.policy


class _Opens:
    """Unpickled, it creates ``marker``: a payload that shows whether anything was unpickled."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, "w")


def _stopped_ppo_run(tmp_path, monkeypatch):
    """A tiny PPO run in ``tmp_path / "cut"``, stopped after its first milestone with its resume state kept."""
    cls = learner_class("ppo")
    learn, calls = cls.learn, []

    def learn_once(self, budget, callback):
        calls.append(budget)
        if len(calls) > 1:
            raise KeyboardInterrupt
        learn(self, budget, callback)

    monkeypatch.setattr(cls, "learn", learn_once)
    with pytest.raises(KeyboardInterrupt):
        run(tiny("ppo"), "battery", tmp_path / "cut", SEEDS["ppo"], progress=False)
    monkeypatch.setattr(cls, "learn", learn)


def test_a_stopped_ppo_run_resumes_from_data_and_unpickles_nothing_in_its_folder(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    import base64
    import pickle
    import zipfile

    marker = tmp_path / "ran"
    _stopped_ppo_run(tmp_path, monkeypatch)
    checkpoints = tmp_path / "cut" / "checkpoints"
    payload = base64.b64encode(pickle.dumps(_Opens(marker))).decode()
    (last,) = [p for p in checkpoints.glob("step_*.zip")]
    with zipfile.ZipFile(last) as zf:  # the checkpoint's data entry carries a payload where SB3 keeps a pickle
        entries = {name: zf.read(name) for name in zf.namelist()}
    data = json.loads(entries["data"])
    data["lr_schedule"][":serialized:"] = payload
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(last, "w") as zf:
        for name, content in entries.items():
            zf.writestr(name, content)
    (checkpoints / "resume_normalize.pkl").write_bytes(pickle.dumps(_Opens(marker)))  # a planted pickle
    assert json.loads((checkpoints / "resume_normalize.json").read_text())["obs_rms"]["count"] > 1
    done = run(tiny("ppo"), "battery", tmp_path / "cut", SEEDS["ppo"], resume=True, progress=False)
    assert not marker.exists()  # the resume read the statistics as JSON and the weights only
    training = json.loads((tmp_path / "cut" / "training.json").read_text())
    assert training["environment_steps"] == 512 and len(training["checkpoints"]) == 2 and done.policy.startswith("sb3:")
    assert not (checkpoints / "resume_normalize.json").exists()


def test_a_ppo_run_folder_handed_to_resume_is_data_its_paths_stay_inside_and_a_pickle_is_one_line(tmp_path, monkeypatch):
    """A folder handed to --resume may be anybody's: a checkpoint path in its state that leads out of the folder
    is refused, never followed; weights that carry a pickle are refused in one line (no traceback)."""
    pytest.importorskip("stable_baselines3")
    import pickle
    import shutil
    import zipfile

    _stopped_ppo_run(tmp_path, monkeypatch)
    resume = tmp_path / "cut" / "checkpoints" / "resume.json"
    state = json.loads(resume.read_text())
    (last,) = (tmp_path / "cut" / "checkpoints").glob("step_*.zip")
    shutil.copyfile(last, tmp_path / "outside.zip")
    for file in ("../outside.zip", str(tmp_path / "outside.zip"), "checkpoints/../../outside.zip"):
        resume.write_text(json.dumps(dict(state, checkpoints=[dict(state["checkpoints"][0], file=file)])))
        with pytest.raises(EtmpcError, match=r"resume.json is corrupt \(checkpoint file .* is not one of the run's"):
            run(tiny("ppo"), "battery", tmp_path / "cut", SEEDS["ppo"], resume=True, progress=False)
    for bad in ({"checkpoints": "step_00000256.zip"}, {"checkpoints": [dict(state["checkpoints"][0], timesteps="256")]}):
        resume.write_text(json.dumps(dict(state, **bad)))
        with pytest.raises(EtmpcError, match=r"resume.json is corrupt \(checkpoints.*; start the run again in another --out"):
            run(tiny("ppo"), "battery", tmp_path / "cut", SEEDS["ppo"], resume=True, progress=False)
    resume.write_text(json.dumps(state))
    with zipfile.ZipFile(last) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    entries["policy.pth"] = pickle.dumps(_Opens(tmp_path / "ran"))  # a pickle where the weights go
    with zipfile.ZipFile(last, "w") as zf:
        for name, content in entries.items():
            zf.writestr(name, content)
    with pytest.raises(EtmpcError, match=r"step_\d{8}\.zip: not this run's weights") as refused:
        run(tiny("ppo"), "battery", tmp_path / "cut", SEEDS["ppo"], resume=True, progress=False)
    assert "\n" not in str(refused.value) and not (tmp_path / "ran").exists()


def test_a_stopped_ppo_run_resumes_only_on_its_task_price_and_options(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    _stopped_ppo_run(tmp_path, monkeypatch)
    assert json.loads((tmp_path / "cut" / "checkpoints" / "resume.json").read_text())["task"] == "battery/trading"
    with pytest.raises(EtmpcError, match="holds a ppo run on battery/trading, not battery/trading@0.5; resume it with that task"):
        run(tiny("ppo"), system_key("battery", 0.5), tmp_path / "cut", SEEDS["ppo"], resume=True, progress=False)


@pytest.mark.parametrize("attribute", ["key", "seeds", "out", "pool"])
def test_what_the_runner_sets_is_an_error_that_says_so_when_read_before(attribute):
    """A learner's task, seeds, run directory and backend are the runner's to set: read before, a one-line
    error naming the attribute and the runner, not a None met later; read on the class, the descriptor."""
    learner = learner_class("dpi")()
    with pytest.raises(EtmpcError, match=rf"^dpi: its {attribute} is not set: run it with etmpc.learning.runner.run$"):
        getattr(learner, attribute)
    assert isinstance(getattr(Learner, attribute), base.SetByRunner)
    setattr(learner, attribute, "set")
    assert getattr(learner, attribute) == "set"
