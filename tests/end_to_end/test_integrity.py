"""A trigger under test cannot change the run it is scored on.

A *vandal* decides exactly as ``every:3`` and, at every decision, writes into everything it is shown:
the state, the plan's prediction and arrays, its forecasts, the observation, the loop's context and,
when it simulates, the environment it is handed (it steps it and writes into its episode). On every
task its trajectory must be the one ``every:3`` plays, bit for bit (the record is the trajectory),
and not one of its writes may have landed. A trigger that writes without catching the error gets a
one-line error that names it, never a different score.
"""

from __future__ import annotations

import numpy as np
import pytest

import etmpc
from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.evaluation import testsets
from etmpc.loop import run_episode
from etmpc.policies.fixed import Every
from etmpc.policies.user import checked
from etmpc.systems import make_system, names


def _arrays(s):
    """Every array the vandal is shown, by name."""
    shown = {
        "x": s.x,
        "x_plan": s.x_plan,
        "x_predicted": s.x_predicted,
        "plan.inputs": s.plan.inputs,
        "plan.states": s.plan.states,
    }
    if s.plan.gains is not None:
        shown["plan.gains"] = s.plan.gains
    shown |= {f"plan.forecasts[{k}]": v for k, v in s.plan.forecasts.items()}
    shown |= {f"observation[{k}]": v for k, v in (s.observation or {}).items() if isinstance(v, np.ndarray)}
    if s.context is not None:
        shown["context.u_prev"] = s.context.u_prev
        episode = s.context.env.task.episode
        shown |= {f"episode.{k}": v for k, v in vars(episode).items() if isinstance(v, np.ndarray)}
    return shown


class Vandal:
    """every:3's rule; writes into everything it is shown, and counts the writes that landed."""

    spec = "vandal"
    stochastic = False

    def __init__(self, simulates: bool = False):
        self.simulates = simulates
        self.tried = self.landed = 0

    def _try(self, write) -> None:
        self.tried += 1
        try:
            write()
        except (ValueError, TypeError, AttributeError):
            return
        self.landed += 1

    def decide(self, s, rng) -> bool:
        for name, array in _arrays(s).items():
            self._try(lambda a=array: a.__setitem__(..., 1e3))
        for mapping in (s.plan.forecasts, s.observation):
            if mapping is not None:
                self._try(lambda m=mapping: m.__setitem__("state", np.zeros(3)))
                self._try(lambda m=mapping: m.clear())
        self._try(lambda: setattr(s, "age", 0))
        self._try(lambda: setattr(s.plan, "inputs", np.zeros(1)))
        if s.context is not None:  # the environment it is handed is a twin: stepping it changes nothing
            env = s.context.env
            spec = env.action_spec()
            action = np.full(spec.shape, 0.5 * (spec.minimum + spec.maximum) + 1.0, dtype=spec.dtype)
            for _ in range(min(3, s.context.system.episode_steps - s.context.step - 1)):
                env.step(action)
        return s.age >= 3


class NaiveVandal:
    """every:3's rule, writing into the state without catching what that raises."""

    spec = "naive-vandal"
    stochastic = False

    def decide(self, s, rng) -> bool:
        s.x[0] += 1.0
        return s.age >= 3


def _played(task: str, policy):
    system = make_system(task)
    stored = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    episode = system.episode_from_arrays(stored.episode_arrays(0))
    return run_episode(system, system.make_env(), policy, np.random.default_rng(0), episode)


FIELDS = ("states", "applied", "planned", "correction", "predicted", "plan_age", "recompute", "forced", "rewards")


@pytest.mark.parametrize("simulates", [False, True], ids=["shown", "simulating"])
@pytest.mark.parametrize("task", names())
def test_a_trigger_that_writes_into_everything_it_is_shown_plays_exactly_as_one_that_does_not(task, simulates):
    vandal = Vandal(simulates)
    wrecked, clean = _played(task, checked(vandal)), _played(task, Every(3))
    assert vandal.tried > 100 and vandal.landed == 0
    for name in FIELDS:
        assert np.array_equal(getattr(wrecked, name), getattr(clean, name), equal_nan=True), name
    assert wrecked.steps == clean.steps and wrecked.solver_failures == clean.solver_failures
    plans = [(i, p.inputs.tobytes(), p.states.tobytes()) for i, p in wrecked.plans]
    assert plans == [(i, p.inputs.tobytes(), p.states.tobytes()) for i, p in clean.plans]


def test_the_vandal_scores_as_every_3_in_evaluate_on_workers():
    result = etmpc.evaluate(
        "cart_pendulum/kicks", ["every:3", Vandal(simulates=True)], episodes=2, workers=2, progress=False
    ).to_json()
    runs = {
        p: [(r["objective"], r["recomputes"], r["solver_failures"]) for r in result["runs"] if r["policy"] == p]
        for p in ("every:3", "vandal")
    }
    assert runs["vandal"] == runs["every:3"]


def test_a_trigger_that_writes_without_catching_is_one_line_naming_it():
    with pytest.raises(EtmpcError, match=r"policy naive-vandal: decide raised ValueError: .*read-only.*np.array\(s.x\)"):
        etmpc.evaluate("battery", [NaiveVandal()], episodes=1, workers=1, progress=False)


def test_on_the_command_line_too(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.dont_write_bytecode", True)
    (tmp_path / "naive_vandal_module.py").write_text(
        "class Naive:\n    spec = 'naive'\n    stochastic = False\n"
        "    def decide(self, s, rng):\n        s.plan.inputs[0] = 0.0\n        return False\n"
    )
    code = main(
        [
            "evaluate",
            "--task",
            "reacher",
            "--policy",
            "py:naive_vandal_module:Naive",
            "--episodes",
            "1",
            "--workers",
            "1",
            "--json",
            "out.json",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "read-only" in err and "py:naive_vandal_module:Naive" in err
    assert not (tmp_path / "out.json").exists()


def test_what_a_stored_test_set_holds_cannot_be_written_through():
    stored = testsets.load(testsets.default_path("battery", "trading"), "battery", "trading")
    rows = {name: values for name, values in stored.episode_arrays(3).items() if isinstance(values, np.ndarray)}
    assert rows  # (a row of a one-dimensional array is a numpy scalar, which nothing can write into)
    for name, values in rows.items():
        with pytest.raises(ValueError, match="read-only"):
            values[...] = 0


class Impostor:
    """A trigger of someone's that calls itself by a built-in policy's name."""

    spec = "every:3"
    stochastic = False

    def decide(self, s, rng) -> bool:
        return True


def test_a_trigger_cannot_take_a_built_in_policys_name():
    with pytest.raises(EtmpcError, match="Impostor has the spec 'every:3', a built-in policy's"):
        etmpc.evaluate("battery", [Impostor()], episodes=1, workers=1, progress=False)
    Impostor.spec = "oracle:every:3"  # and so cannot be shown as the oracle
    with pytest.raises(EtmpcError, match="a built-in policy's"):
        etmpc.evaluate("battery", ["every:3", Impostor()], episodes=1, workers=1, progress=False)
    built_in = etmpc.evaluate("battery", [Every(3)], episodes=1, workers=1, progress=False)  # etmpc's own objects are
    assert built_in.summaries[0].policy == "every:3"  # what their specs say


class Unprintable(Exception):
    def __str__(self):
        raise RuntimeError("no")


class Loud:
    spec, stochastic = "loud", False

    def decide(self, s, rng):
        raise ValueError("x" * 100_000 + "\nsecond line")


class Mute:
    spec, stochastic = "mute", False

    def decide(self, s, rng):
        raise Unprintable()


def test_whatever_a_trigger_raises_is_one_line_of_bounded_length():
    for trigger, says in ((Loud(), "ValueError: xxx"), (Mute(), "Unprintable: (its message cannot be printed)")):
        with pytest.raises(EtmpcError) as raised:
            etmpc.evaluate("battery", [trigger], episodes=1, workers=1, progress=False)
        message = str(raised.value)
        assert says in message and "\n" not in message and len(message) < 500


def test_a_spec_with_a_line_break_is_still_one_line_on_the_command_line(capsys):
    assert main(["evaluate", "--task", "battery", "--policy", "every:\n3"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "every:" in err
