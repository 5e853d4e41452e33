"""Options are data: every option of every task declares what it may be, a value outside that is refused in one
line naming the option before anything is built, and no option can name a library to load."""

from __future__ import annotations

import dataclasses
import math
import re
import shutil
import subprocess
import sys
import textwrap
from dataclasses import dataclass

import numpy as np
import pytest

from etmpc.common.checks import BadType, BadValue
from etmpc.common.declared import PER_STATE, Checked, declarations, element_of, setting
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.control.settings import QP_SOLVERS, SolverSettings
from etmpc.control.sensing import Sensor
from etmpc.control.timing import Latency
from etmpc.systems import names, system_class, system_key
from etmpc.systems.options import canonical, described, settable

TASKS = names()


def _options():
    """``(task, option, declaration, type)`` for each option once (the first task that has it)."""
    seen = {}
    for task in TASKS:
        for name, (declared, kind) in described(system_class(task).Config()).items():
            seen.setdefault(name, (task, name, declared, kind))
    return list(seen.values())


OPTIONS = _options()


def test_every_option_of_every_task_is_declared_and_its_default_is_what_it_may_be():
    for task in TASKS:
        config = system_class(task).Config()
        values, declared = settable(config), described(config)
        assert values and list(values) == list(declared), task
        for name, (what, kind) in declared.items():
            assert what.why and not what.why.endswith("."), (task, name)
            assert what.check(name, kind, values[name]) == values[name]  # the default may be what it is
            assert what.describe(kind)  # and says so in words


def _outside(declared, kind) -> list[str]:
    """Values (as an option's text) just outside what ``declared`` allows."""
    element = element_of(kind)
    scalar = element or kind
    if scalar is bool:
        bad = ["maybe"]
    elif declared.choices or declared.label:
        bad = ["bogus value" if declared.choices else "x" * 81]
    else:
        below = (
            declared.low - (1 if scalar is int else 1e-9 * max(1.0, abs(declared.low)))
            if declared.low is not None
            else declared.above
        )
        above = (
            declared.high + (1 if scalar is int else 1e-9 * max(1.0, abs(declared.high)))
            if declared.high is not None
            else declared.below
        )
        bad = [repr(below), repr(above)]
    if element is None:
        return bad
    count = 2 if declared.lengths is None or PER_STATE in declared.lengths else declared.lengths[0]
    return [",".join([value] * count) for value in bad]


@pytest.mark.parametrize("task, name, declared, kind", OPTIONS, ids=[o[1] for o in OPTIONS])
def test_a_value_just_outside_an_options_range_is_refused_naming_the_option(task, name, declared, kind):
    for text in _outside(declared, kind):
        with pytest.raises((BadValue, BadType), match=rf"^option {re.escape(name)}: "):
            system_key(task, None, {name: text})


@pytest.mark.parametrize("task, name, declared, kind", OPTIONS, ids=[o[1] for o in OPTIONS])
def test_a_value_at_an_options_bounds_is_what_it_may_be(task, name, declared, kind):
    """The bounds are inclusive where declared so (``low``, ``high``), exclusive where not (``above``, ``below``)."""
    element = element_of(kind)
    scalar = element or kind
    if scalar is bool or declared.choices or declared.label:
        return
    count = 1 if element is None else 2 if declared.lengths is None or PER_STATE in declared.lengths else declared.lengths[0]
    shaped = (lambda v: v) if element is None else (lambda v: (v,) * count)
    for bound in (declared.low, declared.high):
        if bound is not None:
            declared.check(name, kind, shaped(scalar(bound)))
    for bound in (declared.above, declared.below):
        if bound is not None:
            with pytest.raises(BadValue):
                declared.check(name, kind, shaped(scalar(bound)))


def test_every_number_an_option_may_be_is_finite_so_no_option_asks_for_unbounded_work():
    for _, name, declared, kind in OPTIONS:
        bounds = [b for b in (declared.low, declared.high, declared.above, declared.below) if b is not None]
        assert all(math.isfinite(b) for b in bounds), name


def test_a_setting_without_both_bounds_or_a_word_without_its_choices_is_refused_where_it_is_declared():
    @dataclass(frozen=True)
    class Half(Checked):
        gain: float = setting(1.0, low=0, why="a gain")

    @dataclass(frozen=True)
    class Free(Checked):
        solver: str = setting("qrqp", why="a solver")

    for cls in (Half, Free):
        with pytest.raises(TypeError, match="needs"):
            declarations(cls)


def test_a_field_that_is_not_declared_is_no_option():
    config = system_class("battery/trading").Config()
    assert config.market.price.unit == "EUR/kWh" and "market.price.unit" not in settable(config)
    with pytest.raises(UnknownNameError, match="'market.price.unit' is not an option"):
        system_key("battery/trading", None, {"market.price.unit": "x"})


@pytest.mark.parametrize(
    "make, error, says",
    [
        (lambda: SolverSettings(qpsol="evil"), BadValue, "SolverSettings.qpsol: 'evil' is not one of qrqp"),
        (lambda: SolverSettings(block=0), BadValue, "SolverSettings.block: 0 is not a whole number in 1..100"),
        (lambda: Latency(compensate="no"), BadType, "Latency.compensate: 'no' is not true or false"),
        (lambda: Latency(intervals=1.0), BadType, "Latency.intervals: 1.0 is not a whole number"),
        (lambda: Sensor(dropout=1.0), BadValue, r"Sensor.dropout: 1.0 is not a number in \[0, 1\)"),
        (lambda: Sensor(noise_std=[0.1, -1]), BadValue, "Sensor.noise_std: "),
    ],
)
def test_settings_made_in_python_are_checked_when_they_are_made(make, error, says):
    with pytest.raises(error, match=says):
        make()


def test_a_value_that_fits_alone_but_not_with_the_plant_or_the_horizon_is_refused_when_the_system_is_made():
    with pytest.raises(BadValue, match="option solver.block: 30 is longer than the horizon of 20"):
        system_key("cart_pendulum/kicks", None, {"solver.block": "30"}).make()
    with pytest.raises(BadValue, match="option sensor.noise_std: .* has 2 values, for a plant of 4 states"):
        system_key("cart_pendulum/kicks", None, {"sensor.noise_std": "0.1,0.1"}).make()
    with pytest.raises(BadValue, match=r"option estimator.process_std: .* has 3 values, for a plant of 12 states"):
        system_key("quadrotor/waypoints", None, {"estimator.process_std": "1,1,1"}).make()
    with pytest.raises(EtmpcError, match="not shorter than the MPC's horizon of 20"):
        system_key("cart_pendulum/kicks", None, {"latency.intervals": "20"}).make()


def test_lqr_weights_that_give_no_stabilising_gain_are_refused_naming_them():
    """Independent truth: with Q = 0 no mode is penalised, and the cart's velocity is an integrator (an eigenvalue
    on the unit circle) that Q = 0 cannot detect: the discrete Riccati equation has no stabilising solution, and
    SciPy's solver refuses it too."""
    from scipy.linalg import solve_discrete_are
    from scipy.signal import cont2discrete

    system = system_key("cart_pendulum/balance").make()
    with pytest.raises(BadValue, match=r"the LQR's weights Q = diag\(0, 0, 0, 0\), R = diag\(0.1\) give no stabilising gain"):
        system_key("cart_pendulum/balance", None, {"lqr_state_weights": "0,0,0,0"}).make()
    a, b = system.model.linearised_upright()
    ad, bd, *_ = cont2discrete((a, b, np.eye(4), np.zeros((4, 1))), 0.1, method="zoh")
    with pytest.raises((np.linalg.LinAlgError, ValueError)):
        solve_discrete_are(ad, bd, np.zeros((4, 4)), np.array([[0.1]]))


def test_each_qp_solver_an_option_may_name_reaches_ipopts_optimum():
    """Each plugin on the list solves the cart pendulum's OCP to the optimum an independent Ipopt transcription
    reaches (tests/control/test_mpc.py), so the list holds only solvers that work here."""
    from etmpc.systems.cart_pendulum.system import CartPendulumSystem
    from tests.control.test_mpc import ipopt_reference, random_state

    base = CartPendulumSystem()
    rng = np.random.default_rng(7)
    states = [(random_state(rng), rng.uniform(-25, 25, 1)) for _ in range(2)]
    references = [ipopt_reference(base, x, u) for x, u in states]
    for qpsol in QP_SOLVERS:
        solver = dataclasses.replace(base.config.solver, qpsol=qpsol, compiled=False)
        mpc = CartPendulumSystem(dataclasses.replace(base.config, solver=solver)).mpc
        for (x, u), reference in zip(states, references):
            plan = mpc.solve(x, u)
            assert plan.success and abs(plan.cost - reference) <= 1e-6 * reference, (qpsol, plan.status)


_PROBE = """
import sys
import casadi as ca
from etmpc.common.checks import BadValue
from etmpc.systems import system_key
from etmpc.control.settings import QP_SOLVERS

for qpsol in QP_SOLVERS:  # each plugin on the list, with a library of its name in the working folder
    system = system_key("cart_pendulum/balance", None, {"solver.qpsol": qpsol, "solver.compiled": "false"}).make()
    system.mpc.solve([0.0, 0.1, 0.1, 0.0], [0.0])
try:
    system_key("cart_pendulum/balance", None, {"solver.qpsol": "planted"}).make()
except BadValue as exc:
    print("refused:", exc)
if sys.argv[1:] == ["bypass"]:  # CasADi itself, asked for a plugin it does not ship, loads the planted library
    x = ca.SX.sym("x")
    try:
        ca.qpsol("q", "planted", {"x": x, "f": x**2})
    except RuntimeError:
        pass
"""


def test_no_library_in_the_working_folder_is_ever_loaded_through_an_option(tmp_path):
    """A library named as CasADi's plugins are, planted in the working folder, writes a file when it is loaded.
    Through options nothing loads it: a name off the list is refused, and each name on it is CasADi's own. The
    same folder asked of CasADi directly for a plugin it lacks does load it: the planted library would be found."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler, "a C compiler is needed (the MPCs are compiled with it too)"
    source = tmp_path / "planted.c"
    source.write_text(
        textwrap.dedent(
            """
            #include <stdio.h>
            __attribute__((constructor)) static void planted(void) {
                FILE *f = fopen("LOADED", "a"); if (f) { fputs(NAME "\\n", f); fclose(f); }
            }
            """
        )
    )
    for name in (*QP_SOLVERS, "planted"):
        library = tmp_path / f"libcasadi_conic_{name}.so"
        subprocess.run([compiler, "-shared", "-fPIC", f'-DNAME="{name}"', "-o", library, source], check=True)
    probe = tmp_path / "probe.py"
    probe.write_text(_PROBE)
    run = subprocess.run([sys.executable, probe], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "refused: option solver.qpsol: 'planted' is not one of" in run.stdout
    assert not (tmp_path / "LOADED").exists()
    bypass = subprocess.run([sys.executable, probe, "bypass"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert bypass.returncode == 0, bypass.stderr
    assert (tmp_path / "LOADED").read_text() == "planted\n"


@pytest.mark.parametrize(
    "options, error, says",
    [
        ("sensor.seed=1", BadType, "options must be a mapping of option names to values .* got str"),
        (3, BadType, "options must be a mapping .* got int 3"),
        ([("sensor.seed", "1", "2")], BadType, r"options must be a mapping .* got an entry \('sensor.seed', '1', '2'\)"),
        ({1: 2}, BadType, "an option's name is text, got int 1"),
        ({"sensor.seed": -1}, BadValue, r"option sensor.seed: -1 is not a whole number in 0..2\*\*63-1"),
    ],
)
def test_gymnasium_refuses_options_of_the_wrong_shape_or_value_when_the_environment_is_made(options, error, says):
    import gymnasium as gym

    import etmpc  # noqa: F401 (registers the environments)

    with pytest.raises(error, match=says):
        gym.make("etmpc/cart_pendulum-kicks-v0", options=options)


def test_etmpc_options_says_what_each_option_may_be_and_why(capsys):
    from etmpc.cli import main

    assert main(["options", "--task", "cart_pendulum/kicks"]) == 0
    out = capsys.readouterr().out
    assert "  horizon = 20\n      a whole number in 1..100 (intervals): the MPC's horizon N" in out
    assert "  solver.qpsol = qrqp\n      one of " + ", ".join(QP_SOLVERS) in out
    kicks = out[out.index("  disturbances.kicks_per_s") :].splitlines()[1]
    assert "acts on newly drawn episodes" in kicks and "[0, 100]" in kicks
    assert canonical(0.3) in out


def test_the_options_page_names_the_qp_solvers_an_option_may_name():
    """The docs say which QP solvers ``solver.qpsol`` takes; the list is the code's (QP_SOLVERS), not another."""
    from tests.conftest import REPO

    page = (REPO / "docs" / "tasks" / "sensing.md").read_text()
    assert "(" + ", ".join(f"`{name}`" for name in QP_SOLVERS) + ";" in page
