"""The suite as a catalogue: per task, what a newcomer looks up first (its id, its Gymnasium id with its
version, its episode's length, the price of a recompute, its options), read from the registry and nothing else.

``etmpc tasks`` prints it; the docs' task lists, tables of ids and counts of tasks are generated from it
(``<!-- generated: etmpc.systems.catalogue:NAME -->`` markers, ``scripts/doc_numbers.py``), so that a page
cannot name a task, an id or a version the registry does not have. A plugin's tasks are listed as etmpc's own.

This module may import what :mod:`etmpc.systems.registry` imports; building a task's Config loads no MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass

from etmpc.systems.registry import BUILT_IN, TaskSpec, specs

_WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten", "eleven", "twelve")


@dataclass(frozen=True)
class Entry:
    """One task of the catalogue."""

    spec: TaskSpec
    episode_steps: int
    control_interval_s: float
    recompute_price: float
    options: tuple[str, ...]  # every option's dotted name (``etmpc options --task TASK`` gives the details)

    @property
    def episode_s(self) -> float:
        return self.episode_steps * self.control_interval_s


def entry(spec: TaskSpec) -> Entry:
    """The catalogue's entry of one task: its System class and default Config, read, not built."""
    from etmpc.systems.options import settable

    cls = spec.system_class
    config = cls.Config()
    return Entry(
        spec, int(cls.episode_steps), float(cls.control_interval_s), float(config.recompute_price), tuple(settable(config))
    )


def entries(own: bool = False) -> tuple[Entry, ...]:
    """Every task of the registry, in its order (domain by domain, each domain's first task first); ``own``:
    etmpc's own tasks only, not an installed plugin's (what the docs describe)."""
    return tuple(entry(spec) for spec in (_own() if own else specs()))


def _own() -> tuple[TaskSpec, ...]:
    return tuple(spec for spec in specs() if spec.domain in BUILT_IN)


def grouped(names: tuple[str, ...]) -> str:
    """Option names with a shared prefix written once: ``horizon, sensor.{noise_std, bias}``."""
    groups: dict[str, list[str]] = {}
    for name in names:
        head, dot, rest = name.partition(".")
        groups.setdefault(head if dot else name, []).append(rest if dot else "")
    return ", ".join(head if parts == [""] else f"{head}.{{{', '.join(parts)}}}" for head, parts in groups.items())


def in_words(count: int) -> str:
    """A count as a page writes it: ``ten``, ``14``."""
    return _WORDS[count] if count < len(_WORDS) else str(count)


# -- the docs' generated text: each a function of no argument, its text what the page shows. The docs describe
# etmpc's own suite: an installed plugin's tasks are not in them.
def task_count() -> str:
    """How many tasks etmpc's suite has, in words (``ten``)."""
    return in_words(len(_own()))


def domain_count() -> str:
    """How many domains etmpc's suite has, in words."""
    return in_words(len({spec.domain for spec in _own()}))


def task_ids() -> str:
    """Every task's id, in code: ```cart_pendulum/balance`, `cart_pendulum/kicks`, ...``."""
    return ", ".join(f"`{spec.id}`" for spec in _own())


def domain_names() -> str:
    """Every domain's name, in code (the domain alone names its first task)."""
    return ", ".join(f"`{name}`" for name in dict.fromkeys(spec.domain for spec in _own()))


def gym_ids_table() -> str:
    """A Markdown table of every task's Gymnasium id, with its episode and price."""
    rows = ["| task | Gymnasium id | episode | price of a recompute |", "|---|---|---|---|"]
    for e in entries(own=True):
        episode = f"{e.episode_steps} steps of {e.control_interval_s:g} s ({e.episode_s:g} s)"
        rows.append(f"| `{e.spec.id}` | `{e.spec.gym_id}` | {episode} | {e.recompute_price:g} |")
    return "\n".join(rows)


def _weight(w: float) -> str:
    """One entry of ``threshold:X``'s W as a page writes it: ``1``, ``√10``."""
    return f"{w:g}" if float(w).is_integer() else f"√{round(w * w, 6):g}"


def threshold_weights() -> str:
    """``threshold:X``'s weights W per task (the built systems' ``error_weights``), tasks with the same W together."""
    found: dict[str, list[str]] = {}
    for spec in _own():
        weights = [_weight(w) for w in spec.make().error_weights]
        shown = weights[0] if len(weights) == 1 else f"diag({', '.join(weights)})"
        found.setdefault(shown, []).append(f"`{spec.id}`")
    return "; ".join(f"`{shown}` on {', '.join(tasks)}" for shown, tasks in found.items())
