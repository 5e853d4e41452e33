"""Every panel of a trajectory figure (etmpc figure trajectory) and of a Gymnasium chart names its quantity with its
unit, for every state, input and signal of every registered task (finding 10 of #75: labels without units)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from etmpc.common.wording import unit_label
from etmpc.systems import names, system_key
from etmpc.views.figures import axis_label, draw_trajectory

UNIT = re.compile(r"^[a-z].* \([^()]+\)$")  # words, then the unit in parentheses


def _quantities(task: str) -> tuple[object, list[str]]:
    system = system_key(task).make()
    signals = system.signals(system.draw_episode(np.random.default_rng(0)))
    return system, [*system.state_names, *system.input_names, *signals]


@pytest.mark.parametrize("task", names())
def test_every_state_input_and_signal_of_every_task_is_labelled_with_its_unit(task):
    _, quantities = _quantities(task)
    unlabelled = [name for name in quantities if not UNIT.match(axis_label(name))]
    assert not unlabelled, [axis_label(name) for name in unlabelled]


def test_a_unit_is_read_from_the_names_suffix():
    assert unit_label("roll_rate_rad_s") == "roll rate (rad/s)" and unit_label("vz_m_s") == "vz (m/s)"
    assert unit_label("shoulder_torque_nm") == "shoulder torque (N m)" and unit_label("thrust0_n") == "thrust0 (N)"
    assert unit_label("state_of_charge") == "state of charge"  # no unit suffix: its words, no made-up unit


def test_the_figure_etmpc_draws_shows_those_labels(cart_system):
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy

    traj = run_episode(cart_system, cart_system.make_env(), parse_policy("every:5", cart_system), np.random.default_rng(0))
    figure = draw_trajectory(cart_system, traj)
    labels = [ax.get_ylabel() for ax in figure.axes if ax.get_ylabel()]
    assert labels and all(UNIT.match(label) for label in labels), labels
    assert figure.axes[-1].get_xlabel() == "time (s)"
