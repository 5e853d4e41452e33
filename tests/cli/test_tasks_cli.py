"""``etmpc tasks`` lists the suite as the registry has it: every task's id, Gymnasium id with its version,
episode length and price of a recompute, and every one of its options' names (as ``etmpc options`` lists them)."""

import re

from etmpc.cli import main
from etmpc.systems import registry
from etmpc.systems.catalogue import grouped
from etmpc.systems.options import settable


def _printed(capsys) -> str:
    assert main(["tasks"]) == 0
    return capsys.readouterr().out


def test_every_task_of_the_registry_is_a_row_with_its_gym_id_episode_and_price(capsys):
    out = _printed(capsys)
    found = registry.specs()
    assert out.splitlines()[0].startswith(f"{len(found)} tasks")
    for spec in found:
        cls = spec.system_class
        (row,) = [line for line in out.splitlines() if line.split()[:1] == [spec.id]]
        seconds = cls.episode_steps * cls.control_interval_s
        words = row.split()
        assert spec.gym_id in words and spec.gym_id.endswith(f"-v{registry.task_version(spec.id)}")
        assert f"{cls.episode_steps} x {cls.control_interval_s:g} s = {seconds:g} s" in row
        assert float(words[-1]) == cls.Config().recompute_price
        assert ("*" in words) == (registry.spec(spec.domain) == spec)  # the task the domain alone names


def test_every_option_name_is_listed_for_its_task(capsys):
    text = " ".join(_printed(capsys).split())
    for spec in registry.specs():
        names = tuple(settable(spec.system_class.Config()))
        assert f"{spec.id}: {grouped(names)}" in text
    # and the grouping loses no name: each dotted name comes back from its group
    names = ("horizon", "sensor.noise_std", "sensor.bias", "market.price.ou_std")
    back = []
    for part in re.findall(r"(\w+)\.\{([^}]*)\}|(\w+)", grouped(names)):
        back += [f"{part[0]}.{rest}" for rest in part[1].split(", ")] if part[0] else [part[2]]
    assert back == list(names)


def test_the_tasks_the_command_line_takes_are_the_listed_ones(capsys):
    listed = {line.split()[0] for line in _printed(capsys).splitlines()[2:] if "etmpc/" in line}
    assert listed == set(registry.names())
    for name in listed:  # each one --task takes
        assert main(["options", "--task", name]) == 0
    capsys.readouterr()
