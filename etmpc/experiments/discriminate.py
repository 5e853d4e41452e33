"""``etmpc discriminate``: can policies be told apart on a task? The clairvoyant reference and the rollout
policy against the periodic front, on the first stored test-set episodes.

Every periodic schedule ``every:1`` … ``every:N`` (``N`` the MPC's horizon) and the task's event triggers
(``threshold:X`` at its :class:`~etmpc.systems.base.Benchmark`'s sweep levels) play the episodes; the best
periodic schedule at the price (by default the task's own) is chosen; then ``oracle:BEST`` (the clairvoyant
reference, not a policy) and ``rollout:BEST:4:H`` (``H`` 20, or the task's shorter
``Benchmark.lookahead``) play them at that price. Each state-dependent policy is compared with the
periodic front interpolated to its own mean rate of recomputes, per episode
(:func:`etmpc.experiments.pareto.versus_front`, as ``etmpc sweep`` does): the gain in control objective,
its 95 % CI and the episodes it wins. A task discriminates when the oracle gains clearly, with a CI that
excludes 0 (docs/adding-a-task.md, step 8).
"""

from __future__ import annotations

from etmpc.common.wording import counted
from etmpc.common.progress import stage
from etmpc.evaluation.evaluate import evaluate
from etmpc.experiments.pareto import best_periodic, episode_table, versus_front
from etmpc.evaluation.testsets import check_options_act
from etmpc.systems import system_key
from etmpc.systems.options import options_line

EPISODES = 30  # the first stored test-set episodes played by default
ROLLOUT_FUTURES, ROLLOUT_HORIZON = 4, 20  # rollout:BEST:K:H, H capped at the task's lookahead


def discriminate(
    task: str,
    price: float | None = None,
    episodes: int = EPISODES,
    workers: int | None = None,
    progress: bool = False,
    options=(),
) -> dict:
    """What :mod:`this module <etmpc.experiments.discriminate>` describes, as a dict: ``price``,
    ``best_periodic``, ``fixed`` and ``priced`` (the two evaluations' JSON), and ``rows``: per event trigger,
    oracle and rollout, its row of :func:`~etmpc.experiments.pareto.versus_front` (``None`` outside the
    periodic schedules' range of rates), in that order. ``progress``: each of the two stages' time left on stderr.
    ``options``: the task's (:mod:`etmpc.systems.options`), for both stages."""
    unpriced = system_key(task, None, options)
    check_options_act(unpriced, takes_test_set=False)  # both stages play the stored test set
    system = unpriced.make()
    price = system.recompute_price if price is None else price
    priced_key = system_key(task, price, options)
    periodic = [f"every:{t}" for t in range(1, system.horizon + 1)]
    events = system.benchmark.threshold_specs()
    with stage(f"{task}: {len(periodic)} periodic schedules and {len(events)} event triggers"):
        fixed = evaluate(unpriced, periodic + events, episodes=episodes, progress=progress, workers=workers).to_json()
    best = best_periodic(fixed, periodic, price, system.objective_sense)
    specs = [f"oracle:{best}", f"rollout:{best}:{ROLLOUT_FUTURES}:{system.benchmark.capped(ROLLOUT_HORIZON)}"]
    with stage(f"{task}: the oracle and the rollout over {best}"):
        priced = evaluate(priced_key, specs, episodes=episodes, progress=progress, workers=workers).to_json()
    table = {**episode_table(fixed), **episode_table(priced)}
    rows = {spec: versus_front(table, periodic, spec, system.objective_sense) for spec in events + specs}
    chosen = dict(unpriced.options)  # the task's options, beside the results (none: the task as it is)
    return {"price": price, "best_periodic": best, "options": chosen, "fixed": fixed, "priced": priced, "rows": rows}


def format_discrimination(task: str, found: dict, episodes: int, seconds: float) -> str:
    """The table ``etmpc discriminate`` prints: one line per state-dependent policy."""
    lines = [
        f"{task}: best periodic schedule at price {found['price']:g}: {found['best_periodic']}; {counted(episodes, 'episode')}, "
        f"{seconds:.0f} s",
        *options_line(found.get("options")),
        f"{'policy':28s} {'recomputes':>12s}  {'gain over the front at its rate':>31s}  better in",
    ]
    for spec, row in found["rows"].items():
        if row is None:
            lines.append(f"{spec:28s} outside the periodic schedules' range of rates")
            continue
        ci = row["gain_percent_ci95"]
        ci = f"{ci:.2f} %" if ci is not None else "(one episode)"
        lines.append(
            f"{spec:28s} {row['computations']:12.1f}  {row['gain_percent']:+18.2f} % ± {ci:>8s}  "
            f"{row['better_episodes']}/{row['episodes']}"
        )
    return "\n".join(lines)
