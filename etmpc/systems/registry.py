"""The registry of tasks: etmpc's own domains and those of other installed packages, found by name.

A *domain* is a package (``etmpc/systems/cart_pendulum/``, or a plugin's own) that names

* ``TASKS``: its tasks, the default first. Importing the package stays light: no MuJoCo or
  dm-control, which pick their OpenGL backend on import;
* ``TEST_SET_SEEDS``: task -> the seed its stored test set was drawn from (``etmpc testset``);
* ``SUITE`` and ``SYSTEMS`` (loaded when first asked): its dm-control task factories, as a
  ``dm_control.suite`` domain has them, and task -> the :class:`~etmpc.systems.base.System` class
  the control loop plays;
* optionally ``DATA``: the folder of its stored test sets and references, one folder per task in it
  (default: etmpc's ``tasks/<domain>/``, so ``tasks/<domain>/<task>/``);
* optionally ``VERSIONS``: task -> its version, where it is not 0 (what bumps it: ``docs/versioning.md``);
  it is the ``-vN`` of the task's environment id and is carried by every score made on it.

:data:`BUILT_IN` lists etmpc's domains; another package adds one with an entry point in the
``etmpc.tasks`` group (``slider = "etmpc_slider"``: the domain's name and its package), read once when
first asked. :mod:`etmpc.systems.discovery` finds them (a plugin that fails to import, or does not name its
tasks, is left out with one warning line); this module names and makes the tasks inside them.

Each task has a :class:`TaskSpec`, from which every surface derives its name: the id ``DOMAIN/TASK``
(``DOMAIN`` alone names its domain's first task), the Gymnasium id ``etmpc/DOMAIN-TASK-vN``, the folder
``DOMAIN/TASK``. A :class:`SystemKey` is a task at a
price of a recompute, made and checked once at the edge and passed as a value: every worker builds
the same system from it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

from etmpc.common import checks
from etmpc.common.errors import EtmpcError, UnknownNameError

# The domains, found by name (etmpc.systems.discovery), are read here too: BUILT_IN, lazy and data_dir as a
# domain's package and a plugin name them.
from etmpc.systems.discovery import BUILT_IN, ENTRY_POINTS, data_dir, domain, domains, lazy  # noqa: F401


class SystemClass(Protocol):
    """A task's :class:`~etmpc.systems.base.System` class as it is read before a system is built (the registry, the
    catalogue): its ``Config``, its episode as its suite entry declares it, and the system it builds from a Config."""

    Config: type
    episode_steps: int
    control_interval_s: float

    def __call__(self, config: Any) -> Any: ...


class TaskNameDeprecation(FutureWarning):
    """A task named the way an older etmpc named it (``DOMAIN-TASK``, its old folder): still taken, for one
    release, with one warning line naming the new id."""


@dataclass(frozen=True)
class TaskSpec:
    """One task of the suite, as :mod:`gymnasium.envs.registration`'s ``EnvSpec`` is one environment: every
    name a surface shows is derived from it, mechanically.

    * :attr:`id`, ``DOMAIN/TASK``: the command line's (which takes ``DOMAIN`` alone for the domain's first
      task), the API's, the score cards' and the leaderboard's;
    * :attr:`gym_id`, ``etmpc/DOMAIN-TASK-vN``: the Gymnasium environment's;
    * :attr:`folder`, ``DOMAIN/TASK``: the folder under ``tasks/`` (its test set, references and benchmark)
      and under ``policies/`` (its shipped policies), and of its results in an output directory;
    * :attr:`slug`, ``DOMAIN-TASK``: the task in one file name, where a folder will not do.
    """

    domain: str
    task: str
    version: int = 0  # what bumps it: docs/versioning.md
    default: bool = False  # the domain's first task: the one ``DOMAIN`` alone names

    @property
    def id(self) -> str:
        return f"{self.domain}/{self.task}"

    @property
    def gym_id(self) -> str:
        return f"etmpc/{self.slug}-v{self.version}"

    @property
    def folder(self) -> str:
        return self.id

    @property
    def slug(self) -> str:
        return f"{self.domain}-{self.task}"

    @property
    def system_class(self) -> SystemClass:
        """The :class:`~etmpc.systems.base.System` class the control loop plays (its entry point)."""
        return domain(self.domain).SYSTEMS[self.task]

    def data_file(self, kind: str) -> Path:
        """The task's stored ``kind`` file (``testset.npz``, ``references.json``, ``benchmark.json``) in its
        folder of its domain's data, ``tasks/DOMAIN/TASK/``. A plugin's data laid out as an older etmpc laid
        it out (``DATA/TASK_KIND``) is read, for one release, with one :class:`TaskNameDeprecation` line."""
        path = data_dir(self.domain) / self.task / kind
        old = data_dir(self.domain) / f"{self.task}_{kind}"
        if not path.exists() and old.exists():
            warnings.warn(f"etmpc: {old} is laid out as an older etmpc's: move it to {path}", TaskNameDeprecation, stacklevel=2)
            return old
        return path

    def make(self, recompute_price: float | None = None):
        """The system, built from the task's ``Config()`` (at ``recompute_price`` if given): the one place a
        system is made (:meth:`SystemKey.make`)."""
        return SystemKey(self.id, recompute_price).make()

    def __str__(self) -> str:
        return self.id


def _specs() -> dict[str, TaskSpec]:  # made anew each time (a few records): a plugin installed later joins
    found = {}
    for domain_name, package in domains().items():
        for index, task in enumerate(package.TASKS):
            found[f"{domain_name}/{task}"] = TaskSpec(domain_name, task, _version(domain_name, task), index == 0)
    return found


def specs() -> tuple[TaskSpec, ...]:
    """Every task's spec, domain by domain, each domain's first task first."""
    return tuple(_specs().values())


def names() -> tuple[str, ...]:
    """Every task's id, ``DOMAIN/TASK``, in the registry's order."""
    return tuple(_specs())


def spec(name: str | TaskSpec) -> TaskSpec:
    """The spec of task ``name``: its id ``DOMAIN/TASK``, or ``DOMAIN`` for the domain's first task. An older
    etmpc's ``DOMAIN-TASK`` is taken with one :class:`TaskNameDeprecation` line; anything else is an
    :class:`UnknownNameError` listing the valid ids."""
    if isinstance(name, TaskSpec):
        return name
    known = _specs()
    if not isinstance(name, str):
        raise UnknownNameError(f"a task is named by a string, not {type(name).__name__}; valid: {', '.join(known)}")
    if name in known:
        return known[name]
    package = domains().get(name)
    if package is not None:
        return known[f"{name}/{package.TASKS[0]}"]
    old = next((s for s in known.values() if name == s.slug), None)
    if old is not None:
        warnings.warn(f"etmpc: task name {name!r} is deprecated: say {old.id!r}", TaskNameDeprecation, stacklevel=2)
        return old
    raise UnknownNameError(f"unknown task {name!r}; valid: {', '.join(known)}")


def parse(name: str) -> tuple[str, str]:
    """``(domain, task)`` of a task name (see :func:`spec`)."""
    found = spec(name)
    return found.domain, found.task


def check_name(name: str) -> None:
    """Raise :class:`UnknownNameError`, listing the valid names, unless ``name`` is a known task."""
    spec(name)


def canonical(name: str) -> str:
    """Task ``name``'s id, ``DOMAIN/TASK``, however it was named."""
    return spec(name).id


def same_task(a, b) -> bool:
    """Whether ``a`` and ``b`` name the same task, however each is named (a file of an older etmpc says
    ``quadrotor`` where one of today's says ``quadrotor/waypoints``); a name of no task is no match."""
    try:
        return isinstance(a, str) and isinstance(b, str) and spec(a) == spec(b)
    except UnknownNameError:
        return False


def distinct(names_given) -> list[str]:
    """The tasks named, as ids, each once: a task named twice (even as ``battery`` and
    ``battery/trading``) is refused, naming it; an unknown name is refused, listing the valid ones."""
    tasks: list[str] = []
    for name in names_given:
        task = canonical(name)
        if task in tasks:
            raise EtmpcError(f"task {task} is given twice")
        tasks.append(task)
    return tasks


def folder_name(name: str) -> str:
    """Task ``name``'s folder, relative: ``DOMAIN/TASK`` (:attr:`TaskSpec.folder`)."""
    return spec(name).folder


def _version(domain_name: str, task: str) -> int:
    version = getattr(domain(domain_name), "VERSIONS", {}).get(task, 0)
    if not (isinstance(version, int) and not isinstance(version, bool) and version >= 0):
        raise EtmpcError(f"domain {domain_name!r} gives task {task!r} the version {version!r}, not a whole number >= 0")
    return version


def task_version(name: str) -> int:
    """Task ``name``'s version: its domain's ``VERSIONS`` entry, 0 if it names none."""
    return spec(name).version


def stored_seed(name: str) -> int | None:
    """The seed task ``name``'s stored test set was drawn from (None if its domain does not say)."""
    domain_name, task = parse(name)
    return domain(domain_name).TEST_SET_SEEDS.get(task)


def has_levels(name: str) -> bool:
    """Whether task ``name``'s decisions are compute levels (keep, one SQP iteration, a full solve: its
    Config's ``compute_levels``, a bool as the system checks it), read off the Config class without building the system."""
    return checks.argument("compute_levels", checks.flag, getattr(system_class(name).Config, "compute_levels", False))


def system_class(name: str) -> SystemClass:
    """The :class:`~etmpc.systems.base.System` class of task ``name`` (:attr:`TaskSpec.system_class`)."""
    return spec(name).system_class


@dataclass(frozen=True)
class SystemKey:
    """A task (its canonical name) at a price of a recompute (``None``: the task's own) and with its
    ``options`` (fields of its Config set by name: :mod:`etmpc.systems.options`; a mapping, or
    ``(name, value)`` pairs), checked when made and kept canonical (sorted ``(name, text)`` pairs).
    ``str(key)`` is how files and messages show it: ``DOMAIN[/TASK]``, ``@PRICE`` when priced, the options
    as the command line writes them."""

    task: str
    recompute_price: float | None = None
    options: tuple[tuple[str, str], ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "task", canonical(self.task))
        if self.recompute_price is not None:
            object.__setattr__(self, "recompute_price", checks.argument("recompute_price", checks.price, self.recompute_price))
        if self.options:
            from etmpc.systems.options import normalised

            object.__setattr__(self, "options", normalised(system_class(self.task).Config(), self.options))
        else:
            object.__setattr__(self, "options", ())

    def __str__(self) -> str:
        shown = self.task if self.recompute_price is None else f"{self.task}@{self.recompute_price!r}"
        if self.options:
            from etmpc.systems.options import shown as written

            shown = f"{shown} {written(self.options)}"
        return shown

    def make(self):
        """The system: the task's class built from its ``Config()``, at this price if one is set. Its time in
        the loop (``latency``, ``compute_levels``) is read, and so checked, here: a bad Config is refused when
        the system is made, not in the middle of an episode."""
        cls = system_class(self.task)
        config = cls.Config()
        if self.recompute_price is not None:
            config = replace(config, recompute_price=self.recompute_price)
        if self.options:
            from etmpc.systems.options import apply

            config = apply(config, self.options)
        system = cls(config)
        from etmpc.systems.options import check_together

        check_together(system)
        system.estimator  # noqa: B018 (read, and so checked, now: a sensor the task cannot filter is refused here)
        latency, levels = system.latency, system.compute_levels  # read, and so checked, now
        if not latency.instant or levels:
            from etmpc.systems.capabilities import TimeInTheLoop, require

            require(system, TimeInTheLoop, "time in the loop (a Config's latency or compute_levels)")
        return system


def system_key(name: str | SystemKey, recompute_price: float | None = None, options=()) -> SystemKey:
    """The key of task ``name`` at ``recompute_price`` (None: the task's own) with ``options`` (none by
    default); a key is returned as it is."""
    if isinstance(name, SystemKey):
        if recompute_price is not None or options:
            raise TypeError("give a task's name with a price and options, or a SystemKey alone")
        return name
    return SystemKey(name, recompute_price, options)  # a mapping or pairs: the key writes them canonically


def make_system(key: str | SystemKey):
    """The system of ``key``: a :class:`SystemKey`, or a task's name at its own price."""
    return system_key(key).make()
