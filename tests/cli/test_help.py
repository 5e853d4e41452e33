"""``--help`` agrees with the parser and the registries: every argument of every subcommand says what it is, a
required one is shown without brackets, every command that plays policies takes ``--policy``, ``--price``'s
default names every task's price, and the policy syntax covers every form the spec parser takes."""

from __future__ import annotations

import argparse
import re

import pytest

from etmpc.cli.options import build_parser
from etmpc.policies.specs import parse_policy, syntax
from etmpc.systems import names, system_class


def _subcommands(parser: argparse.ArgumentParser, prefix: str = "etmpc") -> dict[str, argparse.ArgumentParser]:
    """Every (sub)subcommand's parser by its command line: ``etmpc evaluate``, ``etmpc figure bars``, ..."""
    found = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found[f"{prefix} {name}"] = sub
                found |= _subcommands(sub, f"{prefix} {name}")
    return found


COMMANDS = {"etmpc": build_parser(), **_subcommands(build_parser())}


def _arguments(parser):
    return [
        a
        for a in parser._actions
        if a.help != argparse.SUPPRESS and not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
    ]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_argument_of_every_subcommand_says_what_it_is(command):
    parser = COMMANDS[command]
    parser.format_help()  # every help text expands (a lazy one included)
    silent = [a.option_strings[0] if a.option_strings else a.dest for a in _arguments(parser) if not (a.help or "").strip()]
    assert not silent, f"{command}: no help for {', '.join(silent)}"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_required_argument_is_shown_without_brackets(command):
    parser = COMMANDS[command]
    usage = " ".join(parser.format_usage().split())
    for action in _arguments(parser):
        if action.option_strings and (action.required or getattr(action, "shown_required", False)):
            flag = action.option_strings[0]
            assert f"[{flag}" not in usage and f" {flag} " in usage, f"{command}: {flag} shown as optional: {usage}"
    # --task is required wherever it is one task (the parser's own check, or the older form's: etmpc.cli.tasks)
    task = next((a for a in _arguments(parser) if "--task" in a.option_strings), None)
    if task is not None and task.default is None and not isinstance(task, argparse._AppendAction):
        assert "[--task" not in usage


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_that_plays_policies_takes_them_as_policy(command):
    parser = COMMANDS[command]
    takes = [a for a in _arguments(parser) if a.dest == "policy"]
    assert all(a.option_strings == ["--policy"] for a in takes), command


def test_the_price_default_names_every_tasks_own_price():
    shown = " ".join(COMMANDS["etmpc evaluate"].format_help().split())
    (text,) = re.findall(r"--price P (.*?) --test-set", shown)
    for task in names():
        price = system_class(task).Config().recompute_price
        assert re.search(rf"{re.escape(f'{price:g}')} on [^;]*\b{re.escape(task)}\b", text), (task, price, text)


# One spec of every form the parser takes (the task it is parsed on: one with what the form needs)
FORMS = [
    ("cart_pendulum/kicks", "always"),
    ("cart_pendulum/kicks", "every:3"),
    ("cart_pendulum/kicks_levels", "iterate:3"),
    ("cart_pendulum/kicks", "threshold:0.2"),
    ("cart_pendulum/kicks_levels", "threshold:0.2:iterate"),
    ("cart_pendulum/kicks_noisy", "threshold:0.2:reading"),
    ("cart_pendulum/kicks_levels", "threshold:0.2:iterate:reading"),
    ("quadrotor/waypoints", "shield:every:3"),
    ("cart_pendulum/kicks", "shield:4:every:3"),
    ("cart_pendulum/kicks", "shield:4:0.1:every:3"),
    ("cart_pendulum/kicks", "rollout:every:3"),
    ("cart_pendulum/kicks", "rollout:every:3:2"),
    ("cart_pendulum/kicks", "rollout:every:3:2:5"),
    ("cart_pendulum/kicks", "oracle:every:3"),
]


def _pattern(form: str) -> str:
    """A kind's syntax as a regex: [...] optional, an upper-case placeholder any text."""
    text = re.escape(form).replace(r"\[", "(?:").replace(r"\]", ")?")
    return re.sub(r"[A-Z]+", ".+", text)


@pytest.mark.parametrize("task, spec", FORMS, ids=[spec for _, spec in FORMS])
def test_the_policy_syntax_in_the_help_covers_every_form_the_parser_takes(task, spec):
    parse_policy(spec, system_class(task)(system_class(task).Config()))  # the parser takes it
    forms = [form.strip() for form in syntax().split(" | ")]
    assert any(re.fullmatch(_pattern(form), spec) for form in forms), (spec, forms)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_the_help_says_policy_where_the_glossary_does(command):
    """docs/glossary.md: a "trigger" is no word for a policy; the field's own names keep it (the event trigger, the
    self-trigger, event-triggered MPC)."""
    shown = " ".join(COMMANDS[command].format_help().split())
    assert not re.findall(r"(?<!self-)(?<!event )\btriggers?\b", shown), command
