"""The paper's Figure 3: the mean objective per policy from ``etmpc evaluate --json`` documents, with
the learned policy's seeds as one bar (matplotlib, headless Agg)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.artist import Artist  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.policies.specs import find  # noqa: E402
from etmpc.common.sense import cost_or_profit, higher_or_lower  # noqa: E402
from etmpc.views.blueprint import objective_unit  # noqa: E402
from etmpc.views.png import save_png_atomically  # noqa: E402


# rl:<run dir>/seed<S>/last.json: the final policy of one training seed (etmpc train's layout).
_LEARNED = re.compile(r"^rl:(?:(?P<run>.*)/)?seed(?P<seed>\d+)/last\.json$")


@dataclass(frozen=True)
class Bar:
    """One bar of :func:`draw_policy_bars`: a policy, or the seeds of one training run together."""

    label: str
    mean: float  # objective: the policy's mean, or the mean over seeds of their means
    error: float  # std over the repeats' means, or over the seeds' means (0: none)
    recomputes: float  # mean per episode (over seeds for a group)
    policies: tuple[str, ...]  # the specs drawn by this bar
    stochastic: bool
    clairvoyant: bool = False  # an oracle: a reference that knows the future, not a policy


def _check_evaluations(evaluations: Sequence[dict], sources: Sequence[str] | None) -> list[str]:
    """Check the documents are evaluations of one task on one test set; return their names."""
    if not evaluations:
        raise EtmpcError("no evaluation to draw")
    names = list(sources) if sources is not None else [f"evaluation {i + 1}" for i in range(len(evaluations))]
    for name, doc in zip(names, evaluations):
        if not (
            isinstance(doc, dict)
            and isinstance(doc.get("policies"), dict)
            and doc["policies"]
            and "domain" in doc
            and "task" in doc
        ):
            raise EtmpcError(f"{name} is not an `etmpc evaluate --json` document (no domain, task or policies)")
        for spec, summary in doc["policies"].items():
            missing = [
                key
                for key in ("objective_mean", "objective_std_repeats", "objective_sense", "recomputes_mean", "episodes")
                if not isinstance(summary, dict) or key not in summary
            ]
            if missing:
                raise EtmpcError(f"{name}: policy {spec!r} has no {', '.join(missing)}")
    first, name0 = evaluations[0], names[0]
    what = lambda doc: f"{doc['domain']}/{doc['task']}"  # noqa: E731
    for name, doc in zip(names[1:], evaluations[1:]):
        if what(doc) != what(first):
            raise EtmpcError(f"mismatched tasks: {name0} evaluates {what(first)}, {name} {what(doc)}")
        sha = lambda d: (d.get("test_set") or {}).get("sha256")  # noqa: E731
        if sha(doc) != sha(first):
            raise EtmpcError(f"mismatched test sets: {name0} and {name} were evaluated on different test sets")
    episodes = {(name, summary["episodes"]) for name, doc in zip(names, evaluations) for summary in doc["policies"].values()}
    if len({n for _, n in episodes}) > 1:
        shown = ", ".join(f"{name}: {n}" for name, n in sorted(episodes))
        raise EtmpcError(f"mismatched test-set episodes ({shown}): the means would be over different episodes")
    return names


def policy_bars(evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None) -> list[Bar]:
    """The bars :func:`draw_policy_bars` draws, in the order the policies first appear."""
    names = _check_evaluations(evaluations, sources)
    summaries: dict[str, dict] = {}
    for name, doc in zip(names, evaluations):
        for spec, summary in doc["policies"].items():
            if spec in summaries and summaries[spec] != summary:
                raise EtmpcError(f"policy {spec!r} appears in more than one evaluation with different results ({name})")
            summaries[spec] = summary
    runs: dict[str, list[str]] = {}  # training run dir -> its seeds' specs
    if group_learned:
        for spec in summaries:
            match = _LEARNED.match(spec)
            if match:
                runs.setdefault(match["run"] or ".", []).append(spec)
    bars, drawn = [], set()
    for spec, summary in summaries.items():
        if spec in drawn:
            continue
        match = _LEARNED.match(spec) if group_learned else None
        if match:
            members = runs[match["run"] or "."]
            means = np.array([summaries[m]["objective_mean"] for m in members], dtype=float)
            recomputes = np.array([summaries[m]["recomputes_mean"] for m in members], dtype=float)
            n = len(members)
            label = f"learned ({n} seed{'s' if n > 1 else ''})"
            if len(runs) > 1:
                label = f"learned {_short_path(match['run'] or '.')}\n({n} seed{'s' if n > 1 else ''})"
            error = float(np.std(means, ddof=1)) if n > 1 else float(summary["objective_std_repeats"])
            bars.append(Bar(label, float(np.mean(means)), error, float(np.mean(recomputes)), tuple(members), True))
            drawn.update(members)
        else:
            kind = find(spec)  # None: a policy object's own name
            learned = kind is not None and kind.name == "rl"
            label = f"rl:{_short_path(spec.partition(':')[2])}" if learned else spec
            clairvoyant = is_clairvoyant(spec)
            bars.append(
                Bar(
                    label + ("\n(oracle)" if clairvoyant else ""),
                    float(summary["objective_mean"]),
                    float(summary["objective_std_repeats"]),
                    float(summary["recomputes_mean"]),
                    (spec,),
                    learned,
                    clairvoyant,
                )
            )
            drawn.add(spec)
    return bars


def is_clairvoyant(spec: str) -> bool:
    """Whether ``spec`` is an oracle's (``oracle:``): it knows the episode's future, never a contender."""
    kind = find(spec)
    return kind is not None and kind.clairvoyant


def _short_path(path: str, parts: int = 3) -> str:
    pieces = PurePosixPath(path).parts
    return path if len(pieces) <= parts else "…/" + "/".join(pieces[-parts:])


def draw_policy_bars(evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None):
    """The paper's Figure 3: one bar per policy (its mean objective over the test set), from one or
    more ``etmpc evaluate --json`` documents of the same task and test set.

    Error bars: the std over the repeats' means (``objective_std_repeats``, non-zero only for a
    stochastic policy evaluated with ``--repeats`` > 1). With ``group_learned``, the policies
    ``rl:…/seed<S>/last.json`` of one training run are one bar "learned (N seeds)": the mean over
    seeds, with the std over seeds as its error bar. Each bar is annotated with its mean and its mean
    recomputes per episode. ``sources`` names the documents in error messages.
    """
    bars = policy_bars(evaluations, group_learned, sources)
    first = evaluations[0]
    sense = next(iter(first["policies"].values()))["objective_sense"]
    episodes = next(iter(first["policies"].values()))["episodes"]
    means = np.array([b.mean for b in bars])
    errors = np.array([b.error for b in bars])
    x = np.arange(len(bars))
    fig, ax = plt.subplots(figsize=(max(7.0, 1.45 * len(bars) + 3.0), 4.8))
    colors = ["tab:gray" if b.clairvoyant else "tab:orange" if b.stochastic else "tab:blue" for b in bars]
    container = ax.bar(x, np.nan_to_num(means), width=0.65, color=colors, alpha=0.85, gid="policy_bars")
    for rect, bar in zip(container.patches, bars):
        rect.set_gid(bar.label)
    spread = errors > 0  # error bars only where there is a spread (a deterministic policy's is 0)
    if spread.any():
        ax.errorbar(
            x[spread], means[spread], yerr=errors[spread], fmt="none", ecolor="black", elinewidth=1.2, capsize=5, gid="spread"
        )

    finite = np.isfinite(means)
    low, high = (np.min((means - errors)[finite]), np.max((means + errors)[finite])) if finite.any() else (0.0, 1.0)
    span = high - low
    zoomed = bool(finite.any() and low > 0 and 0 < span < 0.5 * low)  # all positive and close: show the differences
    pad = span if span > 0 else abs(high) or 1.0
    if zoomed:
        ax.set_ylim(low - 0.5 * pad, high + 0.45 * pad)
    else:
        ax.set_ylim(min(0.0, low - 0.1 * pad), max(0.0, high + 0.3 * pad))
    for xi, bar in zip(x, bars):
        if not np.isfinite(bar.mean):
            ax.annotate("no finite run", (xi, 0), ha="center", va="bottom", fontsize=8)
            continue
        up = bar.mean >= 0 or zoomed
        y = bar.mean + bar.error if up else bar.mean - bar.error
        ax.annotate(
            f"{bar.mean:.5g}\n{bar.recomputes:.1f} recomp./ep",
            (xi, y),
            xytext=(0, 4 if up else -4),
            textcoords="offset points",
            ha="center",
            va="bottom" if up else "top",
            fontsize=8,
            gid="recomputes",
        )

    ax.set_xticks(x)
    long = any(len(b.label) > 12 for b in bars)
    ax.set_xticklabels([b.label for b in bars], rotation=20 if long else 0, ha="right" if long else "center", fontsize=9)
    unit = objective_unit(first["domain"], first["task"])
    what = cost_or_profit(sense) + ("" if unit in ("-", "rad²") else f" ({unit})")
    ax.set_ylabel(f"mean {what} per episode\n({higher_or_lower(sense)} is better{'; axis not from 0' if zoomed else ''})")
    ax.set_title(f"{first['domain']}/{first['task']}: objective per policy ({episodes} test-set episodes)", fontsize=11)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)
    handles: list[Artist] = []
    if any(not b.stochastic and not b.clairvoyant for b in bars):
        handles.append(Patch(color="tab:blue", alpha=0.85, label="fixed policy"))
    if any(b.clairvoyant for b in bars):
        handles.append(Patch(color="tab:gray", alpha=0.85, label="oracle: a reference\n(knows the future; not a policy)"))
    if any(b.stochastic and not b.clairvoyant for b in bars):
        handles.append(Patch(color="tab:orange", alpha=0.85, label="learned (stochastic) policy"))
    if spread.any():
        grouped = any(len(b.policies) > 1 for b in bars)
        handles.append(
            Line2D(
                [],
                [],
                color="black",
                marker="_",
                ms=10,
                lw=1.2,
                label="± std over repeats' means" + ("\n(over seeds for a group)" if grouped else ""),
            )
        )
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    return fig


def write_policy_bars_png(
    path, evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None
) -> Path:
    """:func:`draw_policy_bars` written atomically to ``path`` (PNG)."""
    return save_png_atomically(draw_policy_bars(evaluations, group_learned, sources), path)
