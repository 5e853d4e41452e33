"""The System protocol (etmpc.systems.protocol) lists what the rest of etmpc reads of a system: exactly the
members REQUIRED, DERIVED, SETTINGS and OPTIONAL name, each named once, with every capability's members
among the optional ones; and the docs count the members a task writes as REQUIRED does."""

import re

import pytest

from etmpc.common.errors import EtmpcError
from etmpc.systems.base import SystemBase
from etmpc.systems.capabilities import CAPABILITIES, members
from etmpc.systems.protocol import DERIVED, OPTIONAL, REQUIRED, SETTINGS, System
from tests.conftest import REPO

NUMBERS = ("zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen fifteen").split()


def _protocol_members(protocol: type) -> set[str]:
    declared = set(vars(protocol).get("__annotations__", {})) | set(vars(protocol))
    return {name for name in declared if not name.startswith("_")}


def test_the_protocol_lists_exactly_what_the_four_tuples_name_each_once():
    named = REQUIRED + DERIVED + SETTINGS + OPTIONAL
    assert len(named) == len(set(named))
    assert _protocol_members(System) == set(named)


def test_every_capability_is_optional_and_every_member_is_on_system_base():
    assert {m for capability in CAPABILITIES for m in members(capability)} <= set(OPTIONAL)
    on_base = {name for cls in SystemBase.__mro__ for name in (*vars(cls), *vars(cls).get("__annotations__", {}))}
    assert [m for m in REQUIRED + DERIVED + SETTINGS + OPTIONAL if m not in on_base] == []


def test_the_docs_count_the_members_a_task_writes_as_required_does():
    """architecture.md once said "eleven members" where REQUIRED had eight."""
    word = NUMBERS[len(REQUIRED)]
    architecture = (REPO / "docs" / "architecture.md").read_text()
    adding = (REPO / "docs" / "adding-a-task.md").read_text()
    assert re.search(rf"writes the {word} members `etmpc\.systems\.base\.REQUIRED`", architecture)
    assert f"writes {word} members** (`etmpc.systems.base.REQUIRED`)" in adding
    assert not re.search(r"\b(\w+) members of `etmpc\.systems\.base\.System`", architecture)


def test_system_type_gives_the_registered_class_and_refuses_one_that_is_not_a_system_base(monkeypatch):
    """``system_type`` is the registry's class, typed as a SystemBase; a registered class that does not
    subclass it is refused in one line naming the task (not an AssertionError met later)."""
    from etmpc.systems import base, registry

    assert base.system_type("cart_pendulum/kicks") is registry.system_class("cart_pendulum/kicks")
    monkeypatch.setattr(registry, "system_class", lambda task: dict)
    with pytest.raises(EtmpcError, match="'quadrotor/waypoints'.*does not subclass etmpc.systems.base.SystemBase"):
        base.system_type("quadrotor/waypoints")
