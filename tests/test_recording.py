"""Rerun recordings: what is in the file, read back with Rerun's own reader, against the live run."""

import numpy as np
import pytest
from rerun.chunk import RrdReader

import etmpc.evaluate as evaluate_mod
from etmpc.cli import main
from etmpc.evaluate import evaluate
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.recording import prediction_errors, read_recording, replay_summary
from etmpc.workers import context, policy_rng


def live_and_replayed(tmp_path, domain, policies, episodes=3, repeats=1):
    path = tmp_path / f"{domain}.rrd"
    live = evaluate(domain, policies, episodes=episodes, repeats=repeats, workers=1, progress=False, record=path)
    return live, replay_summary(path), path


@pytest.mark.parametrize("domain, policies, repeats", [
    ("cart_pendulum", ["every:3", "threshold:0.3", "always"], 1),
    ("battery", ["every:5", "threshold:0.01"], 2),
])
def test_replay_gives_exactly_the_figures_the_run_computed_live(tmp_path, domain, policies, repeats):
    live, replayed, _ = live_and_replayed(tmp_path, domain, policies, repeats=repeats)
    assert len(replayed) == len(live.runs) == len(policies) * 3 * repeats
    by_key = {(r.policy, r.episode, r.repeat): r for r in replayed}
    for run in live.runs:
        again = by_key[(run.policy, run.episode, run.repeat)]
        assert (again.objective, again.control_objective, again.recomputes, again.steps) == \
            (run.objective, run.control_objective, run.recomputes, run.steps)  # bit for bit


def test_prediction_error_is_what_the_threshold_trigger_compares(tmp_path):
    """Independent truth: `threshold:X` recomputes by choice exactly where the recorded error
    exceeds X, and keeps its plan exactly where it does not."""
    x = 0.3
    path = tmp_path / "t.rrd"
    evaluate("cart_pendulum", [f"threshold:{x}"], episodes=3, workers=1, progress=False, record=path)
    for data in read_recording(path).values():
        steps, errors = data["prediction_error"]
        _, recompute = data["recompute"]
        _, forced = data["forced"]
        chosen = (recompute[steps] > 0) & (forced[steps] == 0)
        kept = recompute[steps] == 0
        assert chosen.any() and kept.any()
        assert np.all(errors[chosen] > x) and np.all(errors[kept] <= x)
        assert steps[0] == 1  # no plan before step 0


def test_prediction_errors_against_a_direct_computation(cart_system, cart_testset):
    _, env, _ = context("cart_pendulum")
    traj = run_episode(cart_system, env, parse_policy("every:4", cart_system.error_weights), policy_rng(0, 0, 1),
                       cart_system.episode_from_arrays(cart_testset.episode_arrays(1)))
    errors = prediction_errors(traj, cart_system.error_weights)
    w = cart_system.error_weights
    for i in range(1, traj.steps):
        k, plan = [p for p in traj.plans if p[0] < i][-1]  # the latest plan made before step i
        assert errors[i] == pytest.approx(np.linalg.norm(w * (traj.states[i] - plan.states[i - k])), abs=1e-15)
    assert np.isnan(errors[0])
    assert np.all(errors[4::4] > 0)  # the plan is 4 steps old when every:4 replaces it


def chunks_by_entity(path):
    out = {}
    for chunk in RrdReader(str(path)).stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    return out


def column_chunk(entities, entity, column):
    """The one chunk of ``entity`` that holds ``column`` (styles come in chunks of their own)."""
    (batch,) = [b for b in entities[entity] if column in b.schema.names]
    return batch


def test_the_recording_holds_states_plans_identity_and_a_blueprint(tmp_path, cart_system, cart_testset):
    path = tmp_path / "c.rrd"
    evaluate("cart_pendulum", ["every:5"], episodes=2, workers=1, progress=False, record=path, seed=7)
    entities = chunks_by_entity(path)
    root = "/cart_pendulum/every_5/episode_001/repeat_0"
    identity = entities[f"{root}/identity"][0].to_pydict()
    assert identity["policy"] == [["every:5"]] and identity["episode"] == [[1]] and identity["seed"] == [[7]]
    assert identity["test_set_sha256"] == [[cart_testset.sha256]]

    _, env, _ = context("cart_pendulum")
    traj = run_episode(cart_system, env, parse_policy("every:5", cart_system.error_weights), policy_rng(7, 0, 1),
                       cart_system.episode_from_arrays(cart_testset.episode_arrays(1)))
    state = column_chunk(entities, f"{root}/state", "Scalars:scalars")
    np.testing.assert_array_equal(state.column("step").to_numpy(), np.arange(traj.steps + 1))
    values = state.column("Scalars:scalars").flatten().to_numpy().reshape(-1, 4)
    np.testing.assert_array_equal(values, traj.states[: traj.steps + 1])
    times = state.column("time").to_numpy().astype("timedelta64[ns]").astype(np.int64)
    np.testing.assert_array_equal(times, np.arange(traj.steps + 1) * 100_000_000)  # 0.1 s per step

    plans = column_chunk(entities, f"{root}/plan/state/pole_angle", "LineStrips2D:strips")
    assert plans.column("step").to_pylist() == [k for k, _ in traj.plans] == list(range(0, 100, 5))
    strips = plans.column("LineStrips2D:strips").to_pylist()
    k, plan = traj.plans[3]
    first = np.array(strips[3][0])
    np.testing.assert_allclose(first[:, 0], (k + np.arange(21)) * 0.1, rtol=1e-6)  # into the future
    np.testing.assert_allclose(first[:, 1], plan.states[:, 2], rtol=1e-6)  # float32 points

    events = column_chunk(entities, f"{root}/events", "TextLog:text")
    assert events.column("step").to_pylist() == list(range(0, 100, 5))
    assert len(RrdReader(str(path)).blueprints()) == 1
    assert any(e.startswith("/cart_pendulum/every_5/episode_000/") for e in entities)  # episodes stay apart


def test_battery_recording_holds_prices_production_and_each_plans_forecasts(tmp_path, battery_testset):
    path = tmp_path / "b.rrd"
    evaluate("battery", ["every:10"], episodes=1, workers=1, progress=False, record=path)
    entities = chunks_by_entity(path)
    root = "/battery/every_10/episode_000/repeat_0"
    episode = battery_testset.episode_arrays(0)
    signal = column_chunk(entities, f"{root}/signal", "Scalars:scalars")
    values = signal.column("Scalars:scalars").flatten().to_numpy().reshape(-1, 2)
    np.testing.assert_array_equal(values[:, 0], episode["price_eur_kwh"][:100])
    np.testing.assert_array_equal(values[:, 1], episode["production_kw"][:100])
    forecasts = column_chunk(entities, f"{root}/forecast/price_eur_kwh", "LineStrips2D:strips")
    assert forecasts.column("step").to_pylist() == list(range(0, 100, 10))
    strip = np.array(forecasts.column("LineStrips2D:strips").to_pylist()[2][0])
    np.testing.assert_allclose(strip[:, 1], episode["price_forecast_eur_kwh"][20], rtol=1e-6)  # the forecast made at step 20
    assert f"{root}/state" in entities and f"{root}/realised/signal/net_production_kw" in entities


def test_an_interrupted_recording_leaves_no_file(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("worker died")

    monkeypatch.setattr(evaluate_mod, "run_jobs", broken)
    with pytest.raises(RuntimeError):
        evaluate("battery", ["always"], episodes=1, workers=1, progress=False, record=tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_replay_cli_prints_the_figures_and_refuses_bad_files(tmp_path, capsys):
    path = tmp_path / "b.rrd"
    assert main(["evaluate", "battery", "--policy", "every:5", "--episodes", "2", "--workers", "1", "--record", str(path)]) == 0
    capsys.readouterr()
    assert main(["replay", str(path), "--per-episode"]) == 0
    out = capsys.readouterr().out
    assert "every:5" in out and "episode 1 repeat 0" in out
    (tmp_path / "junk.rrd").write_bytes(b"not a recording")
    for argv in (["replay", str(tmp_path / "missing.rrd")], ["replay", str(tmp_path / "junk.rrd")],
                 ["evaluate", "battery", "--policy", "always", "--record", str(tmp_path / "x.txt")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err


def test_render_puts_the_video_frames_into_the_recording(tmp_path, capsys):
    out, rec = tmp_path / "v.mp4", tmp_path / "v.rrd"
    argv = ["render", "cart_pendulum", "--policy", "every:5", "--episode", "3", "--out", str(out),
            "--width", "160", "--height", "120", "--record", str(rec)]
    assert main(argv) == 0
    assert "101 frames" in capsys.readouterr().out
    images = [b for e, batches in chunks_by_entity(rec).items() if e.endswith("/camera") for b in batches
              if "EncodedImage:blob" in b.schema.names]
    steps = sorted(s for b in images for s in b.column("step").to_pylist())
    assert steps == list(range(101))
    (replayed,) = replay_summary(rec)
    live = evaluate("cart_pendulum", ["every:5"], episodes=4, workers=1, progress=False).runs[3]
    assert (replayed.episode, replayed.objective, replayed.recomputes) == (3, live.objective, live.recomputes)
    assert main(["render", "cart_pendulum", "--policy", "every:5", "--out", str(tmp_path / "v.avi")]) == 2


def test_train_records_its_evaluations_without_changing_any_result(tmp_path):
    from etmpc.train import TrainConfig, train

    config = TrainConfig("battery", seeds=(0, 1), episodes=4, eval_every=2, eval_episodes=3, normalisation_episodes=2,
                         validation_episodes=2)
    train(config, tmp_path / "plain", workers=1, progress=False)
    train(config, tmp_path / "rec", workers=1, progress=False, record_episodes=2)
    plain = {p.relative_to(tmp_path / "plain"): p.read_bytes() for p in (tmp_path / "plain").rglob("*") if p.is_file()}
    recorded = {p.relative_to(tmp_path / "rec"): p.read_bytes() for p in (tmp_path / "rec").rglob("*") if p.is_file()}
    assert {k: v for k, v in recorded.items() if k.parts[0] != "recordings"} == plain
    assert sorted(p.name for p in (tmp_path / "rec" / "recordings").iterdir()) == ["eval_00000.rrd", "eval_00002.rrd", "eval_00004.rrd"]

    replayed = replay_summary(tmp_path / "rec" / "recordings" / "eval_00004.rrd")
    assert sorted((r.policy, r.episode) for r in replayed) == [(f"seed{s}/episodes00004", e) for s in (0, 1) for e in (0, 1)]
    live = evaluate("battery", [f"rl:{tmp_path / 'rec' / 'seed1' / 'last.json'}"], episodes=2, workers=1, progress=False)
    again = [r for r in replayed if r.policy == "seed1/episodes00004"]
    assert [(r.objective, r.recomputes) for r in again] == [(r.objective, r.recomputes) for r in live.runs]
