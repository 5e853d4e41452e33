"""The suite described: ``etmpc tasks``, listed from the registry (:mod:`etmpc.systems.catalogue`): per task its
id, its Gymnasium id with its version, its episode's length, the price of a recompute and its options' names;
and ``etmpc options --task TASK``, each option's value, range, unit and meaning."""

from __future__ import annotations

import textwrap


def add_parser(sub) -> None:
    """The ``tasks`` subcommand, on the command line's subparsers ``sub``."""
    sub.add_parser(
        "tasks", help="list the suite: each task's id, Gymnasium id and version, episode length, price of a recompute and options"
    )


def format_tasks(entries) -> str:
    """The catalogue as the command prints it: a table, then each task's options."""
    from etmpc.systems.catalogue import grouped

    header = ("task", "Gymnasium id", "episode", "price")
    rows = [
        (
            e.spec.id + (" *" if e.spec.default else ""),
            e.spec.gym_id,
            f"{e.episode_steps} x {e.control_interval_s:g} s = {e.episode_s:g} s",
            f"{e.recompute_price:g}",
        )
        for e in entries
    ]
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]
    lines = [f"{len(rows)} tasks (* the domain's first task, which the domain alone names: --task cart_pendulum)"]
    lines += ["  " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in (header, *rows)]
    lines.append("options (--option NAME=VALUE; `etmpc options --task TASK` says what each may be and does):")
    lines += [
        textwrap.fill(f"{e.spec.id}: {grouped(e.options)}", 110, initial_indent="  ", subsequent_indent="      ") for e in entries
    ]
    return "\n".join(lines)


def run(args) -> None:
    from etmpc.systems.catalogue import entries

    print(format_tasks(entries()))


def run_options(args) -> None:
    from etmpc.systems import system_key
    from etmpc.systems.options import canonical, described, settable

    key = system_key(args.task, options=args.options)
    given, config = dict(key.options), key.make().config
    print(f"{key.task}: its options (--option NAME=VALUE; the price is --price), each with what it may be and why")
    declared = described(config)
    for name, value in settable(config).items():
        text = canonical(value) or ('""' if isinstance(value, str) else "()")  # an empty word, an empty list
        print(f"  {name} = {text}" + ("   (as set)" if name in given else ""))
        what, kind = declared[name]
        unit = f" ({what.unit})" if what.unit else ""
        drawn = "; acts on newly drawn episodes (etmpc testset --option ...), not on a stored test set" if what.draws else ""
        print(f"      {what.describe(kind)}{unit}: {what.why}{drawn}")
