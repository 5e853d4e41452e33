"""The scorecard (etmpc score): normalized scores between fixed references, the suite's aggregate, the
stored references, and its bad inputs.

Independent truths: the two references score exactly 0 and 100 (an identity of the formula); the score
of any trigger equals the formula computed by hand from the per-episode objectives; the interquartile
mean of four task scores is the mean of the middle two; a stored reference is what playing the same
episode again gives, bit for bit.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import replace

import numpy as np
import pytest

import etmpc
from etmpc.cli import main
from etmpc.common.documents import content_sha256, sealed
from etmpc.common.errors import EtmpcError
from etmpc.evaluation import testsets
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.references import (
    SUITE_VERSION,
    References,
    build_references,
    load_references,
    references_path,
    rollout_meter_spec,
    write_references,
)
from etmpc.evaluation.scorecard import TaskScore, aggregate, task_score
from etmpc.systems import make_system, names


@pytest.fixture(scope="module")
def small_battery(tmp_path_factory):
    """A 4-episode battery test set and its references, computed as ``score --test-set`` computes them."""
    path = tmp_path_factory.mktemp("score") / "small.npz"
    testsets.draw(make_system("battery"), 7, 4, path)
    return path, build_references("battery", str(path), workers=1, progress=False, meter=False)


def test_the_two_references_score_exactly_0_and_100(small_battery):
    path, refs = small_battery
    played = evaluate("battery", [refs.best, refs.oracle_spec], workers=1, test_set=str(path), progress=False)
    best, oracle = task_score(refs, played, refs.best), task_score(refs, played, refs.oracle_spec)
    assert best.score == 0.0 and oracle.score == 100.0
    assert best.episode_scores == [0.0] * 4 and best.better_share == 0.5  # every episode a tie


def test_a_score_is_the_formula_computed_by_hand(small_battery):
    path, refs = small_battery
    played = evaluate("battery", ["every:7", "always"], workers=1, test_set=str(path), progress=False)
    profits = {spec: np.array([r.objective for r in played.runs if r.policy == spec]) for spec in ("every:7", "always")}
    best, oracle = np.array(refs.periodic[refs.best]), np.array(refs.oracle)  # the battery's objective is a profit
    for spec, profit in profits.items():
        by_hand = 100 * (profit.mean() - best.mean()) / (oracle.mean() - best.mean())
        row = task_score(refs, played, spec)
        assert row.score == pytest.approx(by_hand, rel=1e-12, abs=1e-9)
        assert np.mean(row.episode_scores) == pytest.approx(by_hand, rel=1e-9, abs=1e-9)
        assert row.better_share == np.mean((profit > best) + 0.5 * (profit == best))
        # The failures: each episode's count, in episode order (to pair them), their mean and 1.96 sd / sqrt(n).
        counts = [r.failures for r in sorted(played.runs, key=lambda r: r.episode) if r.policy == spec]
        assert row.episode_failures == counts and all(type(c) is int for c in counts)
        assert row.failures_mean == pytest.approx(statistics.fmean(counts), abs=1e-12)
        assert row.failures_ci95 == pytest.approx(1.96 * statistics.stdev(counts) / math.sqrt(4), abs=1e-12)
    assert task_score(refs, played, "every:7").failures_ci95 > 0  # the counts differ between episodes


def _row(task: str, scores) -> TaskScore:
    scores = list(map(float, scores))
    return TaskScore(
        task,
        "mine",
        len(scores),
        0.0,
        "min",
        0.0,
        None,
        0,
        0,
        float(np.mean(scores)),
        0.0,
        scores,
        0.0,
        {"solve": 1.0, "feedback": 0.5, "decide": 0.25, "total": 1.75},
        "every:3",
    )


def test_the_suites_interquartile_mean_is_the_mean_of_the_middle_half_of_every_episode_score():
    rng = np.random.default_rng(3)
    rows = [_row(t, rng.normal(m, 10, 30)) for t, m in zip("abcd", (-50, 10, 30, 400))]
    every = np.sort(np.concatenate([r.episode_scores for r in rows]))  # 120 scores: drop 30 at each end
    result = aggregate(rows)
    assert result.iqm == pytest.approx(every[30:90].mean(), rel=1e-12)
    assert result.iqm_ci95[0] < result.iqm < result.iqm_ci95[1]
    assert aggregate(rows) == result  # the bootstrap is seeded
    improved = np.mean([np.mean(np.asarray(r.episode_scores) > 0) for r in rows])
    assert result.probability_of_improvement == pytest.approx(improved)


def test_the_performance_profile_is_the_share_of_episodes_above_each_threshold_averaged_over_tasks():
    from etmpc.evaluation.scorecard import profile

    rows = [_row("a", [0, 50, 100]), _row("b", [-10, 200])]
    curve = profile(rows, np.array([-20.0, -10.0, 0.0, 60.0, 100.0, 200.0]))
    expected = [(3 / 3 + 2 / 2) / 2, (3 / 3 + 1 / 2) / 2, (2 / 3 + 1 / 2) / 2, (1 / 3 + 1 / 2) / 2, (0 + 1 / 2) / 2, 0.0]
    np.testing.assert_allclose(curve, expected, rtol=0, atol=1e-15)


def test_an_unscored_task_is_left_out_of_the_aggregate():
    rows = [_row("a", [10, 20]), _row("b", [30, 50])]
    unscored = TaskScore("c", "mine", 2, 0.0, "min", 0.0, None, 0, 1, math.nan, math.nan, [], math.nan, {}, "every:3")
    assert aggregate(rows + [unscored]).tasks == 2
    assert aggregate(rows + [unscored]).iqm == pytest.approx(25.0)  # the middle two of 10, 20, 30, 50


def test_a_score_from_an_evaluation_is_the_score_from_its_json(small_battery, tmp_path):
    """One way to a row: the played evaluation and its JSON (as ``etmpc evaluate --json`` writes it) give the
    same row, but for the CPU times only the played one carries."""
    from etmpc.common.outputs import write_json

    path, refs = small_battery
    played = evaluate("battery", ["every:5", "threshold:0.02"], workers=1, test_set=str(path), progress=False)
    data = json.loads(write_json(tmp_path / "evaluation.json", played.to_json()).read_text())
    for spec in ("every:5", "threshold:0.02"):
        row, again = task_score(refs, played, spec), task_score(refs, data, spec)
        assert set(row.cpu_ms) == {"solve", "feedback", "decide", "total"} and again.cpu_ms == {}
        assert replace(row, cpu_ms={}) == again
    other = dict(data, test_set=dict(data["test_set"], sha256="0" * 64))
    with pytest.raises(EtmpcError, match="another test set"):
        task_score(refs, other, "every:5")


def test_a_card_round_trips_through_its_json_missing_numbers_included(tmp_path):
    from etmpc.common.outputs import write_json
    from etmpc.evaluation.scorecard import Aggregate, Scorecard, failed_task
    from etmpc.evaluation.scoretable import format_scorecard

    rows = [_row("battery", [10.0, -20.0, 5.0]), _row("reacher", [1.0]), failed_task("reacher", "other", "it failed")]
    rows[0] = replace(
        rows[0], failures_mean=4 / 3, failures_ci95=1.96 * statistics.stdev([0, 1, 3]) / 3**0.5, episode_failures=[0, 1, 3]
    )
    rows[1] = replace(
        rows[1], score_ci95=math.nan, failures_mean=2.0, failures_ci95=math.nan, episode_failures=[2]
    )  # one episode: no interval
    card = Scorecard(
        ["battery", "reacher"],
        {"battery": {"best_periodic": "every:3", "oracle": "oracle:every:3"}},
        rows,
        [aggregate(rows[:2]), aggregate(rows[2:])],
    )
    text = write_json(tmp_path / "card.json", card.to_json()).read_text()
    assert "NaN" not in text  # strict JSON: null
    written = json.loads(text)["rows"]
    assert (
        written[1]["failures_ci95"] is None and written[1]["episode_failures"] == [2] and written[2]["episode_failures"] is None
    )
    again = Scorecard.from_json(json.loads(text))
    assert math.isnan(again.rows[1].failures_ci95) and again.rows[2].failures_ci95 is None  # not known / not counted
    assert format_scorecard(again) == format_scorecard(card)
    assert json.dumps(again.to_json()["rows"]) == json.dumps(card.to_json()["rows"])  # NaN for NaN, null read as NaN
    assert again.aggregates[0] == card.aggregates[0] and isinstance(again.aggregates[0].iqm_ci95, tuple)
    assert all(map(math.isnan, again.aggregates[1].iqm_ci95)) and isinstance(again.aggregates[1], Aggregate)
    unmeasured = format_scorecard(Scorecard(["battery"], {}, [replace(rows[0], cpu_ms={})], []))
    assert unmeasured.splitlines()[3].split()[-4:] == ["-", "-", "-", "-"]  # CPU not measured: no numbers
    shown = format_scorecard(card).splitlines()
    assert f"1.33 ± {rows[0].failures_ci95:.2f}" in shown[3] and "2.00 ± n/a" in shown[4]  # failures per episode, mean ± 95 % CI


def test_a_card_row_of_an_older_etmpc_without_the_failures_ci_and_counts_still_loads():
    from etmpc.evaluation.scorecard import Scorecard
    from etmpc.evaluation.scoretable import format_scorecard

    old = replace(_row("cart_pendulum/kicks", [10.0, -20.0]), failures_mean=0.5).to_json()
    for name in ("failures_ci95", "episode_failures", "task_version"):  # fields an older etmpc did not write
        del old[name]
    row = TaskScore.from_json(json.loads(json.dumps(old)))
    assert (row.failures_mean, row.failures_ci95, row.episode_failures) == (0.5, None, None)  # the CI is not known
    line = format_scorecard(Scorecard(["cart_pendulum/kicks"], {}, [row], [])).splitlines()[3]
    assert " 0.50 " in line and "0.50 ±" not in line  # the mean alone


def test_a_suite_score_in_a_log_counts_the_whole_cards_episodes_on_stderr_and_keeps_stdout_for_results(monkeypatch, capsys):
    import re

    from etmpc.common import progress

    for name in ("FIRST_LINE_AFTER", "EVERY", "CLOSEST", "MEASURED"):  # a line at every episode from the second (a rate)
        monkeypatch.setattr(progress, name, 0.0)
    argv = [
        "score",
        "--policy",
        "every:3",
        "--policy",
        "every:5",
        "--task",
        "battery",
        "--task",
        "cart_pendulum",
        "--episodes",
        "2",
        "--workers",
        "1",
    ]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.startswith("etmpc score: ")]
    line = re.compile(r"etmpc score: (\d+)/8 episodes, \d+:\d\d elapsed, about \d+:\d\d left$")
    counts = [int(m[1]) for m in map(line.match, lines) if m]
    assert counts == list(range(2, 8)) and re.fullmatch(r"etmpc score: 8/8 episodes, done in \d+:\d\d", lines[-1])
    assert "elapsed" not in out and "references: battery" in out


def test_a_score_over_fewer_episodes_than_its_ci_needs_says_so_in_one_line_and_the_card_is_the_same():
    from etmpc.evaluation.metrics import CI_EPISODES
    from etmpc.evaluation.scorecard import Scorecard, failed_task
    from etmpc.evaluation.scoretable import format_scorecard

    enough = _row("battery", range(CI_EPISODES))
    few = _row("reacher", range(CI_EPISODES - 1))
    whole = Scorecard(["battery"], {}, [enough], [aggregate([enough])])
    assert not any(line.startswith("note:") for line in format_scorecard(whole).splitlines())
    card = Scorecard(["battery", "reacher"], {}, [enough, few, failed_task("battery", "other", "it failed")], [])
    (note,) = [line for line in format_scorecard(card).splitlines() if line.startswith("note:")]
    assert f"{CI_EPISODES - 1} episodes on reacher, fewer than the {CI_EPISODES}" in note and "battery" not in note
    assert "note:" not in json.dumps(card.to_json())  # the human-readable output only: the card's fields are its own


@pytest.mark.parametrize("task", names())
def test_the_stored_references_are_what_playing_the_episodes_again_gives(task):
    system = make_system(task)
    stored = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    refs = load_references(task, stored.sha256)
    assert refs.suite_version == SUITE_VERSION and refs.episodes == stored.episodes and refs.gap > 0
    sign = 1 if system.objective_sense == "min" else -1
    assert refs.best == min(refs.periodic, key=lambda s: sign * np.mean(refs.periodic[s]))
    played = evaluate(task, [refs.best, refs.oracle_spec], episodes=1, workers=1, progress=False)
    again = {r.policy: r.objective for r in played.runs}
    assert again == {refs.best: refs.periodic[refs.best][0], refs.oracle_spec: refs.oracle[0]}
    if refs.oracle_evaluation is not None:  # the oracle's whole run as kept for the leaderboard's row: its first episode
        kept = next(r for r in refs.oracle_evaluation["runs"] if r["episode"] == 0)
        again = next(r for r in played.to_json()["runs"] if r["policy"] == refs.oracle_spec)
        assert kept == json.loads(json.dumps(again))  # objective, computations, failures, solver failures
    meter = rollout_meter_spec(system, refs.best)
    assert refs.kept_evaluation(meter) is refs.rollout_evaluation and (refs.rollout_evaluation is None) == (meter is None)
    one_per_domain = ("cart_pendulum/balance", "battery/trading", "quadrotor/waypoints")  # a rollout costs seconds
    if meter is not None and task in one_per_domain:
        kept = next(r for r in refs.rollout_evaluation["runs"] if r["episode"] == 0)
        again = evaluate(task, [meter], episodes=1, workers=1, progress=False).to_json()["runs"][0]
        assert kept == json.loads(json.dumps(again))


def test_playing_the_meter_again_keeps_the_scale_and_replays_the_stored_meter(monkeypatch):
    import etmpc.evaluation.references as references

    first = lambda key, specs, **run: evaluate(key, specs, **(run | {"episodes": 1}))  # noqa: E731 (one episode: seconds)
    monkeypatch.setattr(references, "evaluate", first)
    before = references.stored("battery/trading")
    after = references.replay_meter("battery/trading", workers=1, progress=False)
    assert replace(after, rollout_evaluation=None) == replace(before, rollout_evaluation=None)
    kept = next(r for r in before.rollout_evaluation["runs"] if r["episode"] == 0)
    assert after.rollout_evaluation["runs"] == [kept]  # an exact sensor: the meter as it was


def test_meter_only_belongs_to_references(capsys):
    assert main(["score", "--meter-only", "every:1"]) != 0
    assert "--meter-only is --references'" in capsys.readouterr().err


def test_scoring_plays_only_the_trigger_and_says_what_it_costs(tmp_path):
    best = json.loads(references_path("battery").read_text())["best"]
    card = etmpc.score([best, "threshold:0.01"], tasks=["battery"], workers=1, progress=False, json_path=tmp_path / "card.json")
    rows = {r.policy: r for r in card.rows}
    assert rows[best].score == 0.0 and card.references["battery/trading"]["best_periodic"] == best
    assert all(r.cpu_ms["solve"] > 0 and r.cpu_ms["total"] >= r.cpu_ms["solve"] for r in card.rows)
    assert json.loads((tmp_path / "card.json").read_text())["rows"][1]["policy"] == "threshold:0.01"


def test_on_another_test_set_the_references_are_computed_and_said_so(small_battery, capsys):
    path, refs = small_battery
    figure = path.with_name("profile.png")
    argv = [
        "score",
        "--policy",
        refs.best,
        "--policy",
        refs.oracle_spec,
        "--task",
        "battery",
        "--test-set",
        str(path),
        "--workers",
        "1",
    ]
    assert main([*argv, "--figure", str(figure)]) == 0
    out, err = capsys.readouterr()
    assert f"battery/trading: no stored references for test set {path}: computing them for this run" in err
    assert f"references: battery/trading: {refs.best} and {refs.oracle_spec} (computed)" in out
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_trigger_that_fails_on_one_task_has_that_row_say_so_and_the_others_scored(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.dont_write_bytecode", True)
    (tmp_path / "picky_trigger.py").write_text(  # the battery's state has one component, the cart pendulum's four
        "class T:\n    spec = 'picky'\n    stochastic = False\n    def decide(self, s, rng):\n"
        "        if len(s.x) == 1:\n            raise RuntimeError('not for batteries')\n        return s.age >= 3\n"
    )
    code = main(
        [
            "score",
            "--policy",
            "py:picky_trigger:T",
            "--task",
            "battery",
            "--task",
            "cart_pendulum",
            "--workers",
            "2",
            "--json",
            "card.json",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 2
    assert "failed: policy py:picky_trigger:T: decide raised RuntimeError: not for batteries" in out
    assert err.strip().splitlines()[-1] == (
        "etmpc: error: not every policy could be scored on every task: "
        "py:picky_trigger:T on battery/trading (see its row); card.json not written (a card "
        "with a failed row never is)"
    )
    assert not (tmp_path / "card.json").exists() and "wrote card.json" not in out  # nor said to be
    card = etmpc.score(["py:picky_trigger:T"], tasks=["battery", "cart_pendulum"], workers=1, progress=False)
    rows = {r.task: r for r in card.rows}
    assert not card.complete and rows["battery/trading"].error and rows["cart_pendulum/balance"].error is None
    assert json.loads(references_path("cart_pendulum").read_text())["best"] == "every:3"
    assert rows["cart_pendulum/balance"].score == 0.0  # it plays every:3, the cart pendulum's best periodic schedule


@pytest.mark.parametrize(
    "argv, says",
    [
        (["score", "--policy", "every:3", "--task", "cartpole"], "unknown task 'cartpole'"),
        (["score", "--task", "battery"], "give at least one policy"),
        (["score", "--policy", "every:3", "--policy", "every:3"], "given twice"),
        (["score", "--policy", "every:3", "--task", "battery", "--task", "reacher", "--test-set", "x.npz"], "x.npz not found"),
        (["score", "--policy", "every:3", "--references"], "--references rebuilds the stored references only"),
    ],
)
def test_bad_input_is_one_line(argv, says, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err, err
    assert list(tmp_path.iterdir()) == []


def test_references_made_for_another_test_set_or_suite_version_are_refused(tmp_path, small_battery):
    stored = json.loads(references_path("battery").read_text())
    for change, says in (
        (dict(test_set_sha256="0" * 64), "were made on test set 000000000000"),
        (dict(suite_version=SUITE_VERSION + 1), f"suite version {SUITE_VERSION + 1}"),
        (dict(recompute_price=1.0), "at price 1.0"),
        (dict(oracle=stored["oracle"][:3]), "inconsistent"),
    ):
        path = tmp_path / "refs.json"
        path.write_text(json.dumps(sealed(stored | change)))  # sealed: the check of the content itself is reached
        with pytest.raises(EtmpcError, match=f"{says}.*rebuild them with: etmpc score --references --task battery"):
            load_references("battery", stored["test_set_sha256"], path)
    with pytest.raises(EtmpcError, match="--test-set belongs to one task"):
        etmpc.score(["every:3"], tasks=["battery", "reacher"], test_set=str(small_battery[0]))


def _edited(stored: dict, edit) -> dict:
    data = json.loads(json.dumps(stored))
    edit(data)
    return data


def _swap_best(data: dict) -> None:
    data["best"] = "every:2"


def _worse_oracle(data: dict) -> None:  # the battery's objective is a profit: less is worse
    data["oracle"][7] = data["periodic"][data["best"]][7] - 1.0
    del data["oracle_evaluation"]  # else refused first for not holding the oracle's objectives (the next case)


def _oracle_run_not_the_oracle(data: dict) -> None:
    data["oracle_evaluation"]["runs"][7]["objective"] += 1.0


def _periodic_a_list(data: dict) -> None:
    data["periodic"] = list(data["periodic"].values())


def _episodes_text(data: dict) -> None:
    data["episodes"] = "100"


def _best_a_number(data: dict) -> None:
    data["best"] = 3


def _a_missing_schedule(data: dict) -> None:
    del data["periodic"]["every:20"]


def _nan_objective(data: dict) -> None:
    data["periodic"]["every:4"][0] = None


def _rollout_of_another_schedule(data: dict) -> None:
    for run in data["rollout_evaluation"]["runs"]:
        run["policy"] = run["policy"].replace("rollout:every:1:", "rollout:every:2:")


def _rollout_missing_an_episode(data: dict) -> None:
    del data["rollout_evaluation"]["runs"][-1]


@pytest.mark.parametrize(
    "edit, says",
    [
        (_rollout_of_another_schedule, "rollout_evaluation is not rollout:every:1:4:20's run on 100 episodes"),
        (_rollout_missing_an_episode, "rollout_evaluation is not rollout:every:1:4:20's run on 100 episodes"),
        (_swap_best, "best names 'every:2', but every:1 has the best mean objective"),
        (_oracle_run_not_the_oracle, "oracle_evaluation does not hold the oracle's objectives"),
        (_worse_oracle, "the oracle does worse than every:1 on episode 7"),
        (_periodic_a_list, "periodic must hold every:1 .. every:20 in order"),
        (_episodes_text, "episodes '100' is not a count"),
        (_best_a_number, "best names 3"),
        (_a_missing_schedule, "periodic must hold every:1 .. every:20"),
        (_nan_objective, "need 100 finite objectives"),
    ],
)
def test_references_that_do_not_hold_together_are_refused_even_when_sealed(edit, says, tmp_path):
    """Each edit is sealed again, as a careful forger would: the content checks themselves refuse it."""
    stored = json.loads(references_path("battery").read_text())
    path = tmp_path / "refs.json"
    path.write_text(json.dumps(sealed(_edited(stored, edit))))
    with pytest.raises(EtmpcError, match="inconsistent") as raised:
        load_references("battery", stored["test_set_sha256"], path)
    assert says in str(raised.value), raised.value


def test_references_edited_by_hand_are_refused_by_their_checksum(tmp_path):
    """The stored battery references with one number changed and the seal left as it was, or taken away."""
    stored = json.loads(references_path("battery").read_text())
    assert stored["sha256"] == content_sha256(stored)  # the shipped file is sealed
    better = _edited(stored, lambda d: d["periodic"]["every:1"].__setitem__(0, d["periodic"]["every:1"][0] + 0.5))
    unsealed = {k: v for k, v in stored.items() if k != "sha256"}
    for data, says in ((better, "does not match its checksum"), (unsealed, "carries no checksum")):
        path = tmp_path / "refs.json"
        path.write_text(json.dumps(data))
        with pytest.raises(EtmpcError, match=says):
            load_references("battery", stored["test_set_sha256"], path)
    nan = tmp_path / "nan.json"
    nan.write_text(references_path("battery").read_text().replace('"every:2": [\n    ', '"every:2": [\n    NaN, ', 1))
    with pytest.raises(EtmpcError, match="NaN is not a JSON number"):
        load_references("battery", stored["test_set_sha256"], nan)


def test_a_references_file_round_trips(small_battery, tmp_path):
    _, refs = small_battery
    path = write_references(refs, tmp_path / "refs.json")
    assert load_references("battery", refs.test_set_sha256, path) == References(
        **{k: v for k, v in json.loads(path.read_text()).items() if k not in ("format", "sha256")}
    )


def test_a_worker_builds_its_mpc_before_any_episode_so_no_solve_time_holds_the_build():
    from etmpc.evaluation import workers

    system, _, _ = workers.context("cart_pendulum/kicks")
    assert "mpc" in vars(system)  # the cached MPC (and its compiled code) is there before the first episode
