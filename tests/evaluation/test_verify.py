"""``etmpc verify CARD``: a card made by ``etmpc score`` verifies; one with an edited episode does not, whether
the forger kept the card consistent (the replay finds it) or not (its own numbers give it away). A card is
evidence, never an instruction: each field of another type is one line, the references a card scored with
options carries are rebuilt in full (a forged best schedule is found), and no code it names runs unless allowed."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.verify import sample, verify


@pytest.fixture(scope="module")
def card(tmp_path_factory):
    folder = tmp_path_factory.mktemp("card")
    path = folder / "card.json"
    assert main([*_scored(4), "--json", str(path)]) == 0
    return path


def _scored(episodes: int) -> list[str]:
    """The score command both cards come from: two policies on the battery's first ``episodes``, one process."""
    policies = ["--policy", "every:3", "--policy", "threshold:0.02"]
    return ["score", *policies, "--task", "battery", "--episodes", str(episodes), "--workers", "1"]


def _edited(card, tmp_path, edit):
    data = json.loads(card.read_text())
    edit(data)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(data))
    return path


def test_a_card_made_by_score_verifies_every_episode_replayed(card, capsys):
    verdict = verify(card, size=0)
    assert verdict.verified and verdict.rows == 2 and verdict.replayed == 8
    assert main(["verify", str(card), "--sample", "0", "--workers", "1"]) == 0
    assert "every number it states follows from its episodes, and 8 episodes replayed give the card's numbers bit for bit" in (
        capsys.readouterr().out
    )


def test_one_edited_episode_score_kept_consistent_is_found_by_its_objective_and_by_the_replay(card, tmp_path, capsys):
    """A careful forger raises one episode's score of threshold:0.02 and every number that follows from it: the
    objective the card carries for that episode gives it away, and so does the replay."""
    from etmpc.evaluation.scorecard import TaskScore, aggregate

    def better(data):
        row = data["rows"][1]
        row["episode_scores"][2] += 30.0
        s = np.asarray(row["episode_scores"])
        row["score"] = float(np.mean(s))
        row["score_ci95"] = float(1.96 * np.std(s, ddof=1) / np.sqrt(s.size))
        row["better_share"] = float(np.mean((s > 0) + 0.5 * (s == 0)))
        agg = aggregate([TaskScore.from_json(row)])
        data["aggregates"][1] = {k: list(v) if isinstance(v, tuple) else v for k, v in vars(agg).items()}

    forged = _edited(card, tmp_path, better)
    verdict = verify(forged, size=0)
    row, true_row = json.loads(forged.read_text())["rows"][1], json.loads(card.read_text())["rows"][1]
    assert verdict.mismatches == [
        f"{forged}: battery/trading threshold:0.02 episode 2: score {row['episode_scores'][2]!r} in the card, "
        f"{true_row['episode_scores'][2]!r} from its objective {row['episode_objectives'][2]!r}",
        f"{forged}: battery/trading threshold:0.02 episode 2: score {row['episode_scores'][2]!r} in the card, "
        f"{true_row['episode_scores'][2]!r} replayed",
    ]
    assert main(["verify", str(forged), "--sample", "0", "--workers", "1"]) == 2
    out, err = capsys.readouterr()
    assert out.strip().splitlines() == verdict.mismatches
    assert err.strip() == f"etmpc: error: card {forged} does not verify: 2 mismatch(es), listed above"


def test_an_edited_number_that_does_not_follow_from_the_episodes_is_named(card, tmp_path):
    forged = _edited(card, tmp_path, lambda data: data["rows"][0].update(score=data["rows"][0]["score"] + 5))
    lines = verify(forged, size=1).mismatches
    assert len(lines) == 1 and "battery/trading every:3: score" in lines[0] and "the mean of its episode scores" in lines[0]
    forged = _edited(card, tmp_path, lambda data: data["aggregates"][0].update(iqm=99.0))
    assert [line for line in verify(forged, size=1).mismatches if "aggregate iqm 99.0" in line]


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda d: d.update(suite_version=d["suite_version"] + 1), "suite version"),
        (lambda d: d["task_versions"].update({"battery/trading": 0}), "scored battery/trading at version 0"),
        (lambda d: d["references"]["battery/trading"].update(stored=None), "another test set"),
        (lambda d: d["references"]["battery/trading"].update(test_set_sha256="0" * 64), "on test set 000000000000"),
        (lambda d: d["rows"][0].update(policy="evry:3"), "cannot replay evry:3 on battery"),
        (lambda d: d.update(format="something"), "is not an etmpc scorecard"),
    ],
)
def test_a_card_that_is_not_this_suites_result_is_one_line(card, tmp_path, edit, says, capsys):
    forged = _edited(card, tmp_path, edit)
    with pytest.raises(EtmpcError, match=says):
        verify(forged, size=1)
    assert main(["verify", str(forged)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err


def test_the_sample_is_seeded_and_within_the_episodes():
    assert sample(100, 5, 0, 3) == sample(100, 5, 0, 3) != sample(100, 5, 1, 3)
    assert sample(100, 5, 0, 3) != sample(100, 5, 0, 4)
    assert len(set(sample(100, 5, 0, 0))) == 5 and all(0 <= e < 100 for e in sample(100, 5, 0, 0))
    assert sample(4, 5, 0, 0) == sample(4, 0, 0, 0) == [0, 1, 2, 3]


def test_the_failure_counts_are_checked_too_and_a_card_without_them_still_verifies(card, tmp_path):
    """A forger who edits one episode's failure count, its mean and CI with it, is found by the replay; one who
    edits the mean alone by the card's own counts. A card of an older etmpc (no CI, no counts) verifies."""
    from etmpc.evaluation import metrics

    def fewer(data):
        row = data["rows"][0]
        row["episode_failures"][1] += 1
        row["failures_mean"] = float(np.mean(row["episode_failures"]))
        row["failures_ci95"] = metrics.mean_ci95(row["episode_failures"])

    original = json.loads(card.read_text())["rows"][0]["episode_failures"]
    forged = _edited(card, tmp_path, fewer)
    assert verify(forged, size=0).mismatches == [
        f"{forged}: battery/trading every:3 episode 1: failures {original[1] + 1} in the card, {original[1]} replayed"
    ]
    forged = _edited(card, tmp_path, lambda data: data["rows"][0].update(failures_mean=data["rows"][0]["failures_mean"] + 1))
    (line,) = verify(forged, size=1).mismatches
    assert "battery/trading every:3: failures" in line and "per episode in the card" in line

    def older(data):
        for row in data["rows"]:
            del row["failures_ci95"], row["episode_failures"]

    assert verify(_edited(card, tmp_path, older), size=1).verified


def _bump(value):
    return value + 1 if isinstance(value, int) else value * 1.01 + 0.01


def _row_edit(field, index=None, key=None):
    def edit(data):
        row = data["rows"][0]
        if index is not None:
            row[field][index] = _bump(row[field][index])
        elif key is not None:
            row[field][key] = _bump(row[field][key])
        else:
            row[field] = _bump(row[field])

    return edit


def _aggregate_edit(field, index=None):
    def edit(data):
        aggregate = data["aggregates"][0]
        if index is None:
            aggregate[field] = _bump(aggregate[field])
        else:
            aggregate[field][index] = _bump(aggregate[field][index])

    return edit


# Every number a card states, each changed alone, and the words of the line that names it.
EVERY_NUMBER = [
    *[
        (_row_edit(field), says)
        for field, says in [
            ("objective_mean", "battery/trading every:3: objective"),
            ("recomputes_mean", "battery/trading every:3: recomputes"),
            ("failures_mean", "battery/trading every:3: failures"),
            ("solver_failures", "battery/trading every:3: 1 solver failures in the card, 0 from its episodes"),
            ("nonfinite_episodes", "battery/trading every:3: non-finite episodes 1 in the row"),
            ("score", "battery/trading every:3: score"),
            ("score_ci95", "battery/trading every:3: 95 % CI"),
            ("better_share", "battery/trading every:3: better in"),
            ("failures_ci95", "battery/trading every:3: failures' 95 % CI"),
            ("task_version", "battery/trading every:3: task version 2 in the row, 1 in the card's task versions"),
        ]
    ],
    *[
        (_row_edit(field, index=1), says)
        for field, says in [
            ("episode_scores", "battery/trading every:3 episode 1: score"),
            ("episode_failures", "battery/trading every:3: failures"),
            ("episode_objectives", "battery/trading every:3 episode 1: score"),
            ("episode_recomputes", "battery/trading every:3: recomputes"),
            ("episode_solver_failures", "battery/trading every:3: 0 solver failures in the card, 1 from its episodes"),
        ]
    ],
    *[(_row_edit("cpu_ms", key=key), "battery/trading every:3: CPU total") for key in ("solve", "feedback", "decide", "total")],
    (lambda d: d["rows"][0].update(objective_sense="min"), "battery/trading every:3: objective sense 'min' in the row, 'max'"),
    (lambda d: d["rows"][0].update(reference="every:2"), "battery/trading every:3: scored against every:2"),
    *[
        (_aggregate_edit(field, index), f"every:3: aggregate {field}")
        for field, index in [
            ("tasks", None),
            ("iqm", None),
            ("iqm_ci95", 0),
            ("iqm_ci95", 1),
            ("probability_of_improvement", None),
            ("probability_of_improvement_ci95", 0),
            ("probability_of_improvement_ci95", 1),
        ]
    ],
    (lambda d: d["aggregates"][0].update(policy="every:4"), "every:4: an aggregate in the card, but no rows of it"),
    *[
        (
            lambda d, key=key: d["references"]["battery/trading"].update({key: _bump(d["references"]["battery/trading"][key])}),
            says,
        )
        for key, says in [
            ("gap", "battery/trading: references' gap"),
            ("recompute_price", "battery/trading: references' recompute_price"),
        ]
    ],
    (
        lambda d: d["references"]["battery/trading"].update(best_periodic="every:2"),
        "battery/trading: references' best_periodic 'every:2'",
    ),
    (
        lambda d: d["references"]["battery/trading"].update(oracle="oracle:every:2"),
        "battery/trading: references' oracle 'oracle:every:2'",
    ),
]


@pytest.mark.parametrize("edit, says", EVERY_NUMBER)
def test_every_number_a_card_states_changed_alone_is_named(card, tmp_path, edit, says):
    """Not only the scores: the objective, the computations, the failures, the CPU time's total, the
    aggregates and the references a card states each follow from what it carries, or a line says which."""
    forged = _edited(card, tmp_path, edit)
    lines = verify(forged, size=1).mismatches
    assert any(says in line for line in lines), lines


def test_a_replayed_episode_must_give_the_cards_objective_computations_and_solver_failures_bit_for_bit(card, tmp_path):
    """A forger who changes one episode's objective and every number that follows from it (its score, the
    row's means, the aggregates) is found by the replay, which names the objective."""
    from etmpc.evaluation.card import TaskScore, aggregate
    from etmpc.evaluation.references import stored
    from etmpc.evaluation import metrics

    refs = stored("battery", 4)
    original = json.loads(card.read_text())["rows"][0]["episode_objectives"][2]

    def better(data):
        row = data["rows"][0]
        row["episode_objectives"][2] = original + 0.01
        objectives = np.asarray(row["episode_objectives"])
        best = refs.costs(refs.periodic[refs.best])
        row["episode_scores"] = [float(v) for v in metrics.normalized_scores(refs.costs(objectives), best, refs.gap)]
        s = np.asarray(row["episode_scores"])
        row["objective_mean"], row["score"] = float(np.mean(objectives)), float(np.mean(s))
        row["score_ci95"], row["better_share"] = metrics.mean_ci95(s), metrics.improvement_share(s)
        data["aggregates"][0] = {
            k: list(v) if isinstance(v, tuple) else v for k, v in vars(aggregate([TaskScore.from_json(row)])).items()
        }

    forged = _edited(card, tmp_path, better)
    lines = verify(forged, size=0).mismatches
    assert [line for line in lines if "episode 2: objective" in line] == [
        f"{forged}: battery/trading every:3 episode 2: objective {original + 0.01!r} in the card, {original!r} replayed"
    ]
    assert all("episode 2" in line for line in lines), lines  # nothing else disagrees: only the replay finds it


def test_a_row_of_another_type_or_a_card_without_what_verification_needs_is_one_line(card, tmp_path, capsys):
    for edit, says in [
        (lambda d: d["rows"][0].update(score="1"), "score must be a number, got '1'"),
        (lambda d: d["rows"][0].update(episode_scores="abc"), "episode_scores must be a list of a number"),
        (lambda d: d["rows"][0].update(cpu_ms=[1]), "holds a row that is not a row"),
        (lambda d: d["rows"].append(d["rows"][0]), "holds two rows of every:3 on battery"),
    ]:
        forged = _edited(card, tmp_path, edit)
        assert main(["verify", str(forged), "--workers", "1"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err and "Traceback" not in err, err

    def older(data):
        del data["rows"][0]["episode_objectives"]

    lines = verify(_edited(card, tmp_path, older), size=1).mismatches
    assert lines == [
        f"{tmp_path / 'edited.json'}: battery/trading every:3: no episode_objectives (a row of an older etmpc): "
        "score the policy again to verify its numbers"
    ]


def test_a_card_records_its_machines_libm_and_verify_says_when_this_ones_rounds_otherwise(card, tmp_path, monkeypatch, capsys):
    """A CPU without FMA makes glibc round sin and cos otherwise (about one argument in 1,500): a replay on such a
    machine may differ with nothing wrong in the card, and verify says so beside its verdict."""
    import etmpc.evaluation.verify as verify_module
    from etmpc.common.provenance import libm_rounding

    assert json.loads(card.read_text())["machine"]["libm"] == libm_rounding()
    assert verify(card, size=1).caution is None  # made here, verified here
    monkeypatch.setattr(verify_module, "libm_rounding", lambda: "sse2" if libm_rounding() == "fma" else "fma")
    verdict = verify(card, size=1)
    assert verdict.verified and "this machine's C library rounds sin, cos, exp and log as glibc's" in verdict.caution
    assert main(["verify", str(card), "--workers", "1"]) == 0
    assert capsys.readouterr().out.startswith("note: this machine's C library rounds")


def test_libm_rounding_tells_glibcs_variants_apart_in_a_process_of_each():
    """The probe is libm's own answer: a process told to use glibc's SSE2 variants (as a CPU without FMA would)
    answers sse2; this one answers what its CPU makes glibc pick."""
    import os
    import subprocess
    import sys

    from etmpc.common.provenance import libm_rounding

    mine = libm_rounding()
    if mine == "other":
        pytest.skip("not glibc on x86-64")
    code = "from etmpc.common.provenance import libm_rounding; print(libm_rounding())"
    env = dict(os.environ, GLIBC_TUNABLES="glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-AVX")
    forced = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert forced == "sse2"


# -- a card is evidence: every field of its type, its references rebuilt, no code it alone names run -----------
OPTION = "lqr_input_weight=0.2"  # an option of the battery: its references are computed for the run, carried in the card
OPTIONS_TASK = "battery/trading"
EPISODES = 2  # of the card scored with the option: its references are rebuilt in full (20 schedules and the oracle)


@pytest.fixture(scope="module")
def options_card(tmp_path_factory):
    """A card scored with an option (its references computed for the run and carried), with the references
    ``score`` built, captured as it built them (every periodic schedule's objectives: what a forger has too)."""
    import etmpc.evaluation.scorecard as scorecard

    path = tmp_path_factory.mktemp("options") / "card.json"
    built = []
    real = scorecard.build_references
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scorecard, "build_references", lambda *a, **k: built.append(real(*a, **k)) or built[-1])
        assert main([*_scored(EPISODES), "--option", OPTION, "--json", str(path)]) == 0
    return path, built[0]


def _rebuilt_as_scored(monkeypatch, refs, calls=None):
    """``carried.rebuild`` answering with the references ``score`` built (what a real rebuild gives, bit for bit,
    as the forgery test shows): the comparisons tested without playing the schedules again."""
    import etmpc.evaluation.carried as carried

    def rebuild(key, episodes, workers, progress, say=lambda line: None):
        if calls is not None:
            calls.append((key, episodes))
        return refs

    monkeypatch.setattr(carried, "rebuild", rebuild)


def test_a_card_scored_with_options_verifies_with_its_references_rebuilt_in_full(options_card, capsys):
    """verify plays every periodic schedule and the oracle again under the card's options, on its episodes, and
    says so: the rebuilt references are the ones score built, bit for bit."""
    path, scored = options_card
    said = []
    verdict = verify(path, size=0, workers=1, say=said.append)
    assert verdict.verified, verdict.mismatches
    assert verdict.rebuilt == (OPTIONS_TASK,) and verdict.replayed == 2 * EPISODES
    assert said[0] == (
        f"{OPTIONS_TASK}: rebuilding the references the card scored it against ({OPTION}) on its {EPISODES} episodes: "
        "every periodic schedule and the oracle, as scoring did"
    )
    assert "20 periodic schedules, then the oracle over the best" in said[1]


def test_the_command_says_it_rebuilds_the_references_and_the_rebuild_is_scores(options_card, monkeypatch, capsys):
    from etmpc.systems import system_key

    path, scored = options_card
    calls = []
    _rebuilt_as_scored(monkeypatch, scored, calls)
    assert main(["verify", str(path), "--sample", "1", "--workers", "1"]) == 0
    out, err = capsys.readouterr()
    assert calls == [(system_key("battery", None, {"lqr_input_weight": "0.2"}), EPISODES)]
    assert f"{OPTIONS_TASK}: rebuilding the references the card scored it against" in err
    assert f"the references of {OPTIONS_TASK} (scored with options) rebuilt in full" in out


def test_a_forged_card_naming_the_worst_schedule_as_best_with_its_true_objectives_does_not_verify(options_card, tmp_path):
    """The forger's card: the worst periodic schedule named as the best, with its true objectives and those of
    the oracle over it (each replays), every row scored against it and every number recomputed from that, so
    that the card holds together. The scores rise; the rebuilt references name the true best, and say so."""
    from dataclasses import replace

    from etmpc.common.outputs import strict
    from etmpc.evaluation import metrics
    from etmpc.evaluation.card import TaskScore, aggregate
    from etmpc.evaluation.evaluate import evaluate
    from etmpc.systems import system_key

    path, true = options_card
    worst = max(true.periodic, key=lambda spec: float(np.mean(true.costs(true.periodic[spec]))))
    key = system_key("battery", None, {"lqr_input_weight": "0.2"})
    runs = evaluate(key, [f"oracle:{worst}"], EPISODES, workers=1, progress=False).runs
    forged = replace(true, best=worst, oracle=[r.objective for r in sorted(runs, key=lambda r: r.episode)])
    assert worst != true.best and forged.gap > 0

    def forge(data):
        ref = data["references"][OPTIONS_TASK]
        ref |= {"best_periodic": worst, "oracle": forged.oracle_spec, "gap": forged.gap}
        ref |= {"best_objectives": list(forged.periodic[worst]), "oracle_objectives": list(forged.oracle)}
        best = forged.costs(forged.periodic[worst])
        for row in data["rows"]:
            s = metrics.normalized_scores(forged.costs(row["episode_objectives"]), best, forged.gap)
            row |= {"reference": worst, "episode_scores": [float(v) for v in s], "score": float(np.mean(s))}
            row |= {"score_ci95": metrics.mean_ci95(s), "better_share": metrics.improvement_share(s)}
        data["aggregates"] = [strict(aggregate([TaskScore.from_json(row)]).to_json()) for row in data["rows"]]

    card = _edited(path, tmp_path, forge)
    rows, true_rows = json.loads(card.read_text())["rows"], json.loads(path.read_text())["rows"]
    assert all(r["score"] > t["score"] + 50 for r, t in zip(rows, true_rows))  # what the forgery buys
    verdict = verify(card, size=0, workers=1)
    assert not verdict.verified
    lines = verdict.mismatches
    assert f"{card}: {OPTIONS_TASK}: references' best_periodic {worst!r} in the card, rebuilt {true.best!r}" in lines
    assert f"{card}: {OPTIONS_TASK} every:3: scored against {worst}, the references' best schedule is {true.best}" in lines
    assert f"{card}: {OPTIONS_TASK}: references' gap {forged.gap!r} in the card, rebuilt {true.gap!r}" in lines
    # the card holds together: what differs is what the rebuilt references give (they, the rows' best schedule, and
    # the replayed episodes' scores against them), nothing the card's own numbers give
    assert all(" references' " in line or "scored against" in line or "replayed" in line for line in lines), lines
    assert not [line for line in lines if "from its" in line or "mean of" in line or "aggregate" in line]


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda r: r["best_objectives"].__setitem__(1, r["best_objectives"][1] + 1e-9), "(best_objectives) episode 1: objective"),
        (
            lambda r: r["oracle_objectives"].__setitem__(0, r["oracle_objectives"][0] * 2),
            "(oracle_objectives) episode 0: objective",
        ),
        (lambda r: r.update(recompute_price=1e-4), "references' recompute_price 0.0001 in the card, rebuilt 0.0"),
        (lambda r: r.update(objective_sense="min"), "references' objective_sense 'min' in the card, 'max' rebuilt"),
        (lambda r: r.update(gap=r["gap"] * 2), "references' gap"),
        (lambda r: r.update(oracle="oracle:every:2"), "references' oracle 'oracle:every:2' in the card"),
        (
            lambda r: r.update(options={"lqr_input_weight": "0.20"}),
            "references' options {'lqr_input_weight': '0.20'} in the card",
        ),
    ],
)
def test_every_number_a_card_carries_of_its_references_is_compared_with_the_rebuilt_ones(
    options_card, tmp_path, monkeypatch, edit, says
):
    path, scored = options_card
    _rebuilt_as_scored(monkeypatch, scored)
    forged = _edited(path, tmp_path, lambda data: edit(data["references"][OPTIONS_TASK]))
    lines = verify(forged, size=1, workers=1).mismatches
    assert any(says in line for line in lines), lines


def _set(where, value):
    """An edit of the card: the field at ``where`` (keys and indices) set to ``value``."""

    def edit(data):
        for step in where[:-1]:
            data = data[step]
        data[where[-1]] = value

    return edit


def _twice(data):
    """The card's task named twice, the second time by its short name (its rows would count twice)."""
    data["tasks"].append("battery")
    data["task_versions"]["battery"] = data["task_versions"]["battery/trading"]
    data["references"]["battery"] = data["references"]["battery/trading"]


# Fields of another type or shape, each one line naming the file and the field, before anything is played.
MALFORMED = [
    (_set(["machine"], ["x86_64"]), "machine must be an object, got ['x86_64']"),
    (_set(["machine"], "x86_64"), "machine must be an object, got 'x86_64'"),
    (_set(["machine", "libm"], ["fma"]), "machine.libm must be one of fma, sse2, other, got ['fma']"),
    (_set(["machine", "libm"], "avx512"), "machine.libm must be one of fma, sse2, other, got 'avx512'"),
    (
        _set(["rows", 0, "episode_objectives"], []),
        "rows[0] (every:3 on battery/trading): episode_objectives holds 0 values for its 4",
    ),
    (_set(["rows", 0, "episode_recomputes"], [34]), "episode_recomputes holds 1 values for its 4 episodes"),
    (_set(["rows", 0, "episode_solver_failures"], [0] * 5), "episode_solver_failures holds 5 values for its 4 episodes"),
    (_set(["rows", 1, "episode_failures"], []), "rows[1] (threshold:0.02 on battery/trading): episode_failures holds 0"),
    (_set(["rows", 0, "episodes"], 5), "episode_scores holds 4 values for its 5 episodes"),
    (_set(["rows", 0, "episode_recomputes", 0], 10**400), "rows[0].episode_recomputes[0] is a whole number beyond a double's"),
    (_set(["rows"], {}), "rows must be a non-empty list of rows (objects), got {}"),
    (_set(["rows"], []), "rows must be a non-empty list of rows"),
    (_set(["tasks"], "battery/trading"), "tasks must be a non-empty list of task names"),
    (_set(["tasks"], [["battery/trading"]]), "tasks must be a non-empty list of task names"),
    (_set(["task_versions"], {"battery/trading": "1"}), "task_versions.battery/trading must be a whole number, got '1'"),
    (_set(["task_versions"], []), "task_versions must be an object of a version per task"),
    (_set(["references", "battery/trading"], []), "references.battery/trading must be an object, got []"),
    (_set(["references", "battery/trading", "episodes"], "4"), "references.battery/trading.episodes must be a count"),
    (_set(["references", "battery/trading", "gap"], [1]), "references.battery/trading.gap must be a finite number"),
    (_set(["references", "battery/trading", "episodes"], 1000), "references.battery/trading: --episodes must be in 1..100"),
    (_set(["aggregates"], 3), "aggregates must be a list of objects, got 3"),
    (_set(["aggregates", 0, "policy"], ["every:3"]), "aggregates[0].policy must be a policy's spec (text)"),
    (_set(["aggregates", 0, "iqm_ci95"], "wide"), "aggregates[0].iqm_ci95 must be a pair of finite numbers or nulls"),
    (_set(["aggregates", 0, "tasks"], True), "aggregates[0].tasks must be a count of tasks"),
    (_set(["software"], ["etmpc"]), "software must be an object of versions (text)"),
    (_twice, "tasks: task battery/trading is given twice"),
]


@pytest.mark.parametrize("edit, says", MALFORMED)
def test_a_field_of_another_type_or_shape_is_one_line_naming_it(card, tmp_path, capsys, edit, says):
    forged = _edited(card, tmp_path, edit)
    assert main(["verify", str(forged), "--workers", "1"]) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and says in err and "Traceback" not in err and f"card {forged}: " in err, err
    assert out == ""


def test_a_row_of_another_episode_count_than_its_references_is_a_mismatch(card, tmp_path):
    def fewer(data):
        row = data["rows"][0]
        for name in ("episode_scores", "episode_objectives", "episode_recomputes", "episode_solver_failures", "episode_failures"):
            row[name] = row[name][:3]
        row["episodes"] = 3

    forged = _edited(card, tmp_path, fewer)
    assert f"{forged}: battery/trading every:3: 3 episode scores for 3 episodes; the references have 4" in (
        verify(forged, size=1).mismatches
    )


CARRIED_MALFORMED = [
    (_set(["best_objectives"], []), f"references.battery/trading.best_objectives must be a list of {EPISODES} finite numbers"),
    (
        _set(["oracle_objectives"], ["1.0"] * EPISODES),
        f"references.battery/trading.oracle_objectives must be a list of {EPISODES}",
    ),
    (_set(["options"], {"lqr_input_weight": 0.2}), "references.battery/trading.options must be a non-empty object"),
    (_set(["options"], {}), "references.battery/trading.options must be a non-empty object"),
    (_set(["options"], {"no_such_option": "1"}), "references.battery/trading.options: "),
    (_set(["recompute_price"], "0"), "references.battery/trading.recompute_price must be a finite number, got '0'"),
    (_set(["objective_sense"], "up"), "references.battery/trading.objective_sense must be min or max, got 'up'"),
    (_set(["best_periodic"], None), "references.battery/trading.best_periodic must be a schedule's spec"),
    (_set(["episodes"], float(EPISODES)), "references.battery/trading.episodes must be a count of episodes"),
    (_set(["stored"], "battery/trading/references.json"), "names stored references and options"),
    (_set(["test_set_sha256"], "0" * 64), "scored battery/trading on another test set than the stored one"),
    (
        lambda ref: ref.update(episodes=1000, best_objectives=[1.0] * 1000, oracle_objectives=[1.0] * 1000),
        "scored battery/trading on 1000 episodes; its test set has 100",
    ),
]


@pytest.mark.parametrize("edit, says", CARRIED_MALFORMED)
def test_references_carried_of_another_type_are_one_line_before_any_rebuild(
    options_card, tmp_path, monkeypatch, capsys, edit, says
):
    import etmpc.evaluation.carried as carried

    monkeypatch.setattr(carried, "rebuild", lambda *a, **k: pytest.fail("rebuilt a malformed card's references"))
    forged = _edited(options_card[0], tmp_path, lambda data: edit(data["references"][OPTIONS_TASK]))
    assert main(["verify", str(forged), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err and "Traceback" not in err, err


# -- code a card names -------------------------------------------------------------------------------------
PROBE = "verify_code_probe"  # a module of a py: policy that leaves a file behind when imported


@pytest.fixture
def code_card(card, tmp_path, monkeypatch):
    """The card with its every:3 row named ``py:PROBE:T`` (a factory of every:3: the row replays as it is), the
    module importable, and the file its import writes."""
    marker = tmp_path / "imported"
    (tmp_path / "probe").mkdir()
    (tmp_path / "probe" / f"{PROBE}.py").write_text(
        f"import pathlib\npathlib.Path({str(marker)!r}).write_text('imported')\n"
        "from etmpc.policies.fixed import Every\n\n\ndef T():\n    return Every(3)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "probe"))
    monkeypatch.delitem(sys.modules, PROBE, raising=False)
    yield (lambda spec: _edited(card, tmp_path, lambda data: _renamed(data, "every:3", spec))), marker
    sys.modules.pop(PROBE, None)


def _renamed(data, old, new):
    for entry in (*data["rows"], *data["aggregates"]):
        if entry["policy"] == old:
            entry["policy"] = new


def test_a_row_that_runs_code_is_refused_before_anything_unless_its_exact_spec_is_allowed(code_card, capsys):
    edited, marker = code_card
    spec = f"py:{PROBE}:T"
    path = edited(spec)
    with pytest.raises(EtmpcError, match=rf"{spec} on battery/trading runs code .* --allow-code {spec}$"):
        verify(path, size=1, workers=1)
    assert main(["verify", str(path), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--allow-code {spec}" in err
    assert not marker.exists() and PROBE not in sys.modules  # never imported
    with pytest.raises(EtmpcError, match="runs code"):
        verify(path, size=1, workers=1, allow_code=[f"py:{PROBE}:X"])  # another spec allowed: not this one
    assert not marker.exists()
    verdict = verify(path, size=1, workers=1, allow_code=[spec])
    assert verdict.verified and marker.exists()  # allowed: imported, replayed, and it verifies
    assert main(["verify", str(path), "--workers", "1", "--allow-code", "every:2", "--allow-code", spec]) == 0


@pytest.mark.parametrize("outer", ["shield:4:{}", "shield:{}", "rollout:{}", "rollout:{}:2:5"])
def test_a_spec_that_holds_a_py_spec_runs_code_too(code_card, outer):
    from etmpc.evaluation.verify import runs_code

    edited, marker = code_card
    spec = outer.format(f"py:{PROBE}:T")
    assert runs_code(spec)
    with pytest.raises(EtmpcError, match="runs code"):
        verify(edited(spec), size=1, workers=1, allow_code=[f"py:{PROBE}:T"])  # the inner spec allowed: not this one
    assert not marker.exists()


def test_only_a_py_stretch_runs_code():
    from etmpc.evaluation.verify import runs_code

    assert not any(
        runs_code(spec) for spec in ("every:3", "threshold:0.02", "rl:policy.json", "shield:4:every:3", "oracle:every:2")
    )
    assert runs_code("py:m:T") and runs_code("rollout:shield:3:py:m:T:4")


def test_allow_code_must_be_a_list_of_specs(card):
    with pytest.raises(EtmpcError, match="allow_code: a list of policy specs"):
        verify(card, allow_code=f"py:{PROBE}:T")
