"""Stored test sets: bit-identical regeneration and clear errors."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

from etmpc.evaluation import testsets as testset
from etmpc.common.errors import TestSetError
from etmpc.systems import make_system, names, stored_seed


@pytest.mark.parametrize("domain", [name for name in names() if stored_seed(name) is not None])
def test_stored_test_set_is_etmpc_testset_with_its_documented_seed(domain, tmp_path):
    out = tmp_path / "set.npz"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "etmpc.cli",
            "testset",
            "--task",
            domain,
            "--seed",
            str(stored_seed(domain)),
            "--episodes",
            str(testset.STORED_EPISODES),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    system = make_system(domain)
    stored = testset.default_path(system.domain, system.task)
    assert out.read_bytes() == stored.read_bytes()
    assert testset.checksum_path(out).read_text().split()[0] == testset.checksum_path(stored).read_text().split()[0]


def test_a_drawn_test_set_is_what_evaluate_takes_and_never_overwrites(tmp_path, capsys):
    from etmpc.cli import main

    out = tmp_path / "mine.npz"
    assert main(["testset", "--task", "battery", "--seed", "7", "--episodes", "3", "--out", str(out)]) == 0
    loaded = testset.load(out, "battery", "trading")
    assert loaded.episodes == 3 and loaded.meta["seed"] == 7
    assert main(["evaluate", "--task", "battery", "--policy", "every:3", "--test-set", str(out), "--workers", "1"]) == 0
    assert "3 episodes x 1 repeat per policy" in capsys.readouterr().out
    before = out.read_bytes()
    assert main(["testset", "--task", "battery", "--seed", "8", "--out", str(out)]) == 2
    assert "never overwritten" in capsys.readouterr().err and out.read_bytes() == before


def test_loaded_test_set_matches_its_seed(cart_testset, cart_system):
    assert cart_testset.episodes == 100 and cart_testset.meta["seed"] == 20210601
    assert cart_testset.sha256 == testset.checksum_path(cart_testset.path).read_text().split()[0]
    rng = testset.episode_generators(cart_testset.meta["seed"], 100)[37]
    episode = cart_system.draw_episode(rng)
    np.testing.assert_array_equal(cart_testset.episode_arrays(37)["disturbance"], episode.disturbance)


@pytest.fixture
def copy(tmp_path, cart_testset):
    target = tmp_path / cart_testset.path.name
    shutil.copy(cart_testset.path, target)
    shutil.copy(testset.checksum_path(cart_testset.path), testset.checksum_path(target))
    return target


def test_missing_test_set(tmp_path, monkeypatch):
    # Someone's own file: the advice is not to regenerate the stored set, which would not bring it back.
    with pytest.raises(TestSetError, match="not found") as info:
        testset.load(tmp_path / "nope.npz", "cart_pendulum", "balance")
    assert "etmpc testset" not in str(info.value)
    # The stored one (here: where the stored one is looked for) is regenerated from its seed.
    monkeypatch.setattr(testset, "default_path", lambda domain, task: tmp_path / "stored.npz")
    with pytest.raises(TestSetError, match="not found.*etmpc testset --task cart_pendulum/balance --seed 20210601"):
        testset.load(tmp_path / "stored.npz", "cart_pendulum", "balance")


def test_corrupted_test_set(copy):
    data = bytearray(copy.read_bytes())
    data[len(data) // 2] ^= 0xFF
    copy.write_bytes(bytes(data))
    with pytest.raises(TestSetError, match="corrupted"):
        testset.load(copy, "cart_pendulum", "balance")


def test_missing_checksum(copy):
    testset.checksum_path(copy).unlink()
    with pytest.raises(TestSetError, match="checksum file") as info:
        testset.load(copy, "cart_pendulum", "balance")
    assert "etmpc testset" not in str(info.value)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda a, m: ({**a, "disturbance": a["disturbance"][:2]}, m), "not one row per each"),
        (lambda a, m: ({}, m), "no episode arrays"),
        (lambda a, m: (a, dict(m, episodes=0)), "0 episodes"),
        (lambda a, m: ({**a, "initial_state": np.full_like(a["initial_state"], np.inf)}, m), "not all finite"),
    ],
)
def test_contents_are_checked_not_only_the_checksum(tmp_path, cart_testset, change, message):
    arrays = {k: np.array(v[:4]) for k, v in cart_testset.arrays.items()}
    arrays, meta = change(arrays, dict(cart_testset.meta, episodes=4))
    path = tmp_path / "ts.npz"
    testset.write(path, arrays, meta)  # a matching checksum: only the contents are wrong
    with pytest.raises(TestSetError, match=message):
        testset.load(path, "cart_pendulum", "balance")


def test_every_episode_must_be_playable(tmp_path, cart_testset, cart_system):
    arrays = {k: np.array(v[:4]) for k, v in cart_testset.arrays.items()}
    arrays["disturbance"] = arrays["disturbance"][:, :60]  # an episode is 100 steps
    path = tmp_path / "ts.npz"
    testset.write(path, arrays, dict(cart_testset.meta, episodes=4))
    loaded = testset.load(path, "cart_pendulum", "balance")
    with pytest.raises(TestSetError, match="episode 0: episode has 60 disturbances, need 100"):
        loaded.check_playable(cart_system, cart_system.make_env().task)
    cart_testset.check_playable(cart_system, cart_system.make_env().task)  # the stored one is


def test_wrong_task(copy):
    with pytest.raises(TestSetError, match="is for cart_pendulum/balance"):
        testset.load(copy, "battery", "trading")


def test_episode_out_of_range(cart_testset):
    with pytest.raises(TestSetError, match="out of range"):
        cart_testset.episode_arrays(100)


@pytest.mark.parametrize("name", [name for name in names() if stored_seed(name) is not None])
def test_every_field_of_a_stored_episode_is_within_the_range_its_task_declares(name, tmp_path):
    """A test set is someone's file: a value its task cannot draw (a gust of 2**62 intervals ended in a
    traceback) is refused before any episode is played, naming the episode and the field."""
    system = make_system(name)
    task = system.make_env().task
    stored = testset.load(testset.default_path(system.domain, system.task), system.domain, system.task)
    ranges = task.episode_ranges()
    assert sorted(ranges) == sorted(stored.arrays)  # every field has its range
    stored.check_playable(system, task)  # and the stored episodes are within them
    for field, (low, high) in ranges.items():
        arrays = {k: np.array(v[:3]) for k, v in stored.arrays.items()}
        beyond = 2**62 if arrays[field].dtype.kind in "iu" else float(np.max(high)) + 1.0
        arrays[field][2, ...].flat[-1] = beyond  # a view of episode 2, also of a field of one number
        path = tmp_path / f"{field}.npz"
        testset.write(path, arrays, dict(stored.meta, episodes=3))
        loaded = testset.load(path, system.domain, system.task)  # the file is whole: only a value is wrong
        with pytest.raises(TestSetError, match=f"episode 2: {field}: {beyond!r}.* is outside the task's range"):
            loaded.check_playable(system, task)


def test_a_gust_that_never_ends_is_one_line_before_any_episode_is_played(tmp_path, capsys):
    from etmpc.cli import main

    stored = testset.load(testset.default_path("quadrotor", "waypoints"), "quadrotor", "waypoints")
    arrays = {k: np.array(v[:2]) for k, v in stored.arrays.items()}
    arrays["gust_intervals"][1, 5] = 2**62
    path = tmp_path / "gusts.npz"
    testset.write(path, arrays, dict(stored.meta, episodes=2))
    code = main(["evaluate", "--task", "quadrotor", "--policy", "every:7", "--test-set", str(path), "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert f"episode 1: gust_intervals: {2**62} at [5] is outside the task's range [0, 16]" in err
