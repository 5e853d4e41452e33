"""The plants' stepping skips ``mj_step1`` between sub-steps only where that changes nothing.

The reference is dm-control's legacy RK4 stepping, written out: before each sub-step the task's
force, then ``mj_step`` and ``mj_step1``. Each plant's ``step`` must give the same mjData bit for bit
(state, time, warm start and the derived quantities the tasks read), from many states, with and
without a disturbance, on the rail and against its bumpers.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from etmpc.systems import make_system

FIELDS = ("qpos", "qvel", "qacc", "qacc_warmstart", "qfrc_applied", "qfrc_bias", "xpos", "cvel", "M", "qLD", "time")


def _reference_step(physics, nstep: int, force_of) -> None:
    m, d = physics.model.ptr, physics.data.ptr
    for _ in range(nstep):
        d.qfrc_applied[:] = force_of(m, d)
        mujoco.mj_step(m, d)
        mujoco.mj_step1(m, d)


def _same(a: mujoco.MjData, b: mujoco.MjData) -> bool:
    return all(np.array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f))) for f in FIELDS)


def _cart_force(physics, w: float):
    def force(m, d):
        out = np.zeros(m.nv)
        if w:
            mujoco.mj_mulM(m, d, out, physics._hinge_unit * w)
        if physics.bumpers is not None:
            out[physics._slider[1]] += physics._bumper_force(d.qpos, d.qvel)
        return out

    return force


@pytest.mark.parametrize("task", ["cart_pendulum", "cart_pendulum/kicks"])
@pytest.mark.parametrize("w", [0.0, 0.7])
def test_the_cart_pendulums_stepping_is_the_legacy_rk4_stepping_bit_for_bit(task, w):
    physics = make_system(task).make_env().physics
    twin = make_system(task).make_env().physics
    rng = np.random.default_rng(0)
    against_bumpers = 0
    for trial in range(40):
        # positions out to past the kicks task's rail ends (2.5 m), so some intervals meet the bumpers
        x = np.array([rng.uniform(-2.8, 2.8), rng.normal(0, 2), rng.normal(0, 0.5), rng.normal(0, 2)])
        physics.set_state_vector(x)
        physics.set_disturbance(w)
        physics.data.ctrl[0] = rng.uniform(-10, 10)
        mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
        twin.restore(physics.snapshot())
        against_bumpers += physics.touches_bumper()
        physics.step(10)
        _reference_step(twin, 10, _cart_force(twin, w))
        assert _same(physics.data.ptr, twin.data.ptr), (trial, x)
    if task.endswith("kicks"):
        assert against_bumpers > 0  # the bumpers' branch was exercised


def test_the_reachers_stepping_is_the_legacy_rk4_stepping_bit_for_bit():
    physics = make_system("reacher").make_env().physics
    twin = make_system("reacher").make_env().physics
    rng = np.random.default_rng(1)
    for trial in range(40):
        physics.set_state_vector(np.concatenate([rng.uniform(-np.pi, np.pi, 2), rng.normal(0, 3, 2)]))
        physics.data.ctrl[:] = rng.uniform(-1, 1, 2)
        mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
        twin.restore(physics.snapshot())
        physics.step(10)
        _reference_step(twin, 10, lambda m, d: np.zeros(m.nv))
        assert _same(physics.data.ptr, twin.data.ptr), trial


@pytest.mark.parametrize(
    "task, size, bad_size, not_finite",
    [
        ("quadrotor", 4, "the quadrotor's action is 4 rotor thrusts, got an action of shape (3,)", "the quadrotor's thrusts"),
        ("reacher", 2, "the reacher's action is 2 torques, got an action of shape (3,)", "the reacher's torques"),
    ],
)
def test_a_plant_takes_its_own_number_of_finite_inputs_and_says_so_in_one_line(task, size, bad_size, not_finite):
    physics = make_system(task).make_env().physics
    with pytest.raises(ValueError) as raised:
        physics.set_control(np.zeros(3))
    assert str(raised.value) == bad_size
    bad = np.zeros(size)
    bad[-1] = np.nan
    with pytest.raises(ValueError) as raised:
        physics.set_control(bad)
    assert str(raised.value) == f"{not_finite} must be finite, got {bad.tolist()}"
    physics.set_control(np.full((1, size), 0.01))  # any shape of the right size, as a flat vector
    np.testing.assert_array_equal(physics.data.ctrl, np.full(size, 0.01))
