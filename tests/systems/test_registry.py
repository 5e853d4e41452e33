"""The registries of tasks and policy kinds: etmpc's own entries, and other packages' through entry points
(``etmpc.tasks``, ``etmpc.policies``). Plugins here are modules written into a temporary folder and
announced by fake entry points; tests/end_to_end/test_plugin_package.py installs a real one into a virtual environment."""

import sys
import textwrap
import warnings
from importlib.metadata import EntryPoint
from types import SimpleNamespace

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.policies import specs
from etmpc.systems import discovery, registry

# What parse_policy reads of a system, for kinds that need no real one.
TASK = SimpleNamespace(error_weights=np.ones(4), name="cart_pendulum", episode_steps=100)


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """``install(group, name, value, source=None)``: announce an entry point (writing ``source`` as the
    module it names); the registries are read afresh, and again after the test."""
    announced: dict[str, list[EntryPoint]] = {}

    def fake_entry_points(group):
        return announced.get(group, [])

    def install(group: str, name: str, value: str, source: str | None = None):
        if source is not None:
            (tmp_path / f"{value.partition(':')[0]}.py").write_text(textwrap.dedent(source))
        announced.setdefault(group, []).append(EntryPoint(name, value, group))
        registry.domains.cache_clear()
        specs.kinds.cache_clear()

    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(discovery, "entry_points", fake_entry_points)
    monkeypatch.setattr(specs, "entry_points", fake_entry_points)
    yield install
    registry.domains.cache_clear()
    specs.kinds.cache_clear()
    for name in [m for m in sys.modules if m.startswith("fake_")]:
        del sys.modules[name]


TWIN = """
    from etmpc.systems.cart_pendulum import SUITE as _SUITE, TEST_SET_SEEDS as _SEEDS
    from etmpc.systems.cart_pendulum.system import CartPendulumSystem
    from etmpc.systems.registry import data_dir

    class TwinSystem(CartPendulumSystem):
        domain = "twin"

    TASKS = ("balance",)
    TEST_SET_SEEDS = {"balance": _SEEDS["balance"]}
    DATA = data_dir("cart_pendulum")
    SYSTEMS = {"balance": TwinSystem}
    SUITE = _SUITE
"""


def test_a_task_plugin_joins_the_registry_the_suite_and_gymnasium(plugins):
    plugins("etmpc.tasks", "twin", "fake_twin", TWIN)
    assert registry.names() == (
        "cart_pendulum/balance",
        "cart_pendulum/kicks",
        "cart_pendulum/kicks_late",
        "cart_pendulum/kicks_levels",
        "cart_pendulum/kicks_noisy",
        "battery/trading",
        "reacher/jumps",
        "reacher/jumps_late",
        "quadrotor/waypoints",
        "quadrotor/waypoints_noisy",
        "twin/balance",
    )
    system = registry.make_system(registry.SystemKey("twin/balance", 0.5))
    seed = registry.stored_seed("twin")
    assert (system.name, system.domain, system.recompute_price, seed) == ("twin/balance", "twin", 0.5, 20210601)
    assert registry.data_dir("twin") == registry.data_dir("cart_pendulum")
    from etmpc import suite
    from etmpc.envs.registration import register

    assert "twin" in suite.domains() and suite.load("twin", "balance", task_kwargs={"random": 0}).reset().first()
    import gymnasium

    try:
        assert "etmpc/twin-balance-v0" in register()
    finally:
        gymnasium.registry.pop("etmpc/twin-balance-v0", None)


@pytest.mark.parametrize(
    "source, problem",
    [
        ("raise ImportError('no such plant')", "failed to import (ImportError: no such plant)"),
        ("TASKS = []\nTEST_SET_SEEDS = {}", "its TASKS is not a non-empty tuple of task names"),
        ("TASKS = ('a/b',)\nTEST_SET_SEEDS = {}", "its TASKS is not a non-empty tuple of task names"),
        ("TASKS = ('track',)\nTEST_SET_SEEDS = {'other': 1}", "its TEST_SET_SEEDS is not a dict of its tasks' seeds"),
    ],
)
def test_a_broken_task_plugin_is_one_warning_naming_it_and_every_other_task_still_works(plugins, source, problem):
    plugins("etmpc.tasks", "broken", "fake_broken", source)
    with pytest.warns(RuntimeWarning) as caught:
        names = registry.names()
    assert [str(w.message) for w in caught] == [f"etmpc: task plugin 'broken' (fake_broken) {problem}; its tasks are left out"]
    assert names == (
        "cart_pendulum/balance",
        "cart_pendulum/kicks",
        "cart_pendulum/kicks_late",
        "cart_pendulum/kicks_levels",
        "cart_pendulum/kicks_noisy",
        "battery/trading",
        "reacher/jumps",
        "reacher/jumps_late",
        "quadrotor/waypoints",
        "quadrotor/waypoints_noisy",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # read once: no second warning
        assert registry.make_system("battery").name == "battery/trading"
    with pytest.raises(
        UnknownNameError,
        match="valid: cart_pendulum/balance, cart_pendulum/kicks, cart_pendulum/kicks_late, cart_pendulum/kicks_levels, "
        "cart_pendulum/kicks_noisy, battery/trading, reacher/jumps, reacher/jumps_late, quadrotor/waypoints, "
        "quadrotor/waypoints_noisy",
    ):
        registry.check_name("broken")


def test_a_task_plugin_may_not_take_a_built_in_domains_name(plugins):
    plugins("etmpc.tasks", "battery", "fake_twin", TWIN)
    with pytest.warns(RuntimeWarning, match="'battery' .fake_twin. names a domain etmpc already has"):
        assert registry.system_class("battery").__name__ == "BatterySystem"


KIND = """
    from etmpc.policies.fixed import Every
    from etmpc.policies.specs import Kind

    def build(arg, spec, context):
        return Every(2 * int(arg))

    KIND = Kind("twice", "twice:T", "recompute every 2 T steps", build, family="periodic")
    NOT_A_KIND = "twice"
"""


def test_a_policy_kind_plugin_is_parsed_listed_in_the_help_and_scored_as_its_kind(plugins):
    plugins("etmpc.policies", "twice", "fake_kind:KIND", KIND)
    policy = specs.parse_policy("twice:2", TASK)
    assert policy.period == 4
    assert specs.syntax().endswith("oracle:BASE | twice:T")
    assert specs.kind_of("twice:2").family == "periodic" and not specs.kind_of("twice:2").clairvoyant
    assert specs.names_a_kind("twice:9")
    from etmpc.cli.options import build_parser

    assert "rollout:BASE[:K[:H]] | oracle:BASE | twice:T (repeatable" in _evaluate_help(build_parser())
    with pytest.raises(UnknownNameError, match=r"valid: always \| never .* oracle:BASE \| twice:T$"):
        specs.parse_policy("thrice:2", TASK)


def _evaluate_help(parser) -> str:
    import argparse

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return " ".join(sub.choices["evaluate"].format_help().split())


@pytest.mark.parametrize(
    "name, value, problem",
    [
        ("twice", "fake_kind:NOT_A_KIND", "is not an etmpc.policies.specs.Kind"),
        ("thrice", "fake_kind:KIND", "names its kind 'twice', not 'thrice'"),
        ("every", "fake_kind:KIND", "names its kind 'twice', not 'every'"),
        ("twice", "fake_kind:MISSING", "failed to load (AttributeError: module 'fake_kind' has no attribute 'MISSING')"),
    ],
)
def test_a_broken_policy_kind_plugin_is_one_warning_and_the_built_in_kinds_still_work(plugins, name, value, problem):
    plugins("etmpc.policies", name, value, KIND)
    with pytest.warns(RuntimeWarning) as caught:
        kinds = specs.kinds()
    assert [str(w.message) for w in caught] == [f"etmpc: policy kind plugin {name!r} ({value}) {problem}; left out"]
    assert list(kinds) == [kind.name for kind in specs.BUILT_IN]
    assert specs.parse_policy("every:3", TASK).period == 3


def test_a_policy_kind_plugin_may_not_replace_a_built_in_kind(plugins):
    plugins("etmpc.policies", "every", "fake_every:KIND", KIND.replace('Kind("twice"', 'Kind("every"'))
    with pytest.warns(RuntimeWarning, match="'every' .fake_every:KIND. names a kind etmpc already has"):
        assert specs.parse_policy("every:3", TASK).period == 3


def test_every_spec_reader_asks_the_registry():
    """The kinds' flags drive what tables, figures and the sweep say of a spec."""
    from etmpc.experiments.pareto import short_name
    from etmpc.views.figures import is_clairvoyant

    assert [is_clairvoyant(s) for s in ("oracle:every:3", "rollout:every:3", "every:3", "my-own")] == [True, False, False, False]
    assert short_name("rl:runs/a/seed0/best.json") == "rl:seed0/best.json" and short_name("self:x/y.json") == "self:y.json"
    assert specs.parse_policy("oracle:every:3", TASK).clairvoyant
    assert not specs.parse_policy("rollout:every:3", TASK).clairvoyant
    with pytest.raises(EtmpcError, match="the base policy must not simulate"):
        specs.parse_policy("rollout:oracle:every:3", TASK)


# Plugins that are hostile rather than broken: their code exits, or raises what is not an Exception.
STOP = "class Stop(BaseException):\n    pass\n\nraise Stop('halt')"
HOSTILE_IMPORTS = [
    ("raise SystemExit(0)", "SystemExit(0)"),
    ("raise SystemExit('bye')", "SystemExit('bye')"),
    ("raise KeyboardInterrupt", "KeyboardInterrupt"),
    (STOP, "Stop: halt"),
    ("raise ValueError('two\\nlines')", "ValueError: two lines"),
    ("from etmpc.common.errors import EtmpcError\nraise EtmpcError('no licence')", "EtmpcError: no licence"),
]


@pytest.fixture
def no_ctrl_c(monkeypatch):
    """No Ctrl-C noted so far (another test's real one would make every KeyboardInterrupt count as one)."""
    from etmpc.common import interrupts

    monkeypatch.setattr(interrupts, "_received", 0)


@pytest.fixture
def a_terminal():
    """SIGINT as a terminal's command has it (Python's default handler): a background job of a shell
    without job control, as a CI runner may start the suite, ignores it and no Ctrl-C could arrive."""
    import signal

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize("source, raised", HOSTILE_IMPORTS)
def test_a_task_plugin_whose_import_exits_or_raises_anything_is_one_warning(plugins, no_ctrl_c, source, raised):
    plugins("etmpc.tasks", "hostile", "fake_hostile", source)
    with pytest.warns(RuntimeWarning) as caught:
        names = registry.names()
    assert [str(w.message) for w in caught] == [
        f"etmpc: task plugin 'hostile' (fake_hostile) failed to import ({raised}); its tasks are left out"
    ]
    assert names == (
        "cart_pendulum/balance",
        "cart_pendulum/kicks",
        "cart_pendulum/kicks_late",
        "cart_pendulum/kicks_levels",
        "cart_pendulum/kicks_noisy",
        "battery/trading",
        "reacher/jumps",
        "reacher/jumps_late",
        "quadrotor/waypoints",
        "quadrotor/waypoints_noisy",
    )
    assert registry.make_system("battery").name == "battery/trading"


@pytest.mark.parametrize("source, raised", HOSTILE_IMPORTS)
def test_a_policy_kind_plugin_whose_import_exits_or_raises_anything_is_one_warning(plugins, no_ctrl_c, source, raised):
    plugins("etmpc.policies", "hostile", "fake_hostile:KIND", source)
    with pytest.warns(RuntimeWarning) as caught:
        kinds = specs.kinds()
    assert [str(w.message) for w in caught] == [
        f"etmpc: policy kind plugin 'hostile' (fake_hostile:KIND) failed to load ({raised}); left out"
    ]
    assert list(kinds) == [kind.name for kind in specs.BUILT_IN]
    assert specs.parse_policy("every:3", TASK).period == 3


def test_a_real_ctrl_c_while_a_plugin_imports_still_interrupts(plugins, no_ctrl_c, a_terminal):
    plugins("etmpc.tasks", "slow", "fake_slow", "import os, signal, time\nos.kill(os.getpid(), signal.SIGINT)\ntime.sleep(5)")
    with pytest.raises(KeyboardInterrupt):
        registry.names()


BOOM = """
    from etmpc.common.errors import EtmpcError
    from etmpc.policies.specs import Kind

    class Stop(BaseException):
        pass

    def build(arg, spec, context):
        if arg == "div":
            return 1 / 0
        if arg == "etmpc":
            raise EtmpcError(f"bad policy {spec!r}: the plugin's own message")
        if arg == "real-ctrl-c":
            import os, signal, time
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        raise {"exit": SystemExit(3), "ctrl-c": KeyboardInterrupt(), "stop": Stop("halt\\nnow")}[arg]

    KIND = Kind("boom", "boom:HOW", "raises", build)
"""


@pytest.mark.parametrize(
    "spec, message",
    [
        ("boom:div", "bad policy 'boom:div': the 'boom' plugin (fake_boom:KIND) failed: ZeroDivisionError: division by zero"),
        ("boom:exit", "bad policy 'boom:exit': the 'boom' plugin (fake_boom:KIND) failed: SystemExit(3)"),
        ("boom:ctrl-c", "bad policy 'boom:ctrl-c': the 'boom' plugin (fake_boom:KIND) failed: KeyboardInterrupt"),
        ("boom:stop", "bad policy 'boom:stop': the 'boom' plugin (fake_boom:KIND) failed: Stop: halt now"),
        ("boom:etmpc", "bad policy 'boom:etmpc': the plugin's own message"),
        (
            "rollout:boom:div",
            "bad policy 'rollout:boom:div': bad policy 'boom:div': the 'boom' plugin (fake_boom:KIND) failed: "
            "ZeroDivisionError: division by zero",
        ),
    ],
)
def test_a_policy_kind_plugin_whose_builder_fails_is_one_error_naming_it(plugins, no_ctrl_c, spec, message):
    plugins("etmpc.policies", "boom", "fake_boom:KIND", BOOM)
    with pytest.raises(EtmpcError) as caught:
        specs.parse_policy(spec, TASK)
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)
    assert specs.parse_policy("every:3", TASK).period == 3


def test_a_real_ctrl_c_while_a_plugin_kind_builds_still_interrupts(plugins, no_ctrl_c, a_terminal):
    plugins("etmpc.policies", "boom", "fake_boom:KIND", BOOM)
    with pytest.raises(KeyboardInterrupt):
        specs.parse_policy("boom:real-ctrl-c", TASK)


def test_on_the_command_line_a_hostile_plugin_is_one_line_and_the_rest_works(plugins, no_ctrl_c, capsys):
    from etmpc.cli import main

    plugins("etmpc.tasks", "hostile", "fake_hostile", "raise SystemExit(0)")
    plugins("etmpc.policies", "boom", "fake_boom:KIND", BOOM)
    with pytest.warns(RuntimeWarning, match="'hostile' .fake_hostile. failed to import .SystemExit.0.."):
        assert main(["evaluate", "--task", "battery", "--policy", "boom:div", "--episodes", "1", "--workers", "1"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "etmpc: error: bad policy 'boom:div': the 'boom' plugin (fake_boom:KIND) failed: ZeroDivisionError: division by zero"
    ]
    assert main(["evaluate", "--task", "battery", "--policy", "every:3", "--episodes", "1", "--workers", "1"]) == 0
    assert "every:3" in capsys.readouterr().out
