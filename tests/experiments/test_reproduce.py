"""`etmpc reproduce` end to end at a tiny size: the report's numbers are the JSON's, the JSON's are a
direct evaluation's, and a second run continues rather than redoes."""

import json

import numpy as np
import pytest

import etmpc
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import evaluate
from etmpc.views.replay import replay_summary
from etmpc.experiments import sweep as sweeps
from etmpc.experiments.reproduce import Settings, reproduce
from etmpc.experiments.report import PAPER
from etmpc.systems import folder_name, make_system, names

from tests.conftest import REPO

# Every registered task but those another one here covers: the two whose only difference from kicks and
# jumps is a fixed latency (kicks_levels takes every path of time in the loop they take: a late plan, the
# trigger not asked, and more); kicks itself, which kicks_levels and kicks_noisy play with time in the loop
# and with a sensor; and the quadrotor's two, tracking tasks like the reacher (a GaussNewtonSystem with a
# target as the OCP's parameter and exogenous features), which takes every path of reproduce they would
# take (kicks_noisy takes the sensor's). Each task costs this module's fixture 15-45 s.
COVERED = (
    "cart_pendulum/kicks",
    "cart_pendulum/kicks_late",
    "reacher/jumps_late",
    "quadrotor/waypoints",
    "quadrotor/waypoints_noisy",
)
TASKS = [t for t in names() if t not in COVERED]

TINY = Settings(
    seeds=(0, 1),
    episodes=2,
    eval_every=1,
    eval_episodes=2,
    test_episodes=3,
    repeats=2,
    record_episodes=1,
    video_size=(64, 48),
    dpi_seeds=(0, 1),
    dpi_episodes=2,
    dpi_eval_every=1,
    dpi_labels=3,
    dpi_futures=2,
    dpi_horizon=5,
    dpi_selection_episodes=2,
    validation_episodes=2,
    rollout_episodes=2,
    rollout_futures=2,
    rollout_horizon=5,
    ppo_timesteps=512,
)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    return out, reproduce(out, TINY, workers=1, domains=TASKS, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("domain", ["cart_pendulum/balance", "battery/trading"])
def test_json_equals_a_direct_evaluation(run, domain):
    out, results = run
    r = results["systems"][domain]
    fixed = evaluate(domain, make_system(domain).benchmark.baselines(), episodes=3, workers=1, progress=False)
    for s in fixed.summaries:
        assert r["fixed"][s.policy]["objective_mean"] == s.objective_mean
        assert r["fixed"][s.policy]["recomputes_mean"] == s.recomputes_mean
    sign = 1 if r["objective_sense"] == "max" else -1
    best = max(fixed.summaries, key=lambda s: sign * s.objective_mean)
    assert r["best_fixed"]["policy"] == best.policy

    specs = [f"rl:{out / domain / 'train' / f'seed{s}' / 'last.json'}" for s in TINY.seeds]
    learned = evaluate(domain, specs, episodes=3, repeats=2, workers=1, progress=False)
    assert r["learned"]["objective_mean"] == pytest.approx(np.mean([x.objective for x in learned.runs]), rel=1e-12)
    assert r["learned"]["per_seed"] == [s.objective_mean for s in learned.summaries]
    # The paired comparison, recomputed here from the two direct evaluations.
    diff = [
        np.mean([x.objective for x in learned.runs if x.episode == e])
        - next(x.objective for x in fixed.runs if x.policy == best.policy and x.episode == e)
        for e in range(3)
    ]
    assert r["paired"]["mean_difference"] == pytest.approx(np.mean(diff), rel=1e-12)
    assert r["paired"]["ci95"] == pytest.approx(1.96 * np.std(diff, ddof=1) / np.sqrt(3), rel=1e-12)


@pytest.mark.slow
def test_the_report_scores_what_the_run_trained_against_the_suites_references(run):
    out, results = run
    report = (out / "REPORT.md").read_text().split("## The scorecard")[1]
    for name, r in results["systems"].items():
        card = r["scorecard"]
        assert card["references"]["episodes"] == 3  # the run's test-set episodes: the references of those
        rows = card["rows"]
        assert rows["best periodic"]["score"] == 0.0  # the reference, played by the run, scores exactly 0
        assert {"best periodic", "best fixed", "DPI", "PPO"} <= set(rows) and (("GPOMDP seed 0" in rows) == (name in PAPER))
        dpi = rows["DPI"]
        direct = etmpc.score([dpi["policy"]], tasks=[name], workers=1, progress=False, episodes=3).rows[0]
        assert dpi["score"] == direct.score and dpi["episode_scores"] == direct.episode_scores
        assert f"{dpi['score']:.1f} ± {dpi['score_ci95']:.1f}" in report


@pytest.mark.slow
def test_report_states_the_json_numbers_and_the_files_exist(run):
    out, results = run
    report = (out / "REPORT.md").read_text()
    assert json.loads((out / "results.json").read_text())["systems"] == results["systems"]
    assert set(results["systems"]) == set(TASKS)  # the paper's tasks, the others and time in the loop
    for name, r in results["systems"].items():
        folder, best = folder_name(name), r["best_fixed"]
        assert f"| `{best['policy']}` **(best fixed)** | {best['objective_mean']:.5f} |" in report
        default = r["default_learner"]["paired"]
        assert f"gain {default['gain_percent']:+.2f} % ± {default['gain_percent_ci95']:.2f} %" in report
        learned = {f"rl:{out / 'policies' / folder / 'learned.json'}"}
        if name in PAPER:  # the paper's learner (GPOMDP) runs on the paper's tasks only
            assert f"{r['paired']['mean_difference']:+.5f} ± {r['paired']['ci95']:.5f}" in report
            assert f"| learned (2 seeds x 2 passes) | {r['learned']['objective_mean']:.5f} |" in report
            learned.add(f"rl:{out / folder / 'train' / 'seed0' / 'last.json'}")
        else:
            assert "paired" not in r and "learned" not in r["files"]
        for file in r["files"].values():
            assert (out / file).is_file() and (out / file).stat().st_size > 0, file
        replayed = replay_summary(out / folder / "episodes.rrd")
        assert {e.policy for e in replayed} == {best["policy"], *learned}
    against = report.split("## Against the paper")[1]
    for domain, r in results["systems"].items():
        if domain not in PAPER:
            continue
        (claim,) = [line for line in against.splitlines() if f"best on {domain}," in line]
        verdict = (
            "Holds" if r["margin_percent"] > 0 and r["paired"]["ci95"] < abs(r["paired"]["mean_difference"]) else "Does not hold"
        )
        assert verdict in claim and f"{r['margin_percent']:+.2f} %" in claim
    assert results["software"]["mujoco"] == "3.17.0" and results["machine"]["cores"] >= 1


@pytest.mark.slow
def test_a_second_run_continues_and_other_settings_are_refused(run):
    out, results = run
    mtimes = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name not in ("results.json", "REPORT.md")}
    again = reproduce(out, TINY, workers=1, domains=TASKS, progress=False)
    assert again["systems"] == results["systems"]
    assert {p: p.stat().st_mtime_ns for p in mtimes} == mtimes  # nothing was redone
    with pytest.raises(EtmpcError, match="other settings"):
        reproduce(out, Settings(seeds=(0,), episodes=2, eval_every=1, test_episodes=3), workers=1, domains=TASKS, progress=False)


@pytest.mark.slow
def test_make_sweep_adds_the_trade_off_curves_to_a_finished_run(tmp_path, monkeypatch):
    """`make reproduce`, then `make sweep` on the same directory: the second redoes no stage of the
    first, and adds each task's sweep (exactly its pareto.json) and its section to the report."""
    tiny = sweeps.SweepSettings(
        prices=(0.0, 1e-3), episodes=1, thresholds=(0.01,), futures=1, horizon=2, learner=None, self_trigger=None
    )
    monkeypatch.setattr(sweeps.SweepSettings, "default", classmethod(lambda cls, domain, quick=False: tiny))
    first = reproduce(tmp_path, TINY, workers=1, domains=["battery"], progress=False)
    mtimes = {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*") if p.is_file() and p.name not in ("results.json", "REPORT.md")}
    second = reproduce(tmp_path, TINY, workers=1, domains=["battery"], progress=False, sweep=True)  # named as a user may
    assert {p: p.stat().st_mtime_ns for p in mtimes} == mtimes  # nothing was redone
    assert "sweep" not in first and second["systems"] == first["systems"]
    pareto = json.loads((tmp_path / "sweep" / "battery" / "trading" / "pareto.json").read_text())
    assert second["sweep"]["battery/trading"]["points"] == pareto["points"]
    assert "![trade-off](sweep/battery/trading/pareto.png)" in (tmp_path / "REPORT.md").read_text()


@pytest.mark.slow
@pytest.mark.parametrize("domain", ["cart_pendulum/balance", "battery/trading"])
def test_headroom_and_the_default_learner_are_direct_evaluations(run, domain):
    out, results = run
    r = results["systems"][domain]
    best, sense = r["best_fixed"]["policy"], r["objective_sense"]
    sign = 1 if sense == "max" else -1
    # The shipped policy is the validation-chosen (seed, iteration)'s DPI policy, byte for byte in content.
    selected = json.loads((out / domain / "train_dpi" / "selected.json").read_text())
    assert json.loads((out / "policies" / domain / "learned.json").read_text()) == selected
    validation = r["default_learner"]["validation"]
    seed, episodes = map(int, (max if sense == "max" else min)(validation, key=validation.get).split("@"))
    assert (selected["hyperparameters"]["seed"], selected["hyperparameters"]["episodes"]) == (seed, episodes)
    # Each headroom row is that policy's evaluation, paired with the best fixed one on the same episodes.
    direct = evaluate(domain, [f"rollout:{best}:2:5", f"oracle:{best}", best], episodes=2, workers=1, progress=False)
    by = {(x.policy, x.episode): x.objective for x in direct.runs}
    for key, spec in (("rollout", f"rollout:{best}:2:5"), ("oracle", f"oracle:{best}")):
        row = r["headroom"]["rows"][key]
        diff = [by[spec, e] - by[best, e] for e in range(2)]
        assert row["policies"] == [spec] and row["mean_difference"] == pytest.approx(np.mean(diff), rel=1e-12, abs=1e-15)
        assert row["gain_percent"] == pytest.approx(100 * sign * np.mean(diff) / abs(np.mean([by[best, e] for e in range(2)])))
    report = (out / "REPORT.md").read_text()
    assert f"`oracle:{best}`" in report and "**not a policy**" in report


@pytest.mark.slow
def test_a_smoke_report_says_so_at_its_top_and_gives_no_verdicts(run):
    from etmpc.experiments.report import report

    _, results = run
    smoke = dict(results, settings=dict(results["settings"], smoke=True))
    text = report(smoke)
    assert "smoke run" in text.split("## ")[0]
    assert "Holds" not in text and "Does not hold" not in text and "exclude 0" not in text
    assert "No verdicts in a smoke run." in text


@pytest.mark.slow
def test_the_learners_row_of_ppo_is_its_network_evaluated_against_the_best_fixed_policy(run):
    pytest.importorskip("stable_baselines3")
    out, results = run
    r = results["systems"]["battery/trading"]
    row, best = r["learners"]["ppo"], r["learners"]["reference"]
    spec = f"sb3:{out / 'battery' / 'trading' / 'train_ppo' / 'selected.zip'}"
    direct = evaluate("battery", [spec, best], episodes=3, workers=1, progress=False)
    by = {(x.policy, x.episode): x.objective for x in direct.runs}
    assert row["policies"] == [spec] and row["episodes"] == 3
    assert row["mean_difference"] == pytest.approx(np.mean([by[spec, e] - by[best, e] for e in range(3)]), rel=1e-12, abs=1e-15)
    assert row["training"]["environment_steps"] == 512 and row["training"]["wall_seconds"] > 0
    assert "PPO (Stable-Baselines3, `sb3:`)" in (out / "REPORT.md").read_text()


def test_the_docs_results_page_is_the_runs_report_with_its_provenance_and_figures(run, tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("results_pages", REPO / "scripts" / "results_pages.py")
    pages = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pages)
    out, _ = run
    page = pages.write_pages(out, tmp_path / "results").read_text()
    # the run's directory as it is now: another test continues the run, which writes results.json again
    results = json.loads((out / "results.json").read_text())
    assert f"commit {results['provenance']['commit']}" in page and results["provenance"]["date"] in page
    report = (out / "REPORT.md").read_text()
    lines = page.splitlines()
    assert all(line in lines for line in report.splitlines()[1:] if "![" not in line)  # the run's report, whole
    shown = pages.IMAGE.findall(page)
    assert shown and all((tmp_path / "results" / target).is_file() for _, target in shown)


@pytest.mark.slow
def test_the_run_ships_ppo_with_its_hyperparameters_and_draws_every_learners_sample_efficiency(run):
    pytest.importorskip("stable_baselines3")
    out, results = run
    for name, r in results["systems"].items():
        folder = folder_name(name)
        ppo_dir, shipped = out / folder / "train_ppo", out / "policies" / folder
        training = json.loads((ppo_dir / "training.json").read_text())
        # The chosen network and its description, copied as they are, with the hyperparameters it used.
        assert (shipped / "ppo.zip").read_bytes() == (ppo_dir / "selected.zip").read_bytes()
        assert (shipped / "ppo.json").read_bytes() == (ppo_dir / "selected.json").read_bytes()
        from etmpc.learning import hyperparams

        used = hyperparams.load(shipped / "ppo.yml", name)
        assert used.timesteps == 512 and used.reward_baseline == hyperparams.shipped(name).reward_baseline
        # PPO's curve is its checkpoints on the test set; its last point is what the run simulated, the
        # baseline's lockstep simulation included (no task's episode fails here: twice the agent's steps).
        curves = r["efficiency"]
        assert [p["timesteps"] for p in curves["ppo"]] == [c["timesteps"] for c in training["checkpoints"]]
        assert curves["ppo"][-1]["simulated_steps"] == training["simulated_steps"] == 2 * training["environment_steps"]
        assert ("gpomdp" in curves) == (name in PAPER) and len(curves["dpi"]) == TINY.dpi_episodes // TINY.dpi_eval_every + 1
        row = r["learners"]["dpi"]["training"]
        assert row["simulated_steps_per_seed"] == curves["dpi"][-1]["simulated_steps"] and row["wall_seconds"] > 0
        assert (out / r["files"]["efficiency"]).read_bytes()[:4] == b"\x89PNG"
    report = (out / "REPORT.md").read_text()
    assert "simulated steps per run" in report and "![sample efficiency](battery/trading/efficiency.png)" in report


@pytest.mark.slow
def test_the_report_says_how_the_runs_policies_depart_from_the_shipped_ones(run):
    """A tiny run trains with other budgets than the shipped files record: each says so, naming the budget
    as the two files give it (the shipped file's, then the run's)."""
    out, results = run
    report = (out / "REPORT.md").read_text().split("## This run's policies and the shipped ones")[1]
    for name, r in results["systems"].items():
        shipped = REPO / "policies" / folder_name(name)
        recipe = json.loads((shipped / "learned.json").read_text())["hyperparameters"]
        dpi = r["shipped"]["DPI"]
        assert dpi["verdict"] == "differs"
        assert dpi["recipe"]["states_per_episode"] == [recipe["states_per_episode"], TINY.dpi_labels]
        assert dpi["recipe"]["futures"] == [recipe["futures"], TINY.dpi_futures]
        assert f"| {name} | DPI | other parameters: " in report
        if "PPO" in r["shipped"]:
            timesteps = json.loads((shipped / "ppo.json").read_text())["settings"]["timesteps"]
            assert r["shipped"]["PPO"]["recipe"]["timesteps"] == [timesteps, TINY.ppo_timesteps]


@pytest.mark.slow
def test_the_papers_learner_trains_on_the_papers_features_as_the_report_says(run):
    out, _ = run
    for name in PAPER:
        config = json.loads((out / folder_name(name) / "train" / "checkpoint.json").read_text())["config"]
        assert config["algorithm"] == "gpomdp" and config["features"] == "paper"
    assert "GPOMDP, paper features" in (out / "REPORT.md").read_text()


@pytest.mark.slow
def test_every_stage_of_every_task_is_timed_and_the_report_says_where_the_time_went(run):
    out, results = run
    report = (out / "REPORT.md").read_text().split("## Where the time went")[1]
    wall = results["wall_seconds_this_invocation"]
    totals = {}
    for name, r in results["systems"].items():
        times = r["stage_seconds"]
        expected = {"fixed policies", "DPI training", "DPI evaluation", "rollout", "oracle", "figures, recording, video"}
        expected |= {"GPOMDP training", "GPOMDP evaluation"} if name in PAPER else set()
        expected |= {"PPO training", "PPO evaluation"} if "ppo" in r["efficiency"] else set()
        assert expected <= set(times) and all(v > 0 for v in times.values()), (name, times)
        # A training stage's clock holds the learner's own timer (its wall time in the report's learners table).
        for stage, folder in (("DPI training", "train_dpi"), ("GPOMDP training", "train"), ("PPO training", "train_ppo")):
            if stage in times:
                inner = json.loads((out / folder_name(name) / f"{folder}_cost.json").read_text())["wall_seconds"]
                assert inner <= times[stage] <= inner + 5.0
        totals[name] = sum(times.values())
    assert sum(totals.values()) <= wall  # stages are disjoint parts of the one invocation that played them all
    for name, total in totals.items():
        (row,) = [line for line in report.splitlines() if line.startswith(f"| {name} | ")]
        assert row.endswith(f"| {total / 60:.1f} | {100 * total / sum(totals.values()):.0f} % |")
    costliest = max(totals, key=totals.get)
    assert f"Costliest: {costliest}, {totals[costliest] / 60:.1f} min of {sum(totals.values()) / 60:.1f}." in report


def test_a_run_made_before_dpi_selection_episodes_was_a_setting_continues():
    """Its settings.json has no such key: the default writes none, so the same run is not refused as another."""
    assert "dpi_selection_episodes" not in Settings().to_json()
    assert TINY.to_json()["dpi_selection_episodes"] == 2
