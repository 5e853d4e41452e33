"""What each registered task provides (etmpc.systems.base.FEATURES), and the registry's names."""

import pytest

from etmpc import systems
from etmpc.common.errors import UnknownNameError
from etmpc.systems.base import FEATURES, REQUIRED, provides

# What each task offers beyond the required features. A new task adds its line here, and
# docs/adding-a-task.md says what each feature needs.
OPTIONAL = {
    "cart_pendulum": {"render", "bench"},
    "cart_pendulum/kicks": {"exogenous features", "render", "bench", "failures"},
    "battery": {"exogenous features", "bench"},
    "reacher": {"exogenous features", "render", "bench", "failures"},
}


@pytest.mark.parametrize("name", systems.names())
def test_every_task_provides_the_required_features_and_says_which_optional_ones(name):
    system = systems.make_system(name)
    missing = {feature: [m for m in FEATURES[feature] if not hasattr(system, m)] for feature in REQUIRED}
    assert {f: m for f, m in missing.items() if m} == {}
    offered = {feature for feature in FEATURES if feature not in REQUIRED and provides(system, feature)}
    assert offered == OPTIONAL[name]
    assert systems.canonical(f"{system.domain}/{system.task}") == system.name == name
    assert system.horizon >= 1 and system.episode_steps >= system.horizon


@pytest.mark.parametrize("domain", list(systems.DOMAINS))
def test_a_domain_names_the_same_tasks_in_its_registry_entry_its_suite_and_its_systems(domain):
    package = systems.domain(domain)
    assert tuple(package.SUITE) == package.TASKS == tuple(package.SYSTEMS)
    for task, cls in package.SYSTEMS.items():
        assert (cls.domain, cls.task) == (domain, task)


def test_keys_name_the_default_task_by_its_domain_and_carry_a_price():
    assert systems.system_key("cart_pendulum/balance") == systems.system_key("cart_pendulum") == "cart_pendulum"
    assert systems.system_key("battery", 0.001) == "battery@0.001"
    assert systems.make_system("battery@0.001").recompute_price == 0.001
    for bad in ("cartpole", "cart_pendulum/swing", "battery/balance", ""):
        with pytest.raises(UnknownNameError, match="valid: cart_pendulum, cart_pendulum/kicks, battery, reacher"):
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
