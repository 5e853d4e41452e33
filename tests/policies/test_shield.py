"""The shield (``shield:``): its rule against the played trajectory (plan ages, forced levels), its margins
against the geometry written out here, that it never turns a recompute into a keep, and its refusals."""

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.control.timing import ITERATE, KEEP
from etmpc.loop import run_episode
from etmpc.policies import AugmentedState, parse_policy
from etmpc.policies.shield import Shield
from etmpc.systems import make_system
from etmpc.systems.cart_pendulum import kicks
from etmpc.systems.capabilities import SafetyMargin, ShieldRule, offers
from etmpc.systems.quadrotor import task as quadrotor_task

KICKS, LEVELS = "cart_pendulum/kicks", "cart_pendulum/kicks_levels"


@pytest.fixture(scope="module")
def kicks_system():
    return make_system(KICKS)


def _play(system, spec: str, index: int = 0):
    episode = system.draw_episode(np.random.default_rng(index))
    return run_episode(system, system.make_env(), parse_policy(spec, system), np.random.default_rng(1), episode)


def test_the_pendulums_margin_is_the_angle_left_before_a_fall_one_interval_on():
    upright = np.zeros(4)
    assert kicks.fall_margin(upright) == kicks.FALL_RAD
    tilted = np.array([0.3, -1.0, 0.5, 2.0])  # beta + omega dt = 0.5 + 2 x 0.1 = 0.7 rad
    assert kicks.fall_margin(tilted) == pytest.approx(kicks.FALL_RAD - (0.5 + 2.0 * kicks.CONTROL_DT_S))
    assert kicks.fall_margin(-tilted) == kicks.fall_margin(tilted)  # either side
    assert kicks.fall_margin(np.array([0, 0, kicks.FALL_RAD, 0.0])) == 0.0  # at a fall


def test_the_drones_margin_is_its_distance_to_the_fence_ceiling_or_ground_one_interval_on():
    x = np.zeros(12)
    x[2] = 1.0  # hovering 1 m up at the centre: the ground (1 m - 0.05 m) is nearest
    assert quadrotor_task.fence_margin(x) == pytest.approx(1.0 - quadrotor_task.GROUND_M)
    x[:3], x[6:9] = (1.5, -0.2, 1.2), (3.0, 0.0, 0.0)  # heading for the +x fence at 3 m/s: 1.5 + 0.15 m next interval
    assert quadrotor_task.fence_margin(x) == pytest.approx(
        quadrotor_task.FENCE_HALF_WIDTH_M - 1.5 - 3.0 * quadrotor_task.CONTROL_DT_S
    )
    x[:3], x[6:9] = (0.0, 0.0, 2.6), 0.0  # above the ceiling: outside, a negative margin
    assert quadrotor_task.fence_margin(x) < 0


def test_the_safety_tasks_offer_a_margin_and_the_others_do_not():
    for task in (KICKS, LEVELS, "cart_pendulum/kicks_late", "quadrotor/waypoints"):
        system = make_system(task)
        assert offers(system, SafetyMargin) and system.margin_unit in ("rad", "m")
    assert make_system("battery/trading").safety_margin is None


def test_an_age_shield_keeps_no_plan_past_its_age(kicks_system):
    """``shield:A:never``: a new plan at least every A steps, so a plan plays at ages 0..A-1 (the trajectory
    records the age of the plan in force after the decision); unshielded, far longer."""
    shielded, bare = _play(kicks_system, "shield:4:never"), _play(kicks_system, "never")
    n = shielded.steps
    assert shielded.plan_age[:n].max() == 3 and bare.plan_age[: bare.steps].max() > 10
    assert np.diff(np.flatnonzero(shielded.recompute[:n])).max() <= 4


def test_a_shield_never_turns_a_recompute_into_a_keep(kicks_system):
    """Around ``always`` the shield changes nothing: the same trajectory, bit for bit."""
    shielded, bare = _play(kicks_system, "shield:3:0.5:always"), _play(kicks_system, "always")
    assert np.array_equal(shielded.applied, bare.applied, equal_nan=True)
    assert np.array_equal(shielded.recompute, bare.recompute)


def test_a_margin_shield_recomputes_wherever_the_margin_is_below_its_level(kicks_system):
    """A margin above any state's (here 2 rad > the fall's 1.2 rad): every decision recomputes, as ``always``;
    a margin below any state's (-10 rad): the base alone, as ``every:7``."""
    everywhere = _play(kicks_system, "shield:1000:2:never")
    assert everywhere.recompute[: everywhere.steps].all()
    nowhere, bare = _play(kicks_system, "shield:1000:-10:every:7"), _play(kicks_system, "every:7")
    assert np.array_equal(nowhere.recompute, bare.recompute) and np.array_equal(nowhere.applied, bare.applied, equal_nan=True)


def test_a_deviation_shield_recomputes_exactly_where_the_state_has_left_the_plan(kicks_system):
    """``shield:1000:-10:D:never`` in the loop: no age and no margin ever fires, so every recompute the shield
    makes is the deviation's. From what the loop showed at each decision (the state and the kept plan's
    prediction, recorded by the base), the played trajectory recomputed exactly where ``|W (x_i - x_hat_i)|``
    was above D; unshielded, ``never`` keeps while the deviation grows far beyond it."""
    level, weights = 0.3, np.asarray(kicks_system.error_weights)

    class Watcher:  # never: keeps, and records the deviation it was shown
        spec, stochastic = "never", False

        def __init__(self):
            self.seen = []

        def decide(self, s, rng):
            self.seen.append(np.linalg.norm(weights * (np.asarray(s.x) - np.asarray(s.x_predicted))))
            return False

    def played(policy):
        episode = kicks_system.draw_episode(np.random.default_rng(0))
        return run_episode(kicks_system, kicks_system.make_env(), policy, np.random.default_rng(1), episode)

    watcher = Watcher()
    shield = parse_policy(f"shield:1000:-10:{level:g}:never", kicks_system)
    traj = played(Shield(watcher, 1000, -10.0, kicks.fall_margin, deviation=level, weights=weights))
    asked = ~traj.forced[: traj.steps]  # no plan yet, or the plan ran out: a forced solve, nothing asked
    deviation = np.array(watcher.seen)
    assert len(deviation) == asked.sum() > traj.steps // 2
    assert np.array_equal(traj.recompute[: traj.steps][asked], deviation > level)
    assert 0 < (deviation > level).sum() < len(deviation)  # both answers were played
    assert np.array_equal(_play(kicks_system, shield.spec).recompute, traj.recompute)  # the spec plays the same
    watcher.seen.clear()
    bare = played(Shield(watcher, 1000))  # the same base by age alone, which never fires: never itself
    assert max(watcher.seen) > 3 * level and bare.recompute[: bare.steps].sum() < traj.recompute[: traj.steps].sum()


def test_a_deviation_shield_reads_the_weighted_error_and_reads_it_last():
    """The deviation's measure is the threshold trigger's, |W (x - x_hat)| (a 3-4-5 triangle here), and a
    margin or an age that fires already is not read past."""

    class Keeper:
        spec, stochastic = "keeper", False

        def decide(self, s, rng):
            return False

    shield = Shield(Keeper(), 10, 0.0, lambda x: float(x[0]), deviation=5.0, weights=np.array([1.0, 2.0]))
    state = lambda x, x_hat, age=1: AugmentedState(np.array(x), np.zeros(2), age, np.array(x_hat))  # noqa: E731
    assert not shield.decide(state([3.0, 2.0], [0.0, 0.0]), None)  # |(3, 4)| = 5: on the bound, kept
    assert shield.decide(state([3.0, 2.01], [0.0, 0.0]), None)  # just past it
    assert not shield.decide(state([4.0, 3.5], [1.0, 1.5]), None)  # the difference is what counts: (3, 4) again
    assert shield.decide(state([-1.0, 0.0], [0.0, 0.0]), None)  # the margin (-1 < 0) fires first
    assert shield.overrides == 2 and shield.spec == "shield:10:0:5:keeper"


def test_the_shield_asks_its_base_at_every_decision_and_counts_its_overrides():
    asked = []

    class Base:
        spec, stochastic = "keeper", False

        def decide(self, s, rng):
            asked.append(s.age)
            return False

    shield = Shield(Base(), max_age=3, margin=0.5, margin_of=lambda x: float(x[0]))
    decisions = [
        shield.decide(AugmentedState(np.array([m]), np.zeros(1), age, np.zeros(1)), None)
        for m, age in [(1.0, 1), (1.0, 3), (0.2, 1), (1.0, 2)]
    ]
    assert decisions == [False, True, True, False] and asked == [1, 3, 1, 2] and shield.overrides == 2
    assert shield.spec == "shield:3:0.5:keeper"


def test_on_a_task_with_compute_levels_the_shield_forces_one_sqp_iteration():
    system = make_system(LEVELS)
    policy = parse_policy("shield:5:never", system)
    assert policy.decide(AugmentedState(np.zeros(4), np.zeros(4), 5, np.zeros(4)), None) == ITERATE
    assert policy.decide(AugmentedState(np.zeros(4), np.zeros(4), 4, np.zeros(4)), None) == KEEP
    traj = _play(system, "shield:5:never")
    assert traj.plan_age[: traj.steps].max() <= 5 and (traj.level[: traj.steps] == ITERATE).any()


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("shield:5", "give the policy to shield"),
        ("shield:5:0.3", "give the policy to shield"),
        ("shield:0:always", "whole number of steps >= 1"),
        ("shield:2.5:always", "is not an integer"),
        ("shield:5:oracle:every:3", "an oracle"),
        ("shield:5:nan:always", "finite"),
        ("shield:5:0.3:0:always", "deviation must be a finite number > 0"),
        ("shield:5:0.3:inf:always", "deviation must be a finite number > 0"),
        ("shield:5:0.3:1:2:always", "unknown policy"),  # at most three numbers: the fourth starts the base
    ],
)
def test_bad_shields_are_one_line_each(kicks_system, spec, message):
    with pytest.raises(EtmpcError, match=message):
        parse_policy(spec, kicks_system)


def test_a_task_without_a_margin_or_a_rule_says_how_to_shield_it():
    with pytest.raises(EtmpcError, match="declares no shield rule"):  # a margin, but no rule chosen
        parse_policy("shield:every:3", make_system(KICKS))
    battery = make_system("battery/trading")
    with pytest.raises(EtmpcError, match="no safety margin: shield it by age alone"):
        parse_policy("shield:5:0.1:always", battery)
    with pytest.raises(EtmpcError, match="declares no shield rule"):
        parse_policy("shield:always", battery)
    assert parse_policy("shield:5:always", battery).spec == "shield:5:always"


@pytest.mark.parametrize("task", ["cart_pendulum/kicks_late", "quadrotor/waypoints"])
def test_the_tasks_own_rule_is_what_shield_base_plays(task):
    system = make_system(task)
    assert isinstance(system.shield, ShieldRule)
    policy = parse_policy("shield:every:20", system)
    assert (policy.max_age, policy.margin, policy.deviation) == (
        system.shield.max_age,
        system.shield.margin,
        system.shield.deviation,
    )
    assert policy.spec == f"shield:{system.shield.text}:every:20"  # the rule it played, written out


def test_a_shield_is_no_way_round_the_one_rollout_rule(kicks_system):
    """A rollout's base may not simulate itself; a shield around a rollout simulates as its base does."""
    with pytest.raises(EtmpcError, match="rollout"):
        parse_policy("rollout:shield:5:rollout:every:3:2:3:2:3", kicks_system)
    assert parse_policy("shield:5:rollout:every:3:2:3", kicks_system).simulates
    assert not parse_policy("rollout:shield:5:every:3:2:3", kicks_system).base.simulates
