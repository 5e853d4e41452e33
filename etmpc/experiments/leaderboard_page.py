"""The leaderboard's page, from its JSON alone (``docs/leaderboard.json``): the headline table (the README's
too, between its markers), the entries, each task's rows, and where a learner scores above the
clairvoyant reference and why. :mod:`etmpc.experiments.leaderboard` plays the rows and writes the files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from etmpc.loop import computation_cost
from etmpc.evaluation.metrics import higher_or_lower, oriented
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.results import failures_cell

BEGIN, END = "<!-- leaderboard:begin -->", "<!-- leaderboard:end -->"
ORACLE_NOTE = (
    "a one-step lookahead over the best periodic schedule with each episode's future known: a reference, not a "
    "policy, and not a bound"
)


def _finite(value) -> bool:
    """A number that was scored (the JSON's ``null`` is one that was not)."""
    return value is not None and math.isfinite(value)


def _cell(row: dict) -> str:
    if row.get("error"):
        return "failed"
    if not _finite(row["score"]):
        return f"{row['nonfinite_episodes']} non-finite"
    return f"{row['score']:.1f} ± {_number(row['score_ci95'], '.1f')}"


def _failures(row: dict) -> str:
    """The task's failures per episode, mean ± 95 % CI, and in how many episodes any came (one crash can count
    many steps); a row of an older etmpc has no CI (the mean alone), a task that counts none ``-``. In the JSON
    a CI that could not be given (one episode) is null."""
    ci, episodes = row.get("failures_ci95"), row.get("episode_failures")
    cell = failures_cell(row["failures_mean"], math.nan if ci is None and episodes is not None else ci)
    if episodes is None or cell == "-":
        return cell
    return f"{cell} ({sum(1 for n in episodes if n > 0)} ep.)"


def _number(value, spec: str) -> str:
    return format(value, spec) if _finite(value) else "-"


def headline(data: dict) -> str:
    """The headline table (markdown): each entry's normalized score per task and the suite's aggregate."""
    tasks = data["tasks"]
    lines = [
        "| policy | " + " | ".join(tasks) + " | IQM [95 % CI] | P(improve) | CPU ms/episode |",
        "|---|" + "---:|" * len(tasks) + "---:|---:|---:|",
    ]
    for entry in data["entries"]:
        rows = {r["task"]: r for r in entry["rows"]}
        a = entry["aggregate"]
        cpu = [rows[t]["cpu_ms"]["total"] for t in tasks if t in rows and rows[t].get("cpu_ms")]
        iqm = (
            f"{a['iqm']:.1f} [{a['iqm_ci95'][0]:.1f}, {a['iqm_ci95'][1]:.1f}]"
            if _finite(a["iqm"]) and all(map(_finite, a["iqm_ci95"]))
            else "-"
        )
        if iqm != "-" and len(rows) < len(tasks):  # over the tasks it was played on only: not the suite's
            iqm += f" ({len(rows)} of {len(tasks)} tasks)"
        improve = f"{a['probability_of_improvement']:.2f}" if _finite(a["probability_of_improvement"]) else "-"
        cells = [_cell(rows[t]) if t in rows else "-" for t in tasks] + [iqm, improve, f"{np.mean(cpu):.1f}" if cpu else "-"]
        lines.append(f"| {entry['name']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def with_table(text: str, table: str) -> str:
    """``text`` with the block between the leaderboard's markers replaced by ``table``."""
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:start] + "\n" + table + "\n" + text[end:]


def table_in(text: str) -> str:
    """The table between the leaderboard's markers of ``text``."""
    return text[text.index(BEGIN) + len(BEGIN) : text.index(END)].strip("\n")


def above_the_oracle(data: dict, task: str) -> list[str]:
    """Lines saying, for each learner and meter that scores above 100 on ``task``, why: the recomputes it
    saves against the oracle's, what they are worth at the task's price, and what it gives up in control
    objective (the objective without that price). Every number is the JSON's."""
    ref = data["references"][task]
    price, sense = ref["recompute_price"], ref["objective_sense"]
    oracle = next((r for e in data["entries"] if e["kind"] in ("oracle", "bound") for r in e["rows"] if r["task"] == task), None)
    if oracle is None or not _finite(oracle["objective_mean"]):
        return []
    lines = []
    for entry in data["entries"]:
        row = next((r for r in entry["rows"] if r["task"] == task), None)
        if (
            entry["kind"] not in ("learned", "meter")
            or row is None
            or row.get("error")
            or not _finite(row["score"])
            or row["score"] <= 100
            or not _finite(row["objective_mean"])
        ):
            continue
        saved = oracle["recomputes_mean"] - row["recomputes_mean"]
        worth = computation_cost(saved, price)
        better = -oriented(oracle["objective_mean"] - row["objective_mean"], sense)  # > 0: its objective is the better
        control_loss = worth - better  # what it gives up in control objective, against the oracle's
        head = (
            f"* **{entry['name']}** scores {row['score']:.1f}: {row['recomputes_mean']:.2f} recomputes per episode "
            f"against the oracle's {oracle['recomputes_mean']:.2f}"
        )
        if saved > 0 and price > 0:
            lines.append(
                f"{head}. The {saved:.2f} it saves are worth {worth:.4g} at {price:g} per recompute; it gives "
                f"up {control_loss:.4g} in control objective to the oracle, so its objective is {better:.4g} "
                "better than the oracle's."
            )
        else:
            lines.append(
                f"{head}, saving none the price counts ({price:g} per recompute): its control objective "
                f"itself is {better:.4g} better than the oracle's."
            )
    if lines:
        lines = [
            f"Above 100 on {task}: the oracle is a one-step lookahead over `{ref['best_periodic']}` and spends about "
            "as many recomputes as that schedule; these save some of them:",
            "",
            *lines,
            "",
        ]
    return lines


def page(data: dict) -> str:
    g = data["generated"]
    dirty = " (with uncommitted changes)" if g["uncommitted_changes"] else ""
    software = ", ".join(f"{k} {v}" for k, v in g["software"].items())
    lines = [
        "# Leaderboard",
        "",
        f"Generated by `etmpc score --leaderboard` from commit {g['commit']}{dirty} on {g['date']}, on "
        f"{g['machine']['cores']} cores of {g['machine']['processor']} ({g['machine']['system']}); {software}. "
        f"Its rows were played at commit(s) {', '.join(g.get('rows_played_at', [g['commit']]))} (an interrupted or "
        "repeated run keeps the rows it finished). Do not edit: run `make leaderboard` again.",
        "",
        f"Each task's normalized score on its stored test set ({data['episodes']} episodes, at the task's price): "
        "0 is its best periodic schedule, 100 the clairvoyant reference: the oracle over that schedule, a one-step "
        "lookahead with each episode's future known (not a policy, and not a bound): a learner that saves recomputes "
        "the oracle spends can score above 100 (each task's section says where, and what the saved recomputes are "
        "worth). ± is the 95 % CI "
        "over episodes; the suite's "
        "interquartile mean (of every task's episode scores together, as rliable computes it) and the probability of "
        "improving on the best periodic schedule carry 95 % stratified "
        "bootstrap CIs. The oracle scores exactly 100 on every task, yet its IQM is lower: the IQM trims the quarter "
        "of episodes at each end, and the oracle's episode scores are skewed (a few episodes gain far more than the "
        "mean). CPU is the controller's CPU time per episode on this machine (solves, feedback and the "
        "policy's own decisions, on the thread that runs the loop), averaged over the tasks. See `etmpc score --help` "
        "and the README.",
        "",
        BEGIN,
        headline(data),
        END,
        "",
        "![performance profiles](leaderboard_profile.png)",
        "",
        "## Entries",
        "",
    ]
    for entry in data["entries"]:
        distinct_specs = set(entry["specs"].values())
        specs = (
            f"`{distinct_specs.pop()}`"
            if len(distinct_specs) == 1
            else ", ".join(f"{t}: `{spec}`" for t, spec in entry["specs"].items())
        )
        note = ORACLE_NOTE if entry["kind"] in ("oracle", "bound") else entry["note"]  # a page from an older JSON says it too
        kind = "clairvoyant reference" if entry["kind"] in ("oracle", "bound") else entry["kind"]
        lines.append(f"* **{entry['name']}** ({kind}): {note}; {specs}.")
    lines += ["", "## Per task", ""]
    for task in data["tasks"]:
        ref = data["references"][task]
        sense = higher_or_lower(ref["objective_sense"])
        lines += [
            f"### {task}",
            "",
            f"References: `{ref['best_periodic']}` and `{ref['oracle']}` (mean gap {ref['gap']:.5g}); objective: "
            f"{sense} is better, at {ref['recompute_price']:g} per recompute."
            + (
                f" Failures ({ref['failure_name']}): per episode, mean ± 95 % CI, and in how many episodes any came"
                f" ([what counts](scorecard.md#failures))."
                if ref.get("failure_name")
                else ""
            ),
            "",
            "| policy | spec | objective | recomputes | failures | score | CPU ms/ep (solve / feedback / policy) |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for entry in data["entries"]:
            row = next((r for r in entry["rows"] if r["task"] == task), None)
            if row is None:
                continue
            if row.get("error"):
                lines.append(f"| {entry['name']} | `{row['policy']}` | failed: {row['error']} | | | | |")
                continue
            failures = _failures(row)
            cpu = row["cpu_ms"]
            lines.append(
                f"| {entry['name']} | `{row['policy']}` | {_number(row['objective_mean'], '.5g')} | "
                f"{_number(row['recomputes_mean'], '.2f')} | {failures} | {_cell(row)} | "
                f"{_number(cpu['total'], '.1f')} ({_number(cpu['solve'], '.1f')} / {_number(cpu['feedback'], '.1f')} / "
                f"{_number(cpu['decide'], '.1f')}) |"
            )
        lines.append("")
        lines += above_the_oracle(data, task)
    return "\n".join(lines)


def check_readme(readme: Path) -> None:
    """Raise :class:`EtmpcError` unless ``readme`` is a regular file (a FIFO would hang the read) that has the
    leaderboard's markers, once each and in order, and lies outside etmpc's data folders (checked before any
    row is played)."""
    from etmpc.evaluation.inputs import check_run_outputs

    check_run_outputs({}, edits={"--readme": readme})
    try:
        text = Path(readme).read_text()
    except FileNotFoundError:
        raise EtmpcError(f"--readme {readme} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EtmpcError(f"--readme {readme} cannot be read ({exc})") from None
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise EtmpcError(
            f"--readme {readme} needs one {BEGIN} ... {END} block for the leaderboard's table "
            f"(found {text.count(BEGIN)} begin and {text.count(END)} end markers)"
        )
