"""``etmpc verify CARD``: a card made by ``etmpc score`` verifies; one with an edited episode does not, whether
the forger kept the card consistent (the replay finds it) or not (its own numbers give it away)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.verify import sample, verify


@pytest.fixture(scope="module")
def card(tmp_path_factory):
    folder = tmp_path_factory.mktemp("card")
    path = folder / "card.json"
    assert (
        main(
            ["score", "every:3", "threshold:0.02", "--task", "battery", "--episodes", "4", "--workers", "1", "--json", str(path)]
        )
        == 0
    )
    return path


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
            ("episodes", "episode scores for 5 episodes"),
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
