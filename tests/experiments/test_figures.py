"""The figures: what is drawn is the data, checked against the trajectories and evaluations it comes from.

Figure 1 (battery forecasts), one episode's trajectory with every plan, and Figure 3 (objective per
policy, the learned policy's seeds as one bar), with their command (``etmpc figure forecasts | trajectory |
bars``) end to end.
"""

import json
from pathlib import Path

import matplotlib.image
import matplotlib.pyplot
import numpy as np
import pytest

from etmpc.cli import main
from etmpc.views import figures
from etmpc.common import outputs
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import evaluate
from etmpc.views.figures import forecast_figure
from etmpc.policies.learned import LogisticPolicy, Normalisation
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.evaluation.workers import policy_rng

from tests.conftest import REPO


def test_forecast_figure_draws_truth_and_every_plans_forecast(battery_system, battery_testset):
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(0))
    traj = run_episode(battery_system, battery_system.make_env(), parse_policy("every:20", battery_system), None, episode)
    fig = forecast_figure(episode, [("every:20", traj)], dt_s=10.0, mean_price=0.05)
    production_ax, price_ax = fig.axes
    for ax, true, key in (
        (production_ax, episode.production_kw, "production_kw"),
        (price_ax, episode.price_eur_kwh, "price_eur_kwh"),
    ):
        solid = [line for line in ax.get_lines() if line.get_linestyle() == "-" and line.get_marker() in ("None", "")]
        dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
        np.testing.assert_array_equal(solid[0].get_ydata(), true[:100])
        assert len(dashed) == len(traj.plans) == 5
        for line, (k, plan) in zip(dashed, traj.plans):
            np.testing.assert_array_equal(line.get_xdata(), (k + np.arange(20)) * 10.0)
            np.testing.assert_array_equal(line.get_ydata(), plan.forecasts[key])
            assert plan.forecasts[key][0] == true[k]  # the forecast starts at the true value


def _figure(capsys, *args) -> tuple[int, str, str]:
    """``etmpc figure ARGS`` in this process: (exit code, stdout, stderr)."""
    code = main(["figure", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_forecasts_command_writes_the_figure_of_the_episode(tmp_path, capsys, battery_system, battery_testset):
    out = tmp_path / "fig1.png"
    code, stdout, err = _figure(capsys, "forecasts", "--episode", 5, "--policy", "every:20", "--policy", "every:5", "--out", out)
    assert code == 0 and stdout == f"wrote {out}\n", err
    image = matplotlib.image.imread(out)
    assert image.shape[0] > 400 and image.shape[1] > 400 and image.std() > 0.05
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(5))
    env = battery_system.make_env()
    runs = [
        (spec, run_episode(battery_system, env, parse_policy(spec, battery_system), None, episode))
        for spec in ("every:20", "every:5")
    ]
    again = figures.save_png_atomically(
        figures.forecast_figure(episode, runs, 10.0, battery_system.terminal_price), tmp_path / "again.png", dpi=120
    )
    assert out.read_bytes() == again.read_bytes()  # episode 5 under both policies, drawn as forecast_figure draws it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.png", "fig1.png"]


def test_forecasts_command_default_path(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, stdout, err = _figure(capsys, "forecasts")
    assert code == 0, err
    assert matplotlib.image.imread(tmp_path / "results" / "figure1_battery_forecasts.png").shape[1] > 400


@pytest.mark.parametrize(
    "args, message",
    [
        (("--episode", "100"), "out of range"),
        (("--episode", "-1"), "must be >= 0"),
        (("--policy", "every:0"), "bad policy 'every:0'"),
        (("--policy", "always", "--policy", "always"), "policy always is given twice"),
    ],
)
def test_forecasts_command_rejects_bad_input(tmp_path, capsys, args, message):
    code, _, err = _figure(capsys, "forecasts", *args, "--out", tmp_path / "x.png")
    assert code == 2 and message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not list(tmp_path.iterdir())


# -- one episode: draw_trajectory and etmpc figure trajectory --------------------------------------


def _by_gid(ax, gid):
    return [line for line in ax.get_lines() if line.get_gid() == gid]


def _play(system, testset, spec, episode=0, seed=0):
    stored = system.episode_from_arrays(testset.episode_arrays(episode))
    policy = parse_policy(spec, system)
    return stored, run_episode(system, system.make_env(), policy, policy_rng(seed, 0, episode), stored)


@pytest.mark.filterwarnings("error")  # e.g. a layout matplotlib could not apply
def test_trajectory_figure_draws_states_every_plan_and_the_recomputes(cart_system, cart_testset):
    episode, traj = _play(cart_system, cart_testset, "every:3")
    dt, steps = 0.1, traj.steps
    fig = figures.draw_trajectory(cart_system, traj, signals=cart_system.signals(episode))
    axes = fig.axes
    assert len(axes) == 4 + 1 + 1 and steps == 100
    policy_steps = np.flatnonzero(traj.recompute & ~traj.forced)
    assert policy_steps.size == 33 and list(np.flatnonzero(traj.forced)) == [0]  # every:3 with N = 20
    for i, name in enumerate(cart_system.state_names):
        ax = axes[i]
        (realised,) = _by_gid(ax, "realised")
        assert realised.get_linestyle() == "-"
        np.testing.assert_array_equal(realised.get_xdata(), np.arange(101) * dt)
        np.testing.assert_array_equal(realised.get_ydata(), traj.states[:101, i])
        plans = _by_gid(ax, "plan")
        assert len(plans) == len(traj.plans) == 34 and all(line.get_linestyle() == "--" for line in plans)
        np.testing.assert_array_equal(plans[0].get_ydata(), traj.plans[0][1].states[:, i])  # made at 0: all 21
        np.testing.assert_array_equal(plans[0].get_xdata(), np.arange(21) * dt)
        k, last = traj.plans[-1]
        assert k == 99  # the last plan is clipped to the episode: steps 99 and 100
        np.testing.assert_array_equal(plans[-1].get_xdata(), [9.9, 10.0])
        np.testing.assert_array_equal(plans[-1].get_ydata(), last.states[:2, i])
        (recompute,) = _by_gid(ax, "recompute")
        (forced,) = _by_gid(ax, "forced")
        assert recompute.get_marker() != forced.get_marker()
        np.testing.assert_allclose(recompute.get_xdata(), policy_steps * dt)
        np.testing.assert_array_equal(recompute.get_ydata(), traj.states[policy_steps, i])
        np.testing.assert_array_equal(forced.get_xdata(), [0.0])
    assert axes[2].get_ylabel() == "pole angle (rad)" and axes[-1].get_xlabel() == "time (s)"
    force = axes[4]
    (applied,) = _by_gid(force, "applied")
    (planned,) = _by_gid(force, "planned")
    assert applied.get_drawstyle() == "steps-post" and planned.get_linestyle() == "--"
    np.testing.assert_array_equal(applied.get_ydata()[:-1], traj.applied[:, 0])
    np.testing.assert_array_equal(planned.get_ydata()[:-1], traj.planned[:, 0])
    assert sorted(line.get_ydata()[0] for line in _by_gid(force, "bound")) == [-25.0, 25.0]
    assert force.get_ylabel() == "force on cart (N)"
    (disturbance,) = _by_gid(axes[5], "signal")
    np.testing.assert_array_equal(disturbance.get_ydata()[:-1], episode.disturbance)
    assert axes[0].get_legend() is not None and axes[4].get_legend() is not None
    matplotlib.pyplot.close(fig)


@pytest.mark.filterwarnings("error")
def test_trajectory_figure_marks_forced_recomputes_and_draws_the_battery_signals(battery_system, battery_testset):
    episode, traj = _play(battery_system, battery_testset, "never")
    fig = figures.draw_trajectory(battery_system, traj, title="never", signals=battery_system.signals(episode))
    soc, trade, price, production = fig.axes
    (forced,) = _by_gid(soc, "forced")
    np.testing.assert_array_equal(forced.get_xdata(), [0.0, 200.0, 400.0, 600.0, 800.0])  # the plan runs out every N = 20
    assert _by_gid(soc, "recompute")[0].get_xdata().size == 0
    plans = _by_gid(soc, "plan")
    assert len(plans) == 5
    for line, (k, plan) in zip(plans, traj.plans):
        np.testing.assert_array_equal(line.get_xdata(), (k + np.arange(21)) * 10.0)
        np.testing.assert_array_equal(line.get_ydata(), plan.states[:, 0])
    np.testing.assert_array_equal(_by_gid(price, "signal")[0].get_ydata()[:-1], episode.price_eur_kwh[:100])
    np.testing.assert_array_equal(_by_gid(production, "signal")[0].get_ydata()[:-1], episode.production_kw[:100])
    assert price.get_ylabel() == "price (EUR/kWh)" and fig._suptitle.get_text() == "never"
    matplotlib.pyplot.close(fig)


def _learned_policies(root: Path, domain: str, nx: int, biases=(-1.0, 0.0, 1.0)) -> list[str]:
    """Policy files laid out as `etmpc train` does (root/seed<S>/last.json), keeping with different odds."""
    norm = Normalisation.fit(np.random.default_rng(1).normal(size=(50, 2 * nx + 1)))
    specs = []
    for seed, bias in enumerate(biases):
        policy = LogisticPolicy.initial(norm, domain)
        theta = policy.theta.copy()
        theta[-1] = bias
        path = root / f"seed{seed}" / "last.json"
        policy.with_theta(theta).save(path)
        specs.append(f"rl:{path}")
    return specs


def test_trajectory_command_plays_the_episode_as_evaluate_does(tmp_path, capsys):
    """A stochastic policy, seed 3, episode 2: the command's objective is evaluate's for that run."""
    spec = _learned_policies(tmp_path / "run", "battery", 1, biases=(0.5,))[0]
    code, stdout, err = _figure(
        capsys,
        "trajectory",
        "--task",
        "battery",
        "--policy",
        spec,
        "--episode",
        2,
        "--seed",
        3,
        "--out",
        tmp_path / "out" / "traj.png",
    )
    assert code == 0, err
    run = evaluate("battery", [spec], episodes=3, workers=1, seed=3, progress=False).runs[2]
    assert run.episode == 2 and f"objective {run.objective:.5f}, {run.recomputes} recomputes" in stdout
    image = matplotlib.image.imread(tmp_path / "out" / "traj.png")
    assert image.shape[0] > 500 and image.shape[1] > 800 and image.shape[2] == 4 and image.std() > 0.05
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["traj.png"]  # no temporary file left


def test_trajectory_command_default_path(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, stdout, err = _figure(capsys, "trajectory", "--task", "cart_pendulum", "--policy", "threshold:0.3")
    assert code == 0, err
    out = Path("results") / "trajectory_cart_pendulum-balance_threshold-0.3_ep0.png"
    assert stdout.endswith(f"wrote {out}\n") and matplotlib.image.imread(tmp_path / out).shape[1] > 800


def test_trajectory_command_plays_a_task_of_a_domain_with_its_shipped_policy(tmp_path, capsys, monkeypatch):
    """The kicks task with its shipped policy (trained on cart_pendulum/kicks, not on the domain's default
    task): the task's name, not its domain's, checks the policy; the default file is named by the task."""
    spec = f"rl:{REPO / 'policies' / 'cart_pendulum' / 'kicks' / 'learned.json'}"
    monkeypatch.chdir(tmp_path)
    code, stdout, err = _figure(capsys, "trajectory", "--task", "cart_pendulum/kicks", "--policy", spec, "--episode", 1)
    assert code == 0, err
    run = evaluate("cart_pendulum/kicks", [spec], episodes=2, workers=1, progress=False).runs[1]
    assert f"objective {run.objective:.5f}, {run.recomputes} recomputes" in stdout
    (out,) = (tmp_path / "results").iterdir()
    assert out.name.startswith("trajectory_cart_pendulum-kicks_rl-") and out.name.endswith("_ep1.png")


@pytest.mark.parametrize(
    "args, message",
    [
        (("pendulum", "--policy", "always"), "unknown task 'pendulum'"),
        (("cart_pendulum", "--policy", "every:0"), "bad policy 'every:0'"),
        (("battery", "--policy", "always", "--episode", "100"), "out of range"),
        (("battery", "--policy", "always", "--episode", "one"), "'one' is not a whole number"),
        (
            ("cart_pendulum", "--policy", f"rl:{REPO / 'policies' / 'battery' / 'trading' / 'learned.json'}"),
            "was trained on 'battery'",
        ),
    ],
)
def test_trajectory_command_rejects_bad_input(tmp_path, capsys, args, message):
    code, _, err = _figure(capsys, "trajectory", "--task", *args, "--out", tmp_path / "x.png")
    assert code == 2 and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not list(tmp_path.iterdir())


# -- the paper's Figure 3: draw_policy_bars and etmpc figure bars ---------------------------------
@pytest.fixture(scope="module")
def cart_evaluations(tmp_path_factory):
    """A fixed-policy evaluation and one of three learned seeds, 5 repeats (as the paper), on 2 episodes."""
    specs = _learned_policies(tmp_path_factory.mktemp("runs") / "cart", "cart_pendulum", 4)
    fixed = evaluate("cart_pendulum", ["always", "never", "every:3"], episodes=2, workers=1, progress=False)
    learned = evaluate("cart_pendulum", specs, episodes=2, repeats=5, workers=1, progress=False)
    return json.loads(json.dumps(fixed.to_json())), json.loads(json.dumps(learned.to_json())), specs


def _bars(ax):
    return [p for p in ax.patches if p.get_gid() is not None]


def _error_segments(ax):
    return [segment for c in ax.collections if c.get_gid() == "spread" for segment in c.get_segments()]


@pytest.mark.filterwarnings("error")
def test_bars_are_the_evaluations_means_annotated_with_recomputes(cart_evaluations):
    fixed, _, _ = cart_evaluations
    fig = figures.draw_policy_bars([fixed])
    (ax,) = [a for a in fig.axes]
    bars = _bars(ax)
    assert [b.get_gid() for b in bars] == ["always", "never", "every:3"]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["always", "never", "every:3"]
    for bar, spec in zip(bars, ["always", "never", "every:3"]):
        assert bar.get_height() == fixed["policies"][spec]["objective_mean"]
    notes = [t.get_text() for t in ax.texts]
    assert [note.splitlines()[1] for note in notes] == ["100.0 recomp./ep", "5.0 recomp./ep", "34.0 recomp./ep"]
    assert _error_segments(ax) == []  # deterministic policies: no spread over repeats
    assert "lower is better" in ax.get_ylabel() and "cost" in ax.get_ylabel()
    assert ax.get_legend() is not None
    matplotlib.pyplot.close(fig)


@pytest.mark.filterwarnings("error")
def test_learned_seeds_are_one_bar_with_the_std_over_seeds(cart_evaluations):
    fixed, learned, specs = cart_evaluations
    # Independently of the summaries: each seed's mean over all its runs, then over seeds.
    per_seed = [np.mean([r["objective"] for r in learned["runs"] if r["policy"] == spec]) for spec in specs]
    recomputes = [np.mean([r["recomputes"] for r in learned["runs"] if r["policy"] == spec]) for spec in specs]
    assert np.ptp(per_seed) > 0
    fig = figures.draw_policy_bars([fixed, learned])
    ax = fig.axes[0]
    bars = _bars(ax)
    assert [b.get_gid() for b in bars] == ["always", "never", "every:3", "learned (3 seeds)"]
    assert bars[-1].get_height() == pytest.approx(np.mean(per_seed), rel=1e-12)
    (segment,) = _error_segments(ax)
    std = np.std(per_seed, ddof=1)
    np.testing.assert_allclose(segment[:, 1], [np.mean(per_seed) - std, np.mean(per_seed) + std], rtol=1e-12)
    assert segment[0, 0] == bars[-1].get_x() + bars[-1].get_width() / 2
    assert ax.texts[-1].get_text().splitlines()[1] == f"{np.mean(recomputes):.1f} recomp./ep"
    matplotlib.pyplot.close(fig)


def test_ungrouped_learned_policies_have_the_std_over_repeats(cart_evaluations):
    fixed, learned, specs = cart_evaluations
    fig = figures.draw_policy_bars([fixed, learned], group_learned=False)
    ax = fig.axes[0]
    bars = _bars(ax)[3:]
    segments = _error_segments(ax)
    assert len(bars) == len(segments) == 3
    for bar, segment, spec in zip(bars, segments, specs):
        runs = [r for r in learned["runs"] if r["policy"] == spec]
        by_repeat = [np.mean([r["objective"] for r in runs if r["repeat"] == k]) for k in range(5)]
        mean, std = np.mean([r["objective"] for r in runs]), np.std(by_repeat, ddof=1)
        assert bar.get_height() == pytest.approx(mean, rel=1e-12) and std > 0
        np.testing.assert_allclose(segment[:, 1], [mean - std, mean + std], rtol=1e-12)
    matplotlib.pyplot.close(fig)


def test_bars_refuse_evaluations_of_different_tasks_or_episodes(cart_evaluations):
    fixed, _, _ = cart_evaluations
    battery = dict(fixed, domain="battery", task="trading")
    with pytest.raises(EtmpcError, match="mismatched tasks: a evaluates cart_pendulum/balance, b battery/trading"):
        figures.draw_policy_bars([fixed, battery], sources=["a", "b"])
    fewer = json.loads(json.dumps(fixed))
    fewer["policies"] = {"every:5": dict(fewer["policies"]["every:3"], policy="every:5", episodes=1)}
    with pytest.raises(EtmpcError, match="mismatched test-set episodes"):
        figures.draw_policy_bars([fixed, fewer])


def test_png_writers_are_atomic(tmp_path, cart_evaluations, battery_system, battery_testset, monkeypatch):
    fixed, _, _ = cart_evaluations
    out = figures.write_policy_bars_png(tmp_path / "new" / "bars.png", [fixed])
    assert matplotlib.image.imread(out).shape[2] == 4 and [p.name for p in out.parent.iterdir()] == ["bars.png"]
    _, traj = _play(battery_system, battery_testset, "every:5")
    out = figures.write_trajectory_png(tmp_path / "traj.png", battery_system, traj)
    assert matplotlib.image.imread(out).shape[:2] == (int(1.75 * 2 * 120 + 120), int(9.5 * 120))

    def fail(*args):
        raise OSError(28, "No space left on device")

    before = (tmp_path / "traj.png").read_bytes()
    monkeypatch.setattr(outputs.os, "replace", fail)
    with pytest.raises(EtmpcError, match="cannot write .*traj.png: No space left on device"):
        figures.write_trajectory_png(tmp_path / "traj.png", battery_system, traj, title="another")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new", "traj.png"]  # the old file, whole; no temporary
    assert (tmp_path / "traj.png").read_bytes() == before


def test_bars_command_end_to_end(tmp_path, capsys, monkeypatch, cart_evaluations):
    fixed, learned, _ = cart_evaluations
    (tmp_path / "fixed.json").write_text(json.dumps(fixed))
    (tmp_path / "learned.json").write_text(json.dumps(learned))
    monkeypatch.chdir(tmp_path)
    code, stdout, err = _figure(capsys, "bars", "fixed.json", "learned.json")
    assert code == 0 and stdout == f"wrote {Path('results') / 'figure3_cart_pendulum-balance.png'}\n", err
    out = tmp_path / "results" / "figure3_cart_pendulum-balance.png"
    image = matplotlib.image.imread(out)
    assert image.shape[0] > 400 and image.shape[1] > 800 and image.std() > 0.05
    assert [p.name for p in out.parent.iterdir()] == ["figure3_cart_pendulum-balance.png"]
    again = figures.write_policy_bars_png(tmp_path / "again.png", [fixed, learned], sources=["fixed.json", "learned.json"])
    assert out.read_bytes() == again.read_bytes()  # the evaluations' bars, drawn as draw_policy_bars draws them


def test_bars_command_rejects_bad_input(tmp_path, capsys, monkeypatch, cart_evaluations):
    fixed, _, _ = cart_evaluations
    (tmp_path / "fixed.json").write_text(json.dumps(fixed))
    (tmp_path / "battery.json").write_text(json.dumps(dict(fixed, domain="battery", task="trading")))
    (tmp_path / "broken.json").write_text('{"domain": "cart_pendulum", ')
    (tmp_path / "other.json").write_text('{"episodes": []}')
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp_path / "text.json").write_text(json.dumps(dict(fixed, runs=[dict(fixed["runs"][0], objective="0.4")])))
    (tmp_path / "runs.json").write_text(json.dumps(dict(fixed, runs="every:2")))
    cases = [
        (("fixed.json", "missing.json"), "missing.json not found"),
        (("broken.json",), "broken.json: cannot read an evaluation (Expecting property name"),
        (("other.json",), "other.json is not an etmpc evaluation"),
        (("deep.json",), "deep.json: cannot read an evaluation (nested too deeply"),
        (("text.json",), "text.json is not an etmpc evaluation (objective must be a number, got '0.4')"),
        (("runs.json",), "runs.json is not an etmpc evaluation"),
        (
            ("fixed.json", "battery.json"),
            "mismatched tasks: fixed.json evaluates cart_pendulum/balance, battery.json battery/trading",
        ),
        (("fixed.json", "--out", "x.json"), "argument --out: x.json does not end in .png"),
        (("fixed.json", "named.png", "--out", "named.png"), "--out named.png would overwrite the evaluation named.png"),
    ]
    (tmp_path / "named.png").write_text(json.dumps(fixed))
    monkeypatch.chdir(tmp_path)
    for args, message in cases:
        code, _, err = _figure(capsys, "bars", *args, *(() if "--out" in args else ("--out", "x.png")))
        assert code == 2 and message in err, (args, err)
        assert err.count("\n") == 1 and "Traceback" not in err
        assert not (tmp_path / "x.png").exists() and not (tmp_path / "results").exists()
    for args in (("other.json",), ("broken.json",)):  # the default path is not guessed from a document that is not one
        code, _, err = _figure(capsys, "bars", *args)
        assert code == 2 and not (tmp_path / "results").exists()
