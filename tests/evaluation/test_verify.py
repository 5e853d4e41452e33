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
    assert "8 episodes replayed give the card's scores bit for bit" in capsys.readouterr().out


def test_one_edited_episode_kept_consistent_is_found_by_the_replay(card, tmp_path, capsys):
    """A careful forger raises one episode's score of threshold:0.02 and every number that follows from it."""
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
    assert verdict.mismatches == [
        f"{forged}: battery threshold:0.02 episode 2: score "
        f"{json.loads(forged.read_text())['rows'][1]['episode_scores'][2]!r} in the card, "
        f"{json.loads(card.read_text())['rows'][1]['episode_scores'][2]!r} replayed"
    ]
    assert main(["verify", str(forged), "--sample", "0", "--workers", "1"]) == 2
    out, err = capsys.readouterr()
    assert out.strip() == verdict.mismatches[0]
    assert err.strip() == f"etmpc: error: card {forged} does not verify: 1 mismatch(es), listed above"


def test_an_edited_number_that_does_not_follow_from_the_episodes_is_named(card, tmp_path):
    forged = _edited(card, tmp_path, lambda data: data["rows"][0].update(score=data["rows"][0]["score"] + 5))
    lines = verify(forged, size=1).mismatches
    assert len(lines) == 1 and "battery every:3: score" in lines[0] and "the mean of its episode scores" in lines[0]
    forged = _edited(card, tmp_path, lambda data: data["aggregates"][0].update(iqm=99.0))
    assert [line for line in verify(forged, size=1).mismatches if "aggregate iqm 99.0" in line]


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda d: d.update(suite_version=d["suite_version"] + 1), "suite version"),
        (lambda d: d["task_versions"].update(battery=0), "scored battery at version 0"),
        (lambda d: d["references"]["battery"].update(stored=None), "another test set"),
        (lambda d: d["references"]["battery"].update(test_set_sha256="0" * 64), "on test set 000000000000"),
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
        f"{forged}: battery every:3 episode 1: {original[1] + 1} failures in the card, {original[1]} replayed"
    ]
    forged = _edited(card, tmp_path, lambda data: data["rows"][0].update(failures_mean=data["rows"][0]["failures_mean"] + 1))
    (line,) = verify(forged, size=1).mismatches
    assert "battery every:3: failures" in line and "per episode in the card" in line

    def older(data):
        for row in data["rows"]:
            del row["failures_ci95"], row["episode_failures"]

    assert verify(_edited(card, tmp_path, older), size=1).verified
