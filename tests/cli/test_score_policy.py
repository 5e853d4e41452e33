"""``etmpc score --policy SPEC`` as every other command takes a policy; the older positional form still works for one
release, saying in one line what to write instead, and gives the same card."""

from __future__ import annotations

import json

from etmpc.cli import main

SCORE = ["score", "--task", "battery", "--episodes", "1", "--workers", "1"]


def _card(tmp_path, name: str, argv: list[str], capsys) -> tuple[dict, str]:
    path = tmp_path / name
    assert main([*argv, "--json", str(path)]) == 0
    return json.loads(path.read_text()), capsys.readouterr().err


def test_score_takes_policy_options_and_the_older_positional_form_gives_the_same_card_with_one_line(tmp_path, capsys):
    new, quiet = _card(tmp_path, "new.json", [*SCORE, "--policy", "every:3", "--policy", "never"], capsys)
    old, warned = _card(tmp_path, "old.json", ["score", "every:3", "never", *SCORE[1:]], capsys)
    assert [r["policy"] for r in new["rows"]] == ["every:3", "never"]
    assert [(r["policy"], r["episode_objectives"]) for r in old["rows"]] == [
        (r["policy"], r["episode_objectives"]) for r in new["rows"]
    ]
    assert "deprecated" not in quiet
    lines = [line for line in warned.splitlines() if "deprecated" in line]
    assert lines == [
        "etmpc: warning: 'etmpc score every:3 never' is deprecated: say 'etmpc score --policy every:3 --policy never'"
    ]


def test_policies_given_both_ways_are_refused_in_one_line(capsys):
    assert main(["score", "every:3", "--policy", "never", "--task", "battery"]) == 2
    err = capsys.readouterr().err
    assert err == "etmpc: error: give the policies once, each as --policy SPEC\n"
