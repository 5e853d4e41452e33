"""``sb3:PATH`` reads a policy file as data, never as code, and its numpy network decides as SB3 does.

A hostile model carries a pickle that runs ``touch MARKER`` when unpickled (as ``PPO.load`` would):
in an entry etmpc never reads it loads and plays safely, where etmpc would need it (the policy's class,
its keyword arguments, its weights) it is refused in one line; the marker never appears. Then, on
stored test-set episodes of every shipped model, the numpy decision is compared with SB3's own
``model.predict`` at every decision (``ETMPC_SB3_EPISODES=100`` compares all of them; it prints the
count, the disagreements and the smallest margin between the two logits).
"""

from __future__ import annotations

import base64
import io
import json
import os
import pickle
import shlex
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from etmpc.cli import main  # noqa: E402
from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.evaluation.evaluate import evaluate  # noqa: E402
from etmpc.policies import parse_policy  # noqa: E402
from etmpc.policies.sb3 import TOLERANCE, Network, SB3Policy, load_sb3, pickled_globals  # noqa: E402

from tests.conftest import REPO

SHIPPED = {
    "cart_pendulum/balance": "cart_pendulum",
    "cart_pendulum/kicks": "cart_pendulum/kicks",
    "battery/trading": "battery",
    "reacher/jumps": "reacher",
}  # policies/<directory>: its task (named as a user may name it)
CART = REPO / "policies" / "cart_pendulum" / "balance" / "ppo.zip"
EPISODES = int(os.environ.get("ETMPC_SB3_EPISODES", "3"))


class _Payload:
    """Unpickled, it runs ``touch MARKER``: what a hostile policy file carries."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {shlex.quote(str(self.marker))}",)


def _pickled(marker: Path) -> str:
    return base64.b64encode(pickle.dumps(_Payload(marker))).decode()


def _model(directory: Path, name: str, data_edit=None, state_edit=None, meta_edit=None) -> Path:
    """The shipped cart-pendulum model and its description, copied as ``directory/name.zip``, with its
    ``data`` (a dict), its state dict and its description edited in place (``data`` replaced by the
    bytes its edit returns, if it returns bytes)."""
    model = directory / f"{name}.zip"
    meta = json.loads(CART.with_suffix(".json").read_text())
    if meta_edit is not None:
        meta_edit(meta)
    model.with_suffix(".json").write_text(json.dumps(meta))
    with zipfile.ZipFile(CART) as source, zipfile.ZipFile(model, "w") as target:
        for info in source.infolist():
            content = source.read(info)
            if info.filename == "data" and data_edit is not None:
                data = json.loads(content)
                edited = data_edit(data)
                content = edited if isinstance(edited, bytes) else json.dumps(data).encode()
            if info.filename == "policy.pth" and state_edit is not None:
                state = torch.load(io.BytesIO(content), weights_only=True)
                buffer = io.BytesIO()
                state_edit(state)
                torch.save(state, buffer)
                content = buffer.getvalue()
            target.writestr(info, content)
    return model


def _poisoned(directory: Path, entry: str, marker: Path) -> Path:
    """The model with the payload in ``entry``: a ``data`` field's ``:serialized:`` value, a
    ``policy_kwargs`` that needs unpickling (a custom activation's), or a value in ``policy.pth``."""
    payload = _pickled(marker)
    if entry == "policy.pth":
        return _model(directory, "policy_pth", state_edit=lambda state: state.update(action_net_extra=_Payload(marker)))
    if entry == "policy_kwargs":
        kwargs = {
            ":type:": "<class 'dict'>",
            ":serialized:": payload,
            "net_arch": "[64, 64]",
            "activation_fn": "<class 'torch.nn.modules.activation.ReLU'>",
        }
        return _model(directory, entry, data_edit=lambda data: data.update(policy_kwargs=kwargs))
    return _model(directory, entry, data_edit=lambda data: data[entry].update({":serialized:": payload}))


NEVER_READ = ["lr_schedule", "clip_range", "_last_obs", "observation_space", "action_space"]
REFUSED = {
    "policy_class": "needs a policy class etmpc does not read (a pickle that calls ",
    "policy_kwargs": "needs policy_kwargs that only unpickling reads (net_arch, activation_fn; naming ",
    "policy.pth": "its policy.pth is not plain weights, torch's weights-only reader refuses it",
}


def test_the_payload_is_live_and_stable_baselines3s_own_loader_runs_it(tmp_path):
    """The control: the payload does run when unpickled, and ``PPO.load`` unpickles it even from an
    entry that etmpc never reads."""
    from stable_baselines3 import PPO

    pickle.loads(base64.b64decode(_pickled(tmp_path / "unpickled")))
    assert (tmp_path / "unpickled").exists()
    model = _poisoned(tmp_path, "lr_schedule", tmp_path / "sb3-ran-it")
    try:
        PPO.load(str(model), device="cpu")
    except Exception:  # os.system's 0 is no schedule; the payload ran before that mattered
        pass
    assert (tmp_path / "sb3-ran-it").exists()


@pytest.mark.parametrize("entry", NEVER_READ + list(REFUSED))
def test_a_payload_in_a_policy_file_never_runs(entry, tmp_path, capsys):
    marker = tmp_path / "ran"
    model = _poisoned(tmp_path, entry, marker)
    says = REFUSED.get(entry)
    if says is None:  # an entry etmpc never reads: the model loads, with the shipped model's network
        policy = parse_policy(f"sb3:{model}", "cart_pendulum")
        shipped = load_sb3(str(CART), "cart_pendulum")
        assert isinstance(policy, SB3Policy)
        for (w, b), (w0, b0) in zip(
            [*policy.network.hidden, policy.network.head], [*shipped.network.hidden, shipped.network.head]
        ):
            np.testing.assert_array_equal(w, w0)
            np.testing.assert_array_equal(b, b0)
    else:
        with pytest.raises(EtmpcError, match="^sb3:") as refused:
            parse_policy(f"sb3:{model}", "cart_pendulum")
        assert says in str(refused.value) and len(str(refused.value).splitlines()) == 1
    out = tmp_path / "ev.json"
    code = main(
        [
            "evaluate",
            "--task",
            "cart_pendulum",
            "--policy",
            f"sb3:{model}",
            "--episodes",
            "1",
            "--workers",
            "1",
            "--json",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    if says is None:
        assert code == 0 and out.exists(), err
    else:
        assert code == 2 and len(err.strip().splitlines()) == 1 and says in err and "Traceback" not in err, err
        assert not out.exists()
    assert not marker.exists()


def _runs(json_file: Path) -> list[tuple]:
    return [(r["episode"], r["objective"], r["recomputes"]) for r in json.loads(json_file.read_text())["runs"]]


@pytest.mark.parametrize("entry", ["lr_schedule", "policy_class"])
def test_nor_in_worker_processes(entry, tmp_path, capsys):
    """Workers receive the network's weights, never the file: a model whose payload sits where etmpc
    never reads plays on two workers as the shipped model does on one."""
    marker = tmp_path / "ran"
    model = _poisoned(tmp_path, entry, marker)
    code = main(
        [
            "evaluate",
            "--task",
            "cart_pendulum",
            "--policy",
            f"sb3:{model}",
            "--episodes",
            "3",
            "--workers",
            "2",
            "--json",
            str(tmp_path / "two.json"),
        ]
    )
    err = capsys.readouterr().err
    assert not marker.exists()
    if entry == "policy_class":
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        return
    assert code == 0, err
    assert (
        main(
            [
                "evaluate",
                "--task",
                "cart_pendulum",
                "--policy",
                f"sb3:{CART}",
                "--episodes",
                "3",
                "--workers",
                "1",
                "--json",
                str(tmp_path / "one.json"),
            ]
        )
        == 0
    )
    assert _runs(tmp_path / "two.json") == _runs(tmp_path / "one.json")


def _class_reference(cls) -> dict:
    return {":type:": "<class 'abc.ABCMeta'>", ":serialized:": base64.b64encode(pickle.dumps(cls)).decode()}


def _nan_weight(state):
    state["mlp_extractor.policy_net.2.weight"][3, 5] = float("nan")


@pytest.mark.parametrize(
    "case, data_edit, state_edit, meta_edit, says",
    [
        (
            "another-class",
            lambda d: d.update(policy_class=_class_reference(zipfile.ZipFile)),
            None,
            None,
            "needs a policy class etmpc does not read (zipfile.ZipFile); etmpc reads only PPO's MlpPolicy",
        ),
        ("no-class", lambda d: d.pop("policy_class"), None, None, "needs a policy class etmpc does not read (none given)"),
        (
            "not-a-pickle",
            lambda d: d["policy_class"].update({":serialized:": "bm90IGEgcGlja2xl"}),
            None,
            None,
            "(an unreadable pickle)",
        ),
        ("data-not-json", lambda d: b"{not json", None, None, "is not a Stable-Baselines3 model (its data is not JSON"),
        (
            "other-kwargs",
            lambda d: d.update(policy_kwargs={"net_arch": [64, 64], "ortho_init": False}),
            None,
            None,
            "needs policy_kwargs etmpc does not read (ortho_init); it reads net_arch alone",
        ),
        ("bad-net-arch", lambda d: d.update(policy_kwargs={"net_arch": [64, "64"]}), None, None, "needs net_arch [64, '64']"),
        (
            "shallower-net-arch",
            lambda d: d.update(policy_kwargs={"net_arch": {"pi": [64], "vf": [64, 64]}}),
            None,
            None,
            "does not fit its architecture (10 inputs, tanh layers [64], 2 actions): it has 'mlp_extractor.policy_net.2.weight'",
        ),
        (
            "narrower-net-arch",
            lambda d: d.update(policy_kwargs={"net_arch": {"pi": [64, 32], "vf": [64, 64]}}),
            None,
            None,
            "mlp_extractor.policy_net.2.weight is torch.float32 of shape (64, 64), not torch.float32 of shape (32, 64)",
        ),
        (
            "other-shape",
            lambda d: d["observation_space"].update(_shape=[11]),
            None,
            None,
            "takes observations of shape (11,) and '2' actions; the trigger environment has (10,) and 2",
        ),
        ("three-actions", lambda d: d["action_space"].update(n="3"), None, None, "and '3' actions"),
        (
            "continuous",
            lambda d: d["action_space"].update({":type:": "<class 'gymnasium.spaces.box.Box'>"}),
            None,
            None,
            "needs an action space of type \"<class 'gymnasium.spaces.box.Box'>\"",
        ),
        (
            "feature-weights",
            None,
            lambda s: s.update({"features_extractor.weight": torch.zeros(3)}),
            None,
            "it has 'features_extractor.weight', which the architecture has not",
        ),
        ("missing-weights", None, lambda s: s.pop("action_net.bias"), None, "it has no action_net.bias"),
        (
            "float64-weights",
            None,
            lambda s: s.update({"action_net.bias": torch.zeros(2, dtype=torch.float64)}),
            None,
            "action_net.bias is torch.float64 of shape (2,), not torch.float32 of shape (2,)",
        ),
        ("nan-weight", None, _nan_weight, None, "has non-finite weights ('mlp_extractor.policy_net.2.weight')"),
        ("dqn", None, None, lambda m: m.update(algorithm="dqn"), "names the algorithm 'dqn'; etmpc reads PPO's networks"),
    ],
)
def test_anything_but_ppos_mlp_policy_is_refused_in_one_line(case, data_edit, state_edit, meta_edit, says, tmp_path):
    model = _model(tmp_path, case, data_edit, state_edit, meta_edit)
    with pytest.raises(EtmpcError) as refused:
        load_sb3(str(model), "cart_pendulum")
    message = str(refused.value)
    assert says in message and len(message.splitlines()) == 1 and str(model) in message, message


@pytest.mark.parametrize("kwargs", [{}, {"net_arch": None}, {"net_arch": {"pi": [64, 64], "vf": [64, 64]}}])
def test_the_architectures_ppo_writes_for_the_same_network_load_alike(kwargs, tmp_path):
    model = _model(tmp_path, "kwargs", lambda d: d.update(policy_kwargs=kwargs))
    policy, shipped = load_sb3(str(model), "cart_pendulum"), load_sb3(str(CART), "cart_pendulum")
    np.testing.assert_array_equal(policy.network.head[0], shipped.network.head[0])


def test_the_policy_class_is_parsed_never_run():
    named, only = pickled_globals(_class_reference(zipfile.ZipFile)[":serialized:"])
    assert named == ["zipfile.ZipFile"] and only
    named, only = pickled_globals(_pickled(Path("/nonexistent")))
    assert named == [f"{os.system.__module__}.system"] and not only


# -- the decisions --------------------------------------------------------------------------------
def test_close_logits_are_decided_exactly_and_a_tie_is_action_0(monkeypatch):
    exact, original = [], Network.exact_logits
    monkeypatch.setattr(Network, "exact_logits", lambda self, x: exact.append(x) or original(self, x))
    network = Network([], (np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]), np.zeros(2)))  # logits x0 and x1 + x2
    below_one = 1 - 2**-24
    assert network.action(np.array([1.0, below_one, 2**-23], dtype=np.float32)) == 1  # logit 1 larger by 2^-24
    assert network.action(np.array([1.0, below_one, 2**-24], dtype=np.float32)) == 0  # a tie
    assert network.action(np.array([1.0, below_one, 0.0], dtype=np.float32)) == 0
    assert len(exact) == 3  # each decided by the exact sums: the logits are closer than TOLERANCE
    assert network.action(np.array([1.0, 1.0, 10 * TOLERANCE], dtype=np.float32)) == 1 and len(exact) == 3


def test_the_exact_logits_are_the_fast_ones_to_rounding():
    network = load_sb3(str(CART), "cart_pendulum").network
    rng = np.random.default_rng(0)
    for x in rng.normal(0.0, 2.0, size=(200, 10)).astype(np.float32):
        np.testing.assert_allclose(network.exact_logits(x), network.logits(x), rtol=0, atol=1e-12)


def test_workers_receive_the_weights_and_decide_without_torch():
    """The policy pickles with its numpy weights: a worker unpickles it without torch or the file."""
    policy = load_sb3(str(CART), "cart_pendulum")
    x = np.linspace(-3, 3, 10).astype(np.float32)
    script = (
        "import pickle, sys; policy = pickle.loads(sys.stdin.buffer.read()); "
        "import numpy as np; print(policy.network.action(np.linspace(-3, 3, 10).astype(np.float32))); "
        "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules"
    )
    done = subprocess.run([sys.executable, "-c", script], input=pickle.dumps(policy), capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr.decode()
    assert int(done.stdout) == policy.network.action(x)


class _SB3Predict:
    """SB3's ``model.predict`` deciding on the policy's normalised observation (what ``sb3:`` did before
    it read files as data), with the numpy network asked the same at every decision."""

    stochastic = False
    spec = "sb3-predict"

    def __init__(self, policy: SB3Policy, model):
        self.policy, self.model = policy, model
        self.margins, self.disagreements = [], 0

    def decide(self, s, rng) -> bool:
        x = self.policy.normalised(s)
        theirs = int(self.model.predict(x, deterministic=True)[0]) == 1
        logits = self.policy.network.logits(x)
        self.margins.append(abs(float(logits[1] - logits[0])))
        self.disagreements += self.policy.decide(s, rng) != theirs
        return theirs


@pytest.mark.parametrize("directory", list(SHIPPED))
def test_the_numpy_network_decides_as_sb3s_predict_on_test_set_episodes(directory):
    """At every decision of SB3's own play of ``EPISODES`` test-set episodes; and ``sb3:PATH`` plays them
    to the same objective and recomputations, episode by episode."""
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    path, task = REPO / "policies" / directory / "ppo.zip", SHIPPED[directory]
    compared = _SB3Predict(load_sb3(str(path), task), PPO.load(str(path), device="cpu"))  # shipped files: trusted
    result = evaluate(task, [compared, f"sb3:{path}"], episodes=EPISODES, workers=1, progress=False)
    close = sum(m <= TOLERANCE for m in compared.margins)
    print(
        f"\n{task}: {EPISODES} episodes, {len(compared.margins)} decisions compared, {compared.disagreements} "
        f"disagreements, smallest |logit1 - logit0| {min(compared.margins):.3g}, {close} decided exactly"
    )
    assert compared.disagreements == 0 and len(compared.margins) > 10 * EPISODES
    runs = {
        spec: [(r.episode, r.objective, r.recomputes) for r in result.runs if r.policy == spec]
        for spec in (compared.spec, f"sb3:{path}")
    }
    assert runs[compared.spec] == runs[f"sb3:{path}"] and len(runs[compared.spec]) == EPISODES


@pytest.mark.parametrize("entry", ["lr_schedule", "policy_class"])
def test_nor_when_scored(entry, tmp_path, capsys):
    """``etmpc score`` parses the model on every task before any episode, then plays it on workers."""
    marker = tmp_path / "ran"
    model = _poisoned(tmp_path, entry, marker)
    code = main(["score", "--policy", f"sb3:{model}", "--task", "cart_pendulum", "--episodes", "2", "--workers", "2"])
    err = capsys.readouterr().err
    assert not marker.exists()
    assert code == (0 if entry == "lr_schedule" else 2), err


def test_nor_when_a_swapped_shipped_model_is_on_the_leaderboard(tmp_path, monkeypatch):
    """``make leaderboard`` loads ``policies/<task>/ppo.zip`` by itself: a swapped one is refused by its
    checksum before it is read, and before any row is played."""
    import shutil

    from etmpc.evaluation import inputs
    from etmpc.experiments import leaderboard, leaderboard_rows

    root = tmp_path / "root"
    shutil.copytree(REPO / "policies", root / "policies")
    for folder in ("tasks", "models"):
        (root / folder).symlink_to(REPO / folder)
    marker = tmp_path / "ran"
    poisoned = _poisoned(tmp_path, "lr_schedule", marker)
    shutil.copy(poisoned, root / "policies" / "cart_pendulum" / "balance" / "ppo.zip")
    monkeypatch.setattr(inputs, "data_root", lambda: root)
    monkeypatch.setattr(leaderboard_rows, "data_root", lambda: root)
    monkeypatch.setattr(leaderboard_rows, "play_and_score", lambda *a, **k: pytest.fail("a row was played"))
    with pytest.raises(EtmpcError, match="is not the policy etmpc ships"):
        leaderboard.build(tmp_path / "docs", tmp_path / "work", ["cart_pendulum"], episodes=2, workers=1)
    assert not marker.exists()
