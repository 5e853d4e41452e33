"""Every number a task's module docstrings state that the code holds (its ``Config``, its task module's constants,
its model's parameters, its MJCF) agrees with the code. Each table row builds the docstring's fragment from the
code's value, so a number changed in the code and not in the docstring fails here, naming the module, the
fragment it should hold and what the number is. (The docs/ pages mark such numbers instead: test_docs_numbers.py.)

Left out: numbers of history (what was tried first) and of measurements (gains, solve counts, CIs), which the code
does not hold, and the few it holds only as geometry (the quadrotor's 0.012 m, where a resting drone's centre sits)
or as pi. A sentence is matched with the docstring's line breaks as single spaces."""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest

from etmpc.systems.battery import mpc as battery_mpc
from etmpc.systems.battery import parameters as battery_parameters
from etmpc.systems.battery import system as battery_system
from etmpc.systems.battery import task as battery_task
from etmpc.systems.cart_pendulum import kicks, kicks_system
from etmpc.systems.cart_pendulum import physics as cart_physics
from etmpc.systems.cart_pendulum import system as cart_system
from etmpc.systems.cart_pendulum import task as cart_task
from etmpc.systems.cart_pendulum import timing as kicks_timing
from etmpc.systems.quadrotor import model as quadrotor_model
from etmpc.systems.quadrotor import physics as quadrotor_physics
from etmpc.systems.quadrotor import system as quadrotor_system
from etmpc.systems.quadrotor import task as quadrotor_task
from etmpc.systems.reacher import model as reacher_model
from etmpc.systems.reacher import physics as reacher_physics
from etmpc.systems.reacher import system as reacher_system
from etmpc.systems.reacher import task as reacher_task
from etmpc.systems.reacher import timing as reacher_timing


def g(x) -> str:
    return f"{x:g}"


def e(x) -> str:
    """A power of ten as the docstrings write it: ``1e-5``, not Python's ``1e-05``."""
    return f"{x:.0e}".replace("e-0", "e-").replace("e+0", "e")


def words(n) -> str:
    """A small count as the docstrings spell it."""
    return {1: "one", 2: "two", 3: "three", 4: "four"}.get(n, g(n))


def shooting(block: int) -> str:
    return "full multiple shooting" if block == 1 else f"a shooting node every {block} intervals"


def fraction(x) -> str:
    """A simple fraction as the docstrings write it: ``-1/2``."""
    return str(Fraction(x).limit_denominator(100))


def percent(x, digits: int = 0) -> str:
    return f"{100 * x:.{digits}f} %"


def ctrlrange(root, actuator: str) -> tuple[float, float]:
    low, high = root.find("actuator", actuator).ctrlrange
    return float(low), float(high)


def assert_docstring_says(module, rows: list[tuple[str, str]]) -> None:
    text = " ".join(module.__doc__.split())
    missing = [
        f"{module.__name__}'s docstring should say {fragment!r} ({what})" for fragment, what in rows if fragment not in text
    ]
    assert not missing, "\n" + "\n".join(missing)


# -- the quadrotor ----------------------------------------------------------------------------------------
def quadrotor_system_rows():
    c, p, dt = quadrotor_system.Config(), quadrotor_model.Parameters(), quadrotor_task.CONTROL_DT_S
    q, r = c.feedback_state_weights, c.feedback_input_weights
    stage, _ = quadrotor_system.QuadrotorSystem(c).residuals()
    # the soft floor's width, from the residual itself: at the clearance it is weight * width * log 2 / scale
    at_clearance = np.zeros(12)
    at_clearance[2] = c.clearance_m
    floor = float(stage(at_clearance, np.zeros(4), np.zeros(4), at_clearance[:3]).full()[3, 0])
    width_m = floor * c.distance_scale_m / (c.clearance_weight * math.log(2))
    return [
        (f"N = {c.horizon} ({g(c.horizon * dt)} s)", "the horizon, and its length"),
        (f"RK4, {c.rk4_substeps} steps per interval", "the predictor's RK4 steps"),
        (f"``e / {g(c.distance_scale_m)}``", "the stage's distance scale"),
        (f"below {g(c.clearance_m)} m, {g(width_m * 100)} cm wide", "the soft floor's height and width"),
        (f"times {g(c.clearance_weight)} / {g(c.distance_scale_m)})", "the soft floor's weight"),
        (f"``{g(c.velocity_weight)} v``", "the stage's velocity weight"),
        (f"``{g(c.angle_weight)} angles``", "the stage's angle weight"),
        (f"``{g(c.rate_weight)} rates``", "the stage's rate weight"),
        (f"``{g(c.thrust_weight)} (u - hover) / max``", "the thrust's weight"),
        (f"``{c.thrust_change_weight:.1f} du / max``", "the thrust change's weight"),
        (
            f"``[{g(c.terminal_distance_factor)} e / {g(c.distance_scale_m)}, floor, {g(c.terminal_velocity_weight)} v,"
            f" {g(c.terminal_angle_weight)} angles, {g(c.terminal_rate_weight)} rates]``",
            "the terminal residual's weights",
        ),
        (f"``{g(c.idle_thrust_n)} <= u_i <= {g(p.max_thrust_n)}`` N", "the thrust bounds: idle, and the model's largest"),
        (f"``Q = diag({g(q[0])} I3, {g(q[3])} I3, {g(q[6])} I3, {g(q[9])} I3)``", "the feedback's Q"),
        (f"``R = {g(r[0])} I4``", "the feedback's R"),
    ]


def quadrotor_task_rows():
    t = quadrotor_task
    root = quadrotor_physics.load_model()
    weight_n = t.make_environment(random=0).physics.weight_n()  # the plant's, not the model's
    largest_m = float(np.linalg.norm(t.BOX_HIGH - t.BOX_LOW))
    return [
        (f"``{g(ctrlrange(root, 'rotor0')[0])} <= u_i <= {g(ctrlrange(root, 'rotor0')[1])}`` N", "the MJCF's ctrlrange"),
        (
            f"RK4 at {g(t.PHYSICS_DT_S * 1000)} ms under a {g(t.CONTROL_DT_S)} s control interval",
            "the physics step, the interval",
        ),
        (f"{t.EPISODE_STEPS} intervals ({g(t.EPISODE_STEPS * t.CONTROL_DT_S)} s)", "the episode's length"),
        (f"``|x|, |y| <= {g(t.BOX_HIGH[0])}`` m, ``{g(t.BOX_LOW[2])} <= z <= {g(t.BOX_HIGH[2])}`` m", "the waypoint box"),
        (f"``U(+-{g(t.INITIAL_YAW_RAD)})`` rad", "the initial yaw"),
        (
            f"probability {g(t.CHANGE_PROBABILITY)} ({words(t.CHANGE_PROBABILITY / t.CONTROL_DT_S)} change per second)",
            "the waypoint's changes",
        ),
        (f"probability {g(t.GUST_PROBABILITY)} ({g(t.GUST_PROBABILITY / t.CONTROL_DT_S)} per second)", "the gusts' onsets"),
        (
            f"``U({g(t.GUST_PEAK_N[0])}, {g(t.GUST_PEAK_N[1])})`` N"
            f" ({percent(t.GUST_PEAK_N[0] / weight_n)} to {percent(t.GUST_PEAK_N[1] / weight_n)} of the plant's weight)",
            "the gusts' peaks, and as shares of the plant's weight",
        ),
        (f"``U({g(t.GUST_DURATION_S[0])}, {g(t.GUST_DURATION_S[1])})`` s", "the gusts' lengths"),
        (f"``|x|, |y| <= {g(t.FENCE_HALF_WIDTH_M)}`` m and ``z <= {g(t.FENCE_HEIGHT_M)}`` m", "the geofence"),
        (f"``z < {g(t.GROUND_M)}`` m", "the ground"),
        (f"``-d^2 / (d^2 + {g(t.DISTANCE_SCALE_M)}^2)``", "the reward's scale"),
        (f"({fraction(t.distance_reward(t.DISTANCE_SCALE_M))} at {g(t.DISTANCE_SCALE_M)} m,", "the reward at its scale"),
        (f"a new waypoint is up to {g(largest_m)} m from the last", "the box's diagonal"),
        (f"{g(t.FAILURE_PENALTY)} more off on a failure step", "the failure's penalty"),
        (f"at most -{g(t.FAILURE_PENALTY)} exactly when", "the failure's penalty"),
    ]


# -- the cart pendulum: balance, kicks and kicks with time in the loop ------------------------------------------
def cart_task_rows():
    t = cart_task
    root = cart_physics.load_model()
    physics_s = float(root.option.timestep)
    return [
        (f"(RK4, {g(physics_s)} s) under a {g(t.CONTROL_DT_S)} s control interval", "the MJCF's step, the interval"),
        (f"``w ~ N(0, {g(t.DISTURBANCE_STD_RAD_S2)})`` rad/s^2", "the disturbance's standard deviation"),
        (f"up to one {g(physics_s)} s step", "the MJCF's step"),
        (f"(+-{g(ctrlrange(root, 'force')[1])} N)", "the MJCF's ctrlrange"),
        (f"``OFF_BALANCE_RAD`` = {g(t.OFF_BALANCE_RAD)} rad ({math.degrees(t.OFF_BALANCE_RAD):.1f} degrees)", "off balance"),
        (f"(up to {g(t.INITIAL_STATE_HIGH[2])} rad)", "the initial tilt"),
        (f"within {g(t.OFF_BALANCE_RAD)} rad, for at most ``RECOVERY_STEPS``", "the recovery's band"),
        (f"({t.RECOVERY_STEPS} steps, {g(t.RECOVERY_STEPS * t.CONTROL_DT_S)} s)", "the recovery's length"),
        (f"(the kicks task's {g(kicks.FALL_RAD)} rad)", "a fall"),
    ]


def kicks_residual_rows():
    """The residuals' numbers, read off the compiled residuals themselves (most are not the Config's)."""
    c = kicks_system.Config()
    stage, terminal = kicks_system.KicksSystem(c).residuals()
    inside = kicks.BUMPERS.position_m - c.rail_margin_m

    def s(eta=0.0, v=0.0, beta=0.0, omega=0.0, u=0.0, du=0.0):
        return np.ravel(stage([eta, v, beta, omega], u, du, 0.0).full())

    def f(eta=0.0, v=0.0, beta=0.0, omega=0.0):
        return np.ravel(terminal([eta, v, beta, omega], 0.0).full())

    def times(w, term):  # "eta - r" for a weight of 1, else "3 (eta - r)"
        return term if w == 1 else f"{g(w)} ({term})"

    pole, eta = s(beta=math.pi)[0], s(eta=1.0)[1]
    stage_text = (
        f"``[{g(pole)} sin(beta/2), {times(eta, 'eta - r')}, {g(s(omega=1.0)[2])} omega, {g(s(u=1.0)[3])} u,"
        f" {g(s(du=1.0)[4])} du, {g(s(eta=inside + 1)[5])} max(0, |eta| - {g(inside)})]``"
    )
    terminal_text = (
        f"``[{g(f(beta=math.pi)[0])} sin(beta/2), {times(f(eta=1.0)[1], 'eta - r')}, {g(f(omega=1.0)[2])} omega,"
        f" {g(f(v=1.0)[3])} v, {g(f(eta=inside + 1)[4])} max(0, |eta| - {g(inside)})]``"
    )
    return [(stage_text, "the stage residual"), (terminal_text, "the terminal residual")]


def kicks_system_rows():
    c, t = kicks_system.Config(), kicks
    q = c.feedback_state_weights
    return kicks_residual_rows() + [
        (f"{shooting(c.solver.block)}, N = {c.horizon}, compiled", "the transcription and the horizon"),
        (f"RK4, {c.rk4_substeps} steps per interval", "the predictor's RK4 steps"),
        (f"keeps the plan {g(c.rail_margin_m)} m from the bumpers", "the rail margin"),
        (f"``|u| <= {g(c.force_limit_n)}`` N", "the force limit"),
        (
            f"constraint violation <= {e(10 * c.solver.tolerance)} and Lagrangian gradient <= {e(10 * c.solver.dual_tolerance)}"
            f" (the SQP's tolerances {e(c.solver.tolerance)} and {e(c.solver.dual_tolerance)}, times 10)",
            "the solver's tolerances",
        ),
        (f"Input weight {g(c.input_weight)}", "the input's weight"),
        (f"``Q = diag({', '.join(g(w) for w in q)})``, ``R = {g(c.feedback_input_weight)}``", "the feedback's Q and R"),
        (f"plus {g(c.recompute_price)} per recompute", "the price"),
        (f"**Lookahead** {kicks_system.KicksSystem.benchmark.lookahead} steps", "the benchmark's lookahead"),
        (f"a jump every {g(1 / t.REFERENCE_JUMPS_PER_S)} s on average", "the reference's jump rate"),
    ]


def kicks_task_rows():
    t, b = kicks, kicks.BUMPERS
    h = t.INITIAL_STATE_HIGH
    return [
        (f"``|eta| = {g(b.position_m)} m``", "the bumpers' position"),
        (f"{g(b.stiffness_n_m)} N/m and {g(b.damping_n_s_m)} N s/m", "the bumpers' spring and damper"),
        (f"RK4 at {g(t.PHYSICS_DT_S)} s", "the physics step"),
        (f"{t.EPISODE_STEPS} intervals of {g(t.CONTROL_DT_S)} s", "the episode"),
        (
            f"``eta ~ U(+-{g(h[0])})``, ``v ~ U(+-{g(h[1])})``, ``beta ~ U(+-{g(h[2])})``, ``omega ~ U(+-{g(h[3])})``",
            "the initial state's ranges",
        ),
        (f"``r ~ U(+-{g(t.REFERENCE_M)} m)``", "the reference's range"),
        (f"probability {g(t.REFERENCE_JUMP_PROBABILITY)} ({g(t.REFERENCE_JUMPS_PER_S)} jumps per second)", "the jumps"),
        (f"(rate {g(t.KICKS_PER_S)} per second)", "the kicks' rate"),
        (f"``+-U({g(t.KICK_RAD_S[0])}, {g(t.KICK_RAD_S[1])})`` rad/s", "the kicks' sizes"),
        (
            f"``sin^2(beta/2) / sin^2({g(t.ANGLE_SCALE_RAD)})`` (capped at {g(2 * t.step_cost(math.pi, 0.0, False))}:"
            f" {g(2 * t.ANGLE_SCALE_RAD)} rad)",
            "the angle's cost, its cap and where it is reached",
        ),
        (f"``d^2 / (d^2 + {g(t.POSITION_SCALE_M)}^2)``", "the position's cost"),
        (f"({fraction(t.step_cost(0.0, t.POSITION_SCALE_M, False))} at {g(t.POSITION_SCALE_M)} m off)", "the cost at its scale"),
        (f"or {g(t.step_cost(0.0, 0.0, True))} while the cart presses a bumper", "the cost on a bumper"),
        (f"(``|beta| > {g(t.FALL_RAD)} rad``) costs {g(t.FALL_COST)} once", "a fall"),
        (f"one fall costs an episode {g(t.FALL_COST)},", "a fall's cost"),
    ]


def kicks_timing_rows():
    late, levels = kicks_timing.LateConfig(), kicks_timing.LevelsConfig()
    dt = kicks_timing.KicksLateSystem.control_interval_s
    return [
        (
            f"its plan {words(late.latency.intervals)} control interval ({g(late.latency.intervals * dt)} s) after it started",
            "kicks_late's latency",
        ),
        (f"The price stays {g(late.recompute_price)} per solve.", "kicks_late's price"),
        (f"priced {g(levels.recompute_price)} per SQP iteration", "kicks_levels' price"),
        (
            f"``ceil(iterations x {g(levels.latency.iteration_s * 1000)} ms / {g(dt)} s)``",
            "kicks_levels' latency: the time per iteration and the interval",
        ),
        (
            f"(N = {levels.horizon}, {words(len(kicks_timing.KicksLevelsSystem.state_names))} states, full multiple shooting)"
            f" takes {g(levels.latency.iteration_s * 1000)} ms",
            "the OCP's horizon and states, the time per iteration",
        ),
    ]


# -- the battery ----------------------------------------------------------------------------------------------
def battery_system_rows():
    b = battery_system.Config().battery
    limit_kw = battery_system.CURTAILMENT_TOLERANCE * b.trade_limit_kw
    return [
        (
            f"({percent(battery_system.CURTAILMENT_TOLERANCE)}: {g(limit_kw)} kW, {g(limit_kw * b.interval_h)} kWh"
            f" over a {g(b.interval_s)} s interval)",
            "the curtailment tolerance, of the trade limit, in kW and in kWh per interval",
        ),
        (f"the computer's own draw ({g(b.compute_power_kw)} kW)", "eta_c"),
    ]


def battery_task_rows():
    b, m = battery_system.Config().battery, battery_system.Config().market
    return [
        (f"one {g(b.interval_s)} s interval per step", "the interval"),
        (f"``+-{g(b.trade_fraction_per_interval)} C / delta`` = {g(b.trade_limit_kw)} kW", "the trade limit"),
        (f"``eta_c = {g(b.compute_power_kw)}`` kW", "eta_c"),
        (f"a trade beyond {g(b.trade_limit_kw)} kW is {g(b.trade_limit_kw)} kW", "the trade limit"),
        (f"for the next {m.forecast_steps} intervals", "the forecasts' length"),
    ]


def battery_parameters_rows():
    b, production = battery_parameters.Battery(), battery_parameters.PRODUCTION
    full_kwh = b.trade_limit_kw * b.interval_h
    return [
        (
            f"a full-power trade ({g(b.trade_limit_kw)} kW for {g(b.interval_s)} s) moves {g(full_kwh)} kWh,"
            f" {percent(full_kwh / b.capacity_kwh)} of the capacity",
            "a full-power trade",
        ),
        (
            f"a net production of {g(production.event_high)} kW held for {g(b.interval_s)} s moves"
            f" {percent(production.event_high * b.soc_per_kw, 1)}",
            "a production event",
        ),
        (f"the computer's {g(b.compute_power_kw)} kW draw moves {percent(b.compute_power_kw * b.soc_per_kw, 3)}", "eta_c"),
    ]


def battery_mpc_rows():
    b = battery_parameters.Battery()
    return [(f"|u_j| <= {g(b.trade_fraction_per_interval)} C / delta", "the trade limit")]


# -- the reacher ----------------------------------------------------------------------------------------------
def reacher_system_rows():
    c, t = reacher_system.Config(), reacher_task
    q, r = c.feedback_state_weights, c.feedback_input_weights
    return [
        (f"{shooting(c.solver.block)}, N = {c.horizon}, compiled", "the transcription and the horizon"),
        (f"RK4, {c.rk4_substeps} steps per interval", "the predictor's RK4 steps"),
        (
            f"``[e / {g(c.distance_scale_m)}, {g(c.velocity_weight)} qdot, {g(c.torque_weight)} u,"
            f" {g(c.torque_change_weight)} du]``",
            "the stage residual",
        ),
        (
            f"``[{g(c.terminal_distance_factor)} e / {g(c.distance_scale_m)}, {g(c.terminal_velocity_weight)} qdot]``",
            "the terminal residual",
        ),
        (f"``|u_i| <= {g(c.torque_limit_nm)}`` N m", "the torque limit"),
        (f"A Levenberg-Marquardt term ``{e(c.solver.regularisation)} I``", "the solver's regularisation"),
        (
            f"the Lagrangian gradient's tolerance {e(c.solver.dual_tolerance)} and at most {c.solver.max_iterations} iterations",
            "the solver's dual tolerance and iterations",
        ),
        (
            f"constraint violation <= {e(10 * c.solver.tolerance)} and Lagrangian gradient <= {e(10 * c.solver.dual_tolerance)}"
            " (10 times the SQP's tolerances)",
            "a converged solve",
        ),
        (f"``Q = diag({', '.join(g(w) for w in q)})``, ``R = diag({', '.join(g(w) for w in r)})``", "the feedback's Q and R"),
        (f"``d^2 / (d^2 + {g(t.DISTANCE_SCALE_M)}^2)`` over {t.EPISODE_STEPS} steps", "the cost and the episode"),
        (f"plus {g(c.recompute_price)} per recompute", "the price"),
        (f"At {g(c.recompute_price)} the oracle gains", "the price"),
        (f"**Lookahead** {reacher_system.ReacherSystem.benchmark.lookahead} steps", "the benchmark's lookahead"),
        (f"(every {g(1 / t.JUMPS_PER_S)} s on average)", "the target's jump rate"),
    ]


def reacher_task_rows():
    t, p = reacher_task, reacher_model.Parameters()
    root = reacher_physics.load_model()
    return [
        (f"torques ``|u_i| <= {g(ctrlrange(root, 'shoulder')[1])}`` N m", "the MJCF's ctrlrange"),
        (f"RK4 at {g(t.PHYSICS_DT_S)} s under a {g(t.CONTROL_DT_S)} s control interval", "the physics step, the interval"),
        (f"**Episodes**: {t.EPISODE_STEPS} intervals.", "the episode"),
        (f"``q2 ~ U(+-{g(t.INITIAL_STATE_HIGH[1])})`` rad", "the elbow's initial range"),
        (f"radius ``U({g(t.TARGET_RADIUS_M[0])}, {g(t.TARGET_RADIUS_M[1])})`` m", "the target's radius"),
        (f"(the arm reaches {g(p.upper_arm_length_m + p.forearm_length_m)} m)", "the model's reach"),
        (f"probability {g(t.JUMP_PROBABILITY)} ({g(t.JUMPS_PER_S)} jumps per second)", "the target's jumps"),
        (f"``-d^2 / (d^2 + {g(t.DISTANCE_SCALE_M)}^2)``", "the reward's scale"),
        (f"{fraction(t.distance_reward(t.DISTANCE_SCALE_M))} at {g(t.DISTANCE_SCALE_M)} m,", "the reward at its scale"),
        (f"{g(t.distance_reward(2 * t.DISTANCE_SCALE_M))} at {g(2 * t.DISTANCE_SCALE_M)} m", "the reward at twice its scale"),
        (f"more than {g(t.DISTANCE_SCALE_M)} m from the target", "far from target"),
    ]


def reacher_timing_rows():
    late = reacher_timing.LateConfig()
    return [
        (f"its plan {words(late.latency.intervals)} control interval after it started", "jumps_late's latency"),
        (f"an interval is {g(reacher_timing.JumpsLateSystem.control_interval_s)} s", "the interval"),
        (f"the price stays {g(late.recompute_price)} per solve", "jumps_late's price"),
    ]


TABLES = {
    quadrotor_system: quadrotor_system_rows,
    quadrotor_task: quadrotor_task_rows,
    cart_task: cart_task_rows,
    kicks_system: kicks_system_rows,
    kicks: kicks_task_rows,
    kicks_timing: kicks_timing_rows,
    battery_system: battery_system_rows,
    battery_task: battery_task_rows,
    battery_parameters: battery_parameters_rows,
    battery_mpc: battery_mpc_rows,
    reacher_system: reacher_system_rows,
    reacher_task: reacher_task_rows,
    reacher_timing: reacher_timing_rows,
}


@pytest.mark.parametrize("module", TABLES, ids=lambda m: m.__name__.removeprefix("etmpc.systems."))
def test_the_docstrings_numbers_are_the_codes(module):
    assert_docstring_says(module, TABLES[module]())


def test_a_changed_number_fails_naming_the_module_the_fragment_and_the_number(monkeypatch):
    changed = dataclasses.replace(quadrotor_system.Config(), angle_weight=0.7)  # the Config changed, not its docstring
    monkeypatch.setattr(quadrotor_system, "Config", lambda: changed)
    with pytest.raises(AssertionError) as failed:
        assert_docstring_says(quadrotor_system, quadrotor_system_rows())
    assert "etmpc.systems.quadrotor.system's docstring should say" in str(failed.value)
    assert "``0.7 angles``" in str(failed.value) and "(the stage's angle weight)" in str(failed.value)
    assert "velocity" not in str(failed.value)  # only the number that changed


def test_the_system_modules_without_numbers_state_none():
    """The balance system's docstring states no number (its Config's are on the page, under markers)."""
    assert not any(ch.isdigit() for ch in cart_system.__doc__)
