"""What each registered task provides (etmpc.systems.base), derived from the task itself, and the registry's names."""

import pickle

import numpy as np
import pytest

from etmpc import systems
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.loop import Trajectory
from etmpc.systems.base import DERIVED, REQUIRED, Benchmark, SystemBase
from etmpc.systems.capabilities import (
    CAPABILITIES,
    Bench,
    Experiments,
    ExogenousFeatures,
    Failures,
    Rollouts,
    Scene,
    members,
    offers,
)
from etmpc.systems.registry import BUILT_IN


def test_a_task_writes_at_most_twelve_members():
    assert len(REQUIRED) <= 12
    assert not set(REQUIRED) & set(DERIVED)


@pytest.mark.parametrize("name", systems.names())
def test_every_task_has_the_required_members_and_the_derived_ones(name):
    system = systems.make_system(name)
    assert isinstance(system, SystemBase)
    assert [m for m in REQUIRED + DERIVED if not hasattr(system, m)] == []
    assert systems.canonical(f"{system.domain}/{system.task}") == system.name == type(system).name == name
    assert system.horizon >= 1 and system.episode_steps >= system.horizon
    assert system.u_min.shape == system.u_max.shape == (len(system.input_names),)
    assert system.error_weights.shape == (len(system.state_names),)
    assert system.objective_sense in ("min", "max")


@pytest.mark.parametrize("name", systems.names())
def test_what_a_task_offers_works_as_its_capability_says(name):
    """Each capability the task offers (not None) is checked by what it does; one it does not offer is None."""
    system = systems.make_system(name)
    offered = {capability for capability in CAPABILITIES if offers(system, capability)}
    for capability in set(CAPABILITIES) - offered:
        assert all(getattr(system, m) is None for m in members(capability)), capability
    episode = system.draw_episode(np.random.default_rng(0))
    if Rollouts in offered:  # redrawn from the generator alone, the episode given left as it was
        before = {k: np.array(v) for k, v in episode.arrays().items()}
        a, b = (system.sample_future(episode, 5, np.random.default_rng(1)) for _ in range(2))
        assert all(np.array_equal(a.arrays()[k], b.arrays()[k]) for k in before)
        assert all(np.array_equal(before[k], v) for k, v in episode.arrays().items())
        assert {k: np.shape(v) for k, v in a.arrays().items()} == {k: v.shape for k, v in before.items()}
    if Scene in offered:
        physics = system.make_env().physics
        assert physics.model.name2id(system.camera, "camera") >= 0
    if Failures in offered:  # counted from what an episode played: none before its first step
        assert isinstance(system.failure_name, str) and system.failure_name
        unplayed = Trajectory.empty(system.episode_steps, len(system.state_names), len(system.input_names))
        assert system.failures(unplayed, episode) == 0
    if Experiments in offered:
        assert isinstance(system.benchmark, Benchmark) and system.benchmark.lookahead >= 1
    if ExogenousFeatures in offered:
        assert len(system.exogenous_feature_names) >= 1
    if Bench in offered and system.interpreted is not None:
        assert type(system.interpreted()) is type(system)


@pytest.mark.parametrize("name", [n for n in systems.names() if n.split("/")[0] in BUILT_IN])
def test_every_built_in_task_counts_its_failures(name):
    """Every task of etmpc's own reports failures beside its objective (docs/scorecard.md#failures says
    what each counts); a plugin's task may offer none."""
    assert offers(systems.make_system(name), Failures)


def test_a_missing_capability_is_one_line_naming_the_task_and_what_needs_it():
    from etmpc.systems.capabilities import require

    class Bare(SystemBase):
        domain, task = "cart_pendulum", "balance"

    with pytest.raises(EtmpcError, match="etmpc sweep needs rollouts .sample_future., which task cart_pendulum/balance does not"):
        require(Bare(), Rollouts, "etmpc sweep")


@pytest.mark.parametrize("domain", list(systems.domains()))
def test_a_domain_names_the_same_tasks_in_its_registry_entry_its_suite_and_its_systems(domain):
    package = systems.domain(domain)
    assert tuple(package.SUITE) == package.TASKS == tuple(package.SYSTEMS)
    assert set(package.TEST_SET_SEEDS) == set(package.TASKS)
    for task, cls in package.SYSTEMS.items():
        assert (cls.domain, cls.task) == (domain, task)


def test_keys_name_a_task_by_its_id_and_carry_a_price():
    assert systems.system_key("cart_pendulum/balance") == systems.system_key("cart_pendulum")
    assert str(systems.system_key("cart_pendulum")) == "cart_pendulum/balance"
    key = systems.system_key("battery", 0.001)
    assert (key.task, key.recompute_price, str(key)) == ("battery/trading", 0.001, "battery/trading@0.001")
    assert key.make().recompute_price == 0.001 and systems.make_system(key).recompute_price == 0.001
    assert pickle.loads(pickle.dumps(key)) == key and hash(key) == hash(systems.SystemKey("battery", 0.001))
    for bad in (-1.0, float("nan"), float("inf"), "0.1", True):
        with pytest.raises(EtmpcError, match="recompute_price: "):
            systems.SystemKey("battery", bad)
    for bad in ("cartpole", "cart_pendulum/swing", "battery/balance", "", "battery@0.001"):
        with pytest.raises(
            UnknownNameError,
            match="valid: cart_pendulum/balance, cart_pendulum/kicks, cart_pendulum/kicks_late, cart_pendulum/kicks_levels, "
            "cart_pendulum/kicks_noisy, battery/trading, reacher/jumps, reacher/jumps_late, quadrotor/waypoints, "
            "quadrotor/waypoints_noisy",
        ):
            systems.check_name(bad)


def test_a_rollouts_lookahead_is_capped_by_the_task():
    """The kicks task and the reacher ask for a 10-step lookahead; the rollout meter, DPI's labels and
    the sweep take it, and the paper's tasks keep the default 20."""
    from etmpc.experiments.sweep import SweepSettings

    benchmark = systems.make_system("cart_pendulum/kicks").benchmark
    assert benchmark.lookahead == 10
    assert (benchmark.capped(None), benchmark.capped(5), benchmark.capped(20)) == (10, 5, 10)
    assert SweepSettings.default("cart_pendulum/kicks").horizon == 10
    assert SweepSettings.default("cart_pendulum/kicks").learner.config("cart_pendulum/kicks", 0.1).dpi.horizon == 10
    assert SweepSettings.default("reacher").horizon == 10
    assert SweepSettings.default("cart_pendulum").horizon == SweepSettings.default("battery").horizon == 20
