"""``etmpc score --leaderboard``: every built-in trigger scored on the suite, written as a generated page.

The entries, each one spec per task (:func:`entries`):

* ``always``: standard MPC;
* **best periodic**: the task's best ``every:T`` on its stored test set (its reference: 0);
* **best threshold**: the event trigger ``threshold:X`` whose mean objective is best on
  training-distribution episodes (the validation stream of ``etmpc train``, never the test set), over
  the task's ``Benchmark.sweep_thresholds``;
* the learners shipped in ``policies/<task>/`` (from a checkout): **GPOMDP** (``gpomdp.json``, the
  paper's tasks), **DPI** (``learned.json``) and **PPO** (``ppo.zip``), each where it is shipped;
* **rollout meter**: ``rollout:BEST:4:H``, the one-step lookahead over sampled futures with the task's
  lookahead ``H``: a real policy, and the costliest to run (its CPU column shows it);
* **oracle**: ``oracle:BEST`` (its reference: 100), which knows each episode's future.

Each (entry, task) is scored by :mod:`etmpc.evaluation.scorecard` and kept in the work directory as it
finishes, so an interrupted run continues where it stopped. A kept row is sealed with the SHA-256 of its
content: one edited by hand is refused in one line, never published; one of an older etmpc (no seal)
or of other policy files is played again. The page (``docs/leaderboard.md``), its
JSON and the performance profiles are written at the end, with the commit, date, machine and
software that produced them; the README's headline table is the page's, rewritten between its markers.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from etmpc.common.documents import SEAL, check_seal, loads, sealed
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json, write_text
from etmpc.common.provenance import commit_and_date
from etmpc.common.resources import data_root
from etmpc.evaluation.references import SUITE_VERSION, References, software, stored
from etmpc.evaluation.evaluate import parse_policies
from etmpc.evaluation.inputs import policy_files
from etmpc.evaluation.scorecard import Scorecard, TaskScore, aggregate, play_and_score, profiles
from etmpc.evaluation.workers import make_backend, shared_pools
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.systems import distinct, folder_name, make_system, names
from etmpc.systems.base import require
from etmpc.views.figures import write_performance_profile_png

FORMAT = "etmpc-leaderboard"
WORK = Path("results") / "leaderboard"  # where finished rows are kept (make leaderboard runs from the checkout)
BEGIN, END = "<!-- leaderboard:begin -->", "<!-- leaderboard:end -->"
VALIDATION_EPISODES = 20  # training-distribution episodes that choose the best threshold
ROLLOUT_FUTURES = 4
THRESHOLDS = np.linspace(-100.0, 200.0, 301)


@dataclass(frozen=True)
class Entry:
    """A row of the leaderboard: a name, what kind of trigger it is, and its spec on each task."""

    name: str
    kind: str  # reference | baseline | learned | meter | bound
    specs: dict[str, str]
    note: str = ""


# The learners whose policies the project ships in policies/<task>/: (entry, file, spec prefix, what it is).
SHIPPED = (
    ("GPOMDP (shipped)", "gpomdp.json", "rl:",
     "the paper's learner on its features (5 seeds x 1500 episodes), the seed chosen on validation episodes"),
    ("DPI (shipped)", "learned.json", "rl:", "the default learner, chosen on validation episodes"),
    ("PPO (shipped)", "ppo.zip", "sb3:",
     "Stable-Baselines3 PPO on the trigger environment with the task's policies/<task>/ppo.yml (its reward against "
     "a fixed schedule), chosen on validation episodes"),
)


def shipped_policy(task: str, file: str = "learned.json") -> Path | None:
    """A policy shipped for ``task`` in a checkout's ``policies/`` (``file`` there), if there is one."""
    path = data_root() / "policies" / folder_name(task) / file
    if not path.is_file():
        return None
    try:  # named from where the command runs (make leaderboard: the checkout), so the page names no machine's paths
        return path.relative_to(Path.cwd())
    except ValueError:
        return path


def best_threshold(task: str, workers: int, say: Callable[[str], None]) -> str:
    """The ``threshold:X`` of the task's grid with the best mean objective on training-distribution episodes."""
    system = make_system(task)
    require(system, "experiments", "the leaderboard's best threshold")
    specs = [f"threshold:{x:g}" for x in system.benchmark.sweep_thresholds]
    with make_backend("local", workers) as pool:
        means = mean_scores(pool, system.name, specs, VALIDATION_ENTROPY, VALIDATION_EPISODES)
    sign = 1.0 if system.objective_sense == "min" else -1.0
    chosen = min(zip(specs, means), key=lambda pair: sign * pair[1])[0]
    say(f"{task}: best threshold on {VALIDATION_EPISODES} training-distribution episodes: {chosen}")
    return chosen


def entries(tasks: list[str], references: dict[str, References], workers: int,
            say: Callable[[str], None]) -> list[Entry]:
    best = {t: references[t].best for t in tasks}
    found = [
        Entry("always", "baseline", {t: "always" for t in tasks}, "standard MPC: a new plan every step"),
        Entry("best periodic", "reference", {t: best[t] for t in tasks}, "each task's best every:T on its test set"),
        Entry("best threshold", "baseline", {t: best_threshold(t, workers, say) for t in tasks},
              f"threshold:X chosen on {VALIDATION_EPISODES} training-distribution episodes"),
    ]
    for name, file, prefix, note in SHIPPED:
        shipped = {t: shipped_policy(t, file) for t in tasks}
        if any(path is not None for path in shipped.values()):
            found.append(Entry(name, "learned", {t: f"{prefix}{p}" for t, p in shipped.items() if p is not None},
                               f"{note}; policies/<task>/{file}"))
    found += [
        Entry("rollout meter", "meter", {t: f"rollout:{best[t]}:{ROLLOUT_FUTURES}:{make_system(t).benchmark.lookahead}"
                                         for t in tasks}, "one-step lookahead over sampled futures: a real policy"),
        Entry("oracle", "bound", {t: references[t].oracle_spec for t in tasks}, "knows each episode's future: not a policy"),
    ]
    return found


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _row(entry: Entry, task: str, refs: References, work: Path, episodes: int, workers: int,
         say: Callable[[str], None]) -> tuple[TaskScore, dict]:
    """The entry's score on ``task``, from the work directory if an earlier run finished it, and when and
    at which commit it was played."""
    spec = entry.specs[task]
    path = work / _slug(entry.name) / f"{folder_name(task)}.json"
    key = {"spec": spec, "episodes": episodes, "test_set_sha256": refs.test_set_sha256, "suite_version": SUITE_VERSION}
    files = policy_files(spec)
    if files:  # a policy read from files (rl:, sb3:): a row played with other files is played again
        key["files_sha256"] = {str(f): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}
    kept = _kept(path, key)
    if kept is not None:
        return kept
    say(f"{task}: {entry.name} ({spec})")
    row = play_and_score(task, refs, spec, workers=workers, progress=False)
    played_at = commit_and_date()
    write_json(path, sealed({"key": key, "row": asdict(row), "played": played_at}))
    return row, played_at


def _kept(path: Path, key: dict) -> tuple[TaskScore, dict] | None:
    """The row kept in ``path`` for ``key`` and when it was played; None if there is none to keep (no
    file, an older etmpc's without a seal, or another key: it is played again). A kept row that was
    changed after it was written, or is not a row, is refused in one line (:func:`check_kept`)."""
    kept = _read_kept(path)
    if kept is None or SEAL not in kept or kept.get("key") != key:
        return None
    try:
        return TaskScore.from_json(kept["row"]), dict(kept["played"])
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"kept leaderboard row {path} is not a row ({exc!r}); {_DELETE}") from None


_DELETE = "delete it to play the row again"


def _read_kept(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        kept = loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"kept leaderboard row {path} cannot be read ({exc}); {_DELETE}") from None
    if not isinstance(kept, dict):
        raise EtmpcError(f"kept leaderboard row {path} is not a row (a JSON {type(kept).__name__}); {_DELETE}")
    if SEAL in kept:
        check_seal(kept, f"kept leaderboard row {path}", _DELETE)
    return kept


def check_kept(work: Path) -> None:
    """Every row kept in ``work``, checked before any is played (see :func:`_kept`)."""
    for path in sorted(Path(work).glob("*/*.json")):
        _read_kept(path)


def check_readme(readme: Path) -> None:
    """Raise :class:`EtmpcError` unless ``readme`` has the leaderboard's markers, once each and in order
    (checked before any row is played)."""
    try:
        text = Path(readme).read_text()
    except FileNotFoundError:
        raise EtmpcError(f"--readme {readme} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EtmpcError(f"--readme {readme} cannot be read ({exc})") from None
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise EtmpcError(f"--readme {readme} needs one {BEGIN} ... {END} block for the leaderboard's table "
                         f"(found {text.count(BEGIN)} begin and {text.count(END)} end markers)")


def _provenance() -> dict:
    """:func:`~etmpc.common.provenance.commit_and_date`, with the machine and the software: what made the page."""
    return commit_and_date() | {"machine": {"processor": platform.processor() or platform.machine(), "system": platform.platform(),
                                    "cores": len(os.sched_getaffinity(0))},
                        "software": software()}


def build(docs: Path, work: Path, tasks: list[str] | None = None, episodes: int | None = None, workers: int = 1,
          readme: Path | None = None, say: Callable[[str], None] = lambda line: None) -> dict:
    """Score every entry on every task and write ``docs/leaderboard.{md,json}`` and the profile figure;
    with ``readme``, rewrite its headline table between the markers. Returns the JSON."""
    with shared_pools():  # one pool of workers for every row (a row is one evaluation)
        return _build(docs, work, distinct(tasks or names()), episodes, workers, readme, say)


def _build(docs: Path, work: Path, tasks: list[str], episodes: int | None, workers: int, readme: Path | None,
           say: Callable[[str], None]) -> dict:
    if readme is not None:
        check_readme(readme)
    check_kept(work)
    references = {task: stored(task, episodes) for task in tasks}
    for task in tasks:  # the shipped policies parse (and are the files shipped) before any row is played
        system = make_system(task)
        parse_policies(system, [f"{prefix}{path}" for _, file, prefix, _ in SHIPPED
                                if (path := shipped_policy(task, file)) is not None])
    board = entries(tasks, references, workers, say)
    n = episodes or min(r.episodes for r in references.values())
    result = []
    rows_all: list[TaskScore] = []
    played: dict[str, dict] = {}
    for entry in board:
        rows = []
        for task in [t for t in tasks if t in entry.specs]:
            row, at = _row(entry, task, references[task], work, n, workers, say)
            rows.append(row)
            played[f"{at['commit']}{' (with uncommitted changes)' if at['uncommitted_changes'] else ''}"] = at
        named = [TaskScore(**(asdict(r) | {"policy": entry.name})) for r in rows]
        rows_all += named
        result.append({"name": entry.name, "kind": entry.kind, "note": entry.note, "specs": entry.specs,
                       "rows": [asdict(r) for r in rows], "aggregate": asdict(aggregate(named))})
    data = {"format": FORMAT, "suite_version": SUITE_VERSION, "tasks": tasks, "episodes": n,
            "references": {t: {"best_periodic": r.best, "oracle": r.oracle_spec, "gap": r.gap,
                               "test_set_sha256": r.test_set_sha256, "recompute_price": r.recompute_price,
                               "objective_sense": r.objective_sense} for t, r in references.items()},
            "generated": _provenance() | {"rows_played_at": sorted(played)}, "entries": result}
    docs.mkdir(parents=True, exist_ok=True)
    card = Scorecard(tasks, {}, rows_all, [])
    write_performance_profile_png(docs / "leaderboard_profile.png", profiles(card, THRESHOLDS), THRESHOLDS, tasks)
    write_json(docs / "leaderboard.json", data)
    write_text(docs / "leaderboard.md", page(data))
    if readme is not None:
        write_text(Path(readme), with_table(Path(readme).read_text(), headline(data)))
    return data


# -- what the page says ------------------------------------------------------------------------------
def _finite(value) -> bool:
    """A number that was scored (the JSON's ``null`` is one that was not)."""
    return value is not None and math.isfinite(value)


def _cell(row: dict) -> str:
    if row.get("error"):
        return "failed"
    if not _finite(row["score"]):
        return f"{row['nonfinite_episodes']} non-finite"
    return f"{row['score']:.1f} ± {_number(row['score_ci95'], '.1f')}"


def _number(value, spec: str) -> str:
    return format(value, spec) if _finite(value) else "-"


def headline(data: dict) -> str:
    """The headline table (markdown): each entry's normalized score per task and the suite's aggregate."""
    tasks = data["tasks"]
    lines = ["| trigger | " + " | ".join(tasks) + " | IQM [95 % CI] | P(improve) | CPU ms/episode |",
             "|---|" + "---:|" * len(tasks) + "---:|---:|---:|"]
    for entry in data["entries"]:
        rows = {r["task"]: r for r in entry["rows"]}
        a = entry["aggregate"]
        cpu = [rows[t]["cpu_ms"]["total"] for t in tasks if t in rows and rows[t].get("cpu_ms")]
        iqm = (f"{a['iqm']:.1f} [{a['iqm_ci95'][0]:.1f}, {a['iqm_ci95'][1]:.1f}]"
               if _finite(a["iqm"]) and all(map(_finite, a["iqm_ci95"])) else "-")
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
    return text[text.index(BEGIN) + len(BEGIN):text.index(END)].strip("\n")


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
        "0 is its best periodic schedule, 100 the oracle over it (a one-step lookahead with the episode's future: "
        "above 100 is possible, and the oracle is a bound, not a policy). ± is the 95 % CI over episodes; the suite's "
        "interquartile mean (of every task's episode scores together, as rliable computes it) and the probability of "
        "improving on the best periodic schedule carry 95 % stratified "
        "bootstrap CIs. The oracle scores exactly 100 on every task, yet its IQM is lower: the IQM trims the quarter "
        "of episodes at each end, and the oracle's episode scores are skewed (a few episodes gain far more than the "
        "mean). CPU is the controller's measured time per episode on this machine (solves, feedback and the "
        "trigger's own decisions), averaged over the tasks. See `etmpc score --help` and the README.",
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
        specs = (f"`{distinct_specs.pop()}`" if len(distinct_specs) == 1
                 else ", ".join(f"{t}: `{spec}`" for t, spec in entry["specs"].items()))
        lines.append(f"* **{entry['name']}** ({entry['kind']}): {entry['note']}; {specs}.")
    lines += ["", "## Per task", ""]
    for task in data["tasks"]:
        ref = data["references"][task]
        sense = "lower" if ref["objective_sense"] == "min" else "higher"
        lines += [f"### {task}", "",
                  f"References: `{ref['best_periodic']}` and `{ref['oracle']}` (mean gap {ref['gap']:.5g}); objective: "
                  f"{sense} is better, at {ref['recompute_price']:g} per computation.", "",
                  "| trigger | spec | objective | computations | failures | score | CPU ms/ep (solve / feedback / trigger) |",
                  "|---|---|---:|---:|---:|---:|---:|"]
        for entry in data["entries"]:
            row = next((r for r in entry["rows"] if r["task"] == task), None)
            if row is None:
                continue
            if row.get("error"):
                lines.append(f"| {entry['name']} | `{row['policy']}` | failed: {row['error']} | | | | |")
                continue
            failures = "-" if row["failures_mean"] is None else f"{row['failures_mean']:.2f}"
            cpu = row["cpu_ms"]
            lines.append(f"| {entry['name']} | `{row['policy']}` | {_number(row['objective_mean'], '.5g')} | "
                         f"{_number(row['recomputes_mean'], '.2f')} | {failures} | {_cell(row)} | "
                         f"{_number(cpu['total'], '.1f')} ({_number(cpu['solve'], '.1f')} / {_number(cpu['feedback'], '.1f')} / "
                         f"{_number(cpu['decide'], '.1f')}) |")
        lines.append("")
    return "\n".join(lines)
