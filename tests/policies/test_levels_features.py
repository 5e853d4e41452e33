"""The ``levels`` feature set: the ``error`` features and ``unconverged``, 1 exactly when the kept plan is a
real-time iterate its SQP left short of the KKT tolerance. Checked against the MPC's own iterations (one more
from a converged plan barely moves it; from an unconverged one it moves it a lot) and in the loop: the error
features unchanged before it, both values met under ``iterate:1``, never 1 under full solves; a policy on it
plays from its file."""

import numpy as np
import pytest

from etmpc.control.timing import ITERATE, SOLVE
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.policies.features import feature_size, raw_features, raw_names, raw_size
from etmpc.policies.learned import LogisticPolicy, Normalisation
from etmpc.systems import make_system

TASK = "cart_pendulum/kicks_levels"


@pytest.fixture(scope="module")
def system():
    return make_system(TASK)


def test_converged_is_the_sqps_own_fixed_point(system):
    mpc, p = system.mpc, system.observed(system.make_env().reset())
    x, u = np.array([0.0, 0.0, 0.3, 0.0]), np.zeros(1)  # the pole tilted: a cold start is far from the optimum
    one = mpc.iterate(x, u, None, 0, parameters=p, limit=1)
    full = mpc.iterate(x, u, None, 0, parameters=p, limit=system.config.solver.max_iterations)
    assert one.success and not one.converged and full.converged and full.iterations > 1
    after_one = mpc.iterate(x, u, one, 0, parameters=p, limit=1)
    after_full = mpc.iterate(x, u, full, 0, parameters=p, limit=1)
    scale = np.abs(full.inputs).max()
    assert np.abs(after_full.inputs - full.inputs).max() < 1e-3 * scale  # a KKT point: another step stays
    assert np.abs(after_one.inputs - one.inputs).max() > 1e-2 * scale  # not one: another step moves it


class _Reader:
    """Answers ``answer`` at every decision and records the ``levels`` features it was shown."""

    spec, stochastic, observes = "reader", False, True

    def __init__(self, answer):
        self.answer, self.flags = answer, []

    def decide(self, s, rng):
        levels, error = raw_features("levels", TASK, s), raw_features("error", TASK, s)
        assert np.array_equal(levels[:-1], error) and levels[-1] == float(not s.plan.converged)
        self.flags.append(levels[-1])
        return self.answer


@pytest.mark.parametrize("answer, seen", [(ITERATE, {0.0, 1.0}), (SOLVE, {0.0})])
def test_the_feature_reads_the_kept_plan(system, answer, seen):
    reader = _Reader(answer)
    run_episode(system, system.make_env(), reader, None, system.draw_episode(np.random.default_rng(3)))
    assert set(reader.flags) == seen


def test_a_policy_on_the_levels_features_plays_from_its_file(system, tmp_path):
    names = raw_names("levels", TASK, system.state_names)
    size = raw_size("levels", TASK, len(system.state_names))
    assert names[-1] == "unconverged" and len(names) == size == raw_size("error", TASK, len(system.state_names)) + 1
    p = feature_size(len(system.state_names), "levels", TASK)
    rng = np.random.default_rng(0)
    normalisation = Normalisation(np.zeros(size), np.ones(size), np.zeros(size), np.ones(size))
    policy = LogisticPolicy(
        rng.normal(size=p), normalisation, TASK, {}, features="levels", greedy=True, theta_level=rng.normal(size=p)
    )
    path = tmp_path / "levels.json"
    policy.save(path)
    played = parse_policy(f"rl:{path}", system)
    traj = run_episode(system, system.make_env(), played, None, system.draw_episode(np.random.default_rng(4)))
    assert traj.steps == system.episode_steps and set(np.unique(traj.level[: traj.steps])) <= {0, 1, 2}
