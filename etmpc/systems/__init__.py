"""The tasks of the benchmark, and the registry that finds them by name (:mod:`etmpc.systems.registry`).

One folder per domain (``cart_pendulum/``, ``battery/``, ``reacher/``), registered by one line in
:data:`~etmpc.systems.registry.BUILT_IN`, or a package of someone else's announced by an
``etmpc.tasks`` entry point. :mod:`etmpc.systems.base` says what a system provides;
``docs/adding-a-task.md`` says in which order to write one.

This package may import ``etmpc.common`` and ``etmpc.control``.
"""

from etmpc.systems.registry import (
    SystemKey,
    TaskNameDeprecation,
    TaskSpec,
    canonical,
    check_name,
    data_dir,
    distinct,
    domain,
    domains,
    folder_name,
    has_levels,
    make_system,
    names,
    parse,
    same_task,
    spec,
    specs,
    system_class,
    system_key,
    stored_seed,
    task_version,
)

__all__ = [
    "SystemKey",
    "TaskNameDeprecation",
    "TaskSpec",
    "canonical",
    "check_name",
    "data_dir",
    "distinct",
    "domain",
    "domains",
    "folder_name",
    "has_levels",
    "make_system",
    "names",
    "parse",
    "same_task",
    "spec",
    "specs",
    "system_class",
    "system_key",
    "stored_seed",
    "task_version",
]
