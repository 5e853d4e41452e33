"""The price sweep: re-priced objectives, the equal-rate comparison, the figure, and the run directory.

Independent truths: the evaluation engine itself run at another price (the sweep re-prices instead),
hand-built episode tables whose answers are known exactly, and brute force over the schedules.
"""

import json

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import evaluate
from etmpc.experiments import pareto as front_numbers
from etmpc.experiments import sweep as sw
from etmpc.views import curves
from etmpc.learning.selftrigger import SelfSettings


def test_re_pricing_an_evaluation_gives_what_evaluating_at_that_price_gives():
    policies = ["every:3", "threshold:0.3"]
    free = evaluate("cart_pendulum", policies, episodes=2, workers=1, progress=False).to_json()
    priced = evaluate("cart_pendulum", policies, episodes=2, workers=1, progress=False, recompute_price=1e-3).to_json()
    assert priced["recompute_price"] == 1e-3 and free["recompute_price"] == 5e-5
    for a, b in zip(free["runs"], priced["runs"], strict=True):
        assert (a["control_objective"], a["recomputes"]) == (b["control_objective"], b["recomputes"])  # decisions: price-free
        assert front_numbers.objective(a["control_objective"], a["recomputes"], 1e-3, "min") == pytest.approx(
            b["objective"], rel=1e-12
        )


def _table(rows: dict) -> dict:
    """policy -> episode -> (control, computations) from {policy: [(control, computations) per episode]}."""
    return {spec: dict(enumerate(cells)) for spec, cells in rows.items()}


PERIODIC = ["every:1", "every:2", "every:4"]
BASE = {"every:1": [(1.0, 100), (3.0, 100)], "every:2": [(2.0, 50), (4.0, 50)], "every:4": [(4.0, 25), (6.0, 25)]}


def test_a_policy_on_the_front_gains_nothing_and_a_better_one_gains_its_margin():
    # Exactly halfway between every:2 and every:1 in rate and in control, per episode: on the front.
    halfway = [(1.5, 75), (3.5, 75)]
    on = front_numbers.versus_front(_table({**BASE, "event": halfway}), PERIODIC, "event", "min")
    assert on["between"] == ["every:2", "every:1"] and on["weight"] == pytest.approx(0.5)
    assert on["gain"] == pytest.approx(0.0) and on["computations"] == 75
    # 0.25 better (lower cost) on every episode, at 30 computations (a fifth of the way from every:4 to every:2).
    better = [(4.0 - 0.4 - 0.25, 30), (6.0 - 0.4 - 0.25, 30)]
    row = front_numbers.versus_front(_table({**BASE, "event": better}), PERIODIC, "event", "min")
    assert row["weight"] == pytest.approx(0.2) and row["front_control_objective"] == pytest.approx(np.mean([3.6, 5.6]))
    assert row["gain"] == pytest.approx(0.25) and row["gain_ci95"] == pytest.approx(0.0, abs=1e-12)
    assert row["better_episodes"] == 2
    # The same problem as a profit (every value negated): the same gain.
    negated = {spec: [(-c, n) for c, n in cells] for spec, cells in {**BASE, "event": better}.items()}
    assert front_numbers.versus_front(_table(negated), PERIODIC, "event", "max")["gain"] == pytest.approx(0.25)
    # As a profit the unnegated numbers make every:4 (fewest computations, most profit) the whole front.
    assert front_numbers.front(_table(BASE), PERIODIC, [0, 1], "max") == ["every:4"]
    # Outside the schedules' range there is no front to compare with.
    assert front_numbers.versus_front(_table({**BASE, "event": [(1.0, 10), (1.0, 10)]}), PERIODIC, "event", "min") is None


def test_a_dominated_schedule_is_not_part_of_the_front():
    # every:3 at 34 computations but worse than every:2 at 50: dominated, so the front runs every:4 -> every:2.
    rows = {**BASE, "every:3": [(5.0, 34), (7.0, 34)], "event": [(3.0, 34), (5.0, 34)]}
    periodic = [*PERIODIC, "every:3"]
    assert front_numbers.front(_table(rows), periodic, [0, 1], "min") == ["every:4", "every:2", "every:1"]
    row = front_numbers.versus_front(_table(rows), periodic, "event", "min")
    assert row["between"] == ["every:4", "every:2"]
    w = (34 - 25) / (50 - 25)
    assert row["gain"] == pytest.approx(np.mean([(1 - w) * 4 + w * 2 - 3, (1 - w) * 6 + w * 4 - 5]))


def test_the_ci_is_the_paired_normal_interval():
    gains = np.array([0.1, -0.2, 0.4, 0.3])
    cells = [(2.0 - g, 50) for g in gains]  # at every:2's rate: the front is every:2 itself
    row = front_numbers.versus_front(
        _table({"every:1": [(1.0, 100)] * 4, "every:2": [(2.0, 50)] * 4, "every:4": [(4.0, 25)] * 4, "event": cells}),
        PERIODIC,
        "event",
        "min",
    )
    assert row["gain"] == pytest.approx(gains.mean())
    assert row["gain_ci95"] == pytest.approx(1.96 * gains.std(ddof=1) / 2.0)


def test_the_best_periodic_schedule_and_the_nearest_one_match_brute_force():
    runs = [
        {"policy": spec, "episode": e, "finite": True, "control_objective": c, "recomputes": n}
        for spec, cells in BASE.items()
        for e, (c, n) in enumerate(cells)
    ]
    fixed = {"runs": runs}
    for price in (0.0, 0.01, 0.05, 1.0):
        brute = min(PERIODIC, key=lambda s: np.mean([c + price * n for c, n in BASE[s]]))
        assert front_numbers.best_periodic(fixed, PERIODIC, price, "min") == brute
    near = front_numbers.versus_nearest(_table({**BASE, "event": [(3.0, 45), (5.0, 45)]}), PERIODIC, "event", 0.01, "min")
    assert near["policy"] == "every:2" and near["gain"] == pytest.approx(3.5 - 4.45)  # (2.5, 4.5) against (3.45, 5.45)


def test_settings_refuse_bad_prices():
    with pytest.raises(EtmpcError, match="twice"):
        sw.SweepSettings.default("battery", [1e-3, 0.001])
    with pytest.raises(EtmpcError, match="finite"):
        sw.SweepSettings.default("battery", [-1.0])
    from etmpc.systems import make_system, names

    assert sw.SweepSettings.default("cart_pendulum").prices == make_system("cart_pendulum").benchmark.prices
    for task in names():  # every task's own prices: several, its own price among them
        benchmark = make_system(task).benchmark
        assert len(benchmark.prices) >= 5 and make_system(task).recompute_price in benchmark.prices


TINY_LEARNER = sw.LearnerSettings(
    seeds=(0,),
    episodes=2,
    eval_every=2,
    labels=3,
    futures=1,
    horizon=2,
    validation_episodes=2,
    bases=("every:3", "every:20"),
    selection_episodes=1,
)
TINY_SELF = SelfSettings(
    bases=("every:3", "every:20"),
    selection_episodes=1,
    episodes=2,
    solves_per_episode=2,
    futures=1,
    horizon=2,
    ridges=(0.1,),
    validation_episodes=2,
)
TINY = sw.SweepSettings(
    prices=(5e-5, 5e-3), episodes=1, thresholds=(0.3, 1.0), futures=1, horizon=2, learner=TINY_LEARNER, self_trigger=TINY_SELF
)


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "cart"
    return out, sw.sweep("cart_pendulum", out, TINY, workers=1, progress=False)


def test_a_sweep_writes_every_point_and_continues_without_redoing_work(tiny_sweep):
    out, pareto = tiny_sweep
    assert sorted(p.name for p in out.iterdir()) == [
        "SWEEP.md",
        "fixed.json",
        "learned_0.json",
        "learned_1.json",
        "pareto.json",
        "pareto.png",
        "price_0.json",
        "price_1.json",
        "self_0.json",
        "self_1.json",
        "self_policy_0.json",
        "self_policy_1.json",
        "settings.json",
        "train_0",
        "train_1",
    ]
    kinds = {}
    for point in pareto["points"]:
        kinds.setdefault((point["price"], point["kind"]), []).append(point["policy"])
    for price in TINY.prices:
        assert len(kinds[(price, "periodic")]) == 20 and kinds[(price, "event")] == ["threshold:0.3", "threshold:1"]
        assert len(kinds[(price, "rollout")]) == 1 and len(kinds[(price, "oracle")]) == 1
        assert len(kinds[(price, "learned")]) == 1 and len(kinds[(price, "self")]) == 1
    # A point's objective is its control objective plus the price of its computations (a cost).
    for point in pareto["points"]:
        assert point["objective"] == pytest.approx(point["control_objective"] + point["price"] * point["computations"])
    # The oracle is marked as one wherever it appears: a reference that knows the future.
    assert all(p["clairvoyant"] == (p["kind"] == "oracle") for p in pareto["points"])
    assert "The oracle knows the future: a reference, not a policy." in (out / "SWEEP.md").read_text()
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".json" and p.name != "pareto.json"}
    again = sw.sweep("cart_pendulum", out, TINY, workers=1, progress=False)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name in before} == before  # reused, not redone
    assert again["points"] == pareto["points"]
    other = sw.SweepSettings(prices=(1e-4,), episodes=1, thresholds=(0.3,), futures=1, horizon=2)
    with pytest.raises(EtmpcError, match="other settings"):
        sw.sweep("cart_pendulum", out, other, workers=1, progress=False)


def test_each_price_has_its_own_learned_policy_trained_and_played_at_that_price(tiny_sweep):
    out, pareto = tiny_sweep
    for i, price in enumerate(TINY.prices):
        policy = json.loads((out / f"train_{i}" / "selected.json").read_text())
        assert policy["hyperparameters"]["recompute_price"] == price and policy["domain"] == "cart_pendulum/balance"
        checkpoint = json.loads((out / f"train_{i}" / "checkpoint.json").read_text())
        assert checkpoint["config"]["recompute_price"] == price and checkpoint["config"]["algorithm"] == "dpi"
        learned = json.loads((out / f"learned_{i}.json").read_text())
        assert learned["recompute_price"] == price and list(learned["policies"]) == [f"rl:{out / f'train_{i}' / 'selected.json'}"]
        own = json.loads((out / f"self_policy_{i}.json").read_text())
        assert own["hyperparameters"]["recompute_price"] == price and own["domain"] == "cart_pendulum/balance"
        played = json.loads((out / f"self_{i}.json").read_text())
        assert played["recompute_price"] == price and list(played["policies"]) == [f"self:{out / f'self_policy_{i}.json'}"]


def test_the_best_periodic_schedule_changes_with_the_price_as_the_evaluations_say(tiny_sweep):
    out, pareto = tiny_sweep
    fixed = json.loads((out / "fixed.json").read_text())
    for i, price in enumerate(TINY.prices):
        runs = [r for r in fixed["runs"] if r["policy"].startswith("every:")]
        brute = min(runs, key=lambda r: (r["control_objective"] + price * r["recomputes"], r["policy"]))["policy"]
        assert pareto["answers"][i]["best_periodic"] == brute
        assert json.loads((out / f"price_{i}.json").read_text())["policies"].keys() == {f"rollout:{brute}:1:2", f"oracle:{brute}"}


def test_the_figure_draws_the_points_of_the_json(tiny_sweep):
    _, pareto = tiny_sweep
    fig = curves.draw_pareto(pareto)
    ax = fig.axes[0]
    first = [p for p in pareto["points"] if p["price"] == TINY.prices[0]]
    (dots,) = [line for line in ax.get_lines() if line.get_gid() == "periodic-points"]
    np.testing.assert_allclose(
        dots.get_xydata(), [[p["computations"], p["control_objective"]] for p in first if p["kind"] == "periodic"]
    )
    assert any(not p["on_front"] for p in first if p["kind"] == "periodic")  # a front, not every schedule
    for kind in ("periodic", "event"):
        (line,) = [line for line in ax.get_lines() if line.get_gid() == kind]
        rows = sorted((p for p in first if p["kind"] == kind and p.get("on_front", True)), key=lambda p: p["computations"])
        np.testing.assert_allclose(line.get_xydata(), [[p["computations"], p["control_objective"]] for p in rows])
    for price in TINY.prices:
        for kind in ("rollout", "learned", "self", "oracle"):
            (dots,) = [c for c in ax.collections if c.get_gid() == f"{kind}@{price!r}"]
            rows = [p for p in pareto["points"] if p["price"] == price and p["kind"] == kind]
            np.testing.assert_allclose(dots.get_offsets(), [[p["computations"], p["control_objective"]] for p in rows])
    oracle = [c for c in ax.collections if c.get_gid().startswith("oracle@")]
    assert all(np.all(c.get_facecolors()[:, 3] == 0) for c in oracle)  # hollow: drawn as a reference
    assert "oracle: knows the future" in ax.get_title()
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_the_report_section_gives_each_prices_answer(tiny_sweep):
    _, pareto = tiny_sweep
    lines = front_numbers.report_section(pareto)
    rows = [line for line in lines if line.startswith("| ") and not line.startswith("| price")]
    assert len(rows) == len(TINY.prices)
    for row, answer in zip(rows, pareto["answers"], strict=True):
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert cells[0] == f"{answer['price']:g}" and cells[1] == f"`{answer['best_periodic']}`"
        for cell, kind in zip(cells[2:], ("rollout", "learned", "self", "best_event", "oracle"), strict=True):
            found = answer[kind]
            assert (
                cell == "outside the periodic range"
                if found is None
                else (
                    cell.startswith(f"`{front_numbers.short_name(found['policy'])}`")
                    and f"{found['gain_percent']:+.2f} %" in cell
                )
            )


def test_a_sweep_with_the_tasks_options_plays_and_trains_every_stage_with_them(tmp_path):
    from etmpc.systems import system_key

    calm = (("disturbances.disturbance_scale", "0.0"),)  # the balance task without its disturbance
    settings = sw.SweepSettings(
        prices=(5e-5,), episodes=1, thresholds=(0.3,), futures=1, horizon=2, learner=TINY_LEARNER, self_trigger=None, options=calm
    )
    out = tmp_path / "calm"
    pareto = sw.sweep("cart_pendulum", out, settings, workers=1, progress=False)
    fixed, priced = (json.loads((out / name).read_text()) for name in ("fixed.json", "price_0.json"))
    assert fixed["options"] == priced["options"] == {"disturbances.disturbance_scale": "0.0"}
    checkpoint = json.loads((out / "train_0" / "checkpoint.json").read_text())
    assert checkpoint["config"]["options"] == [["disturbances.disturbance_scale", "0.0"]]
    assert json.loads((out / "learned_0.json").read_text())["options"] == fixed["options"]
    # the fixed stage's numbers are evaluate's with the same options, and not the task's without them
    alone = evaluate(system_key("cart_pendulum", None, dict(calm)), ["every:3"], 1, workers=1, progress=False).to_json()
    plain = evaluate("cart_pendulum", ["every:3"], 1, workers=1, progress=False).to_json()
    ours = [r["objective"] for r in fixed["runs"] if r["policy"] == "every:3"]
    assert ours == [alone["runs"][0]["objective"]] != [plain["runs"][0]["objective"]]
    assert "with --option disturbances.disturbance_scale=0.0" in (out / "SWEEP.md").read_text()
    assert pareto["settings"]["options"] == [["disturbances.disturbance_scale", "0.0"]]
    without = sw.SweepSettings(
        prices=(5e-5,), episodes=1, thresholds=(0.3,), futures=1, horizon=2, learner=TINY_LEARNER, self_trigger=None
    )
    with pytest.raises(EtmpcError, match="other settings"):
        sw.sweep("cart_pendulum", out, without, workers=1, progress=False)
    assert "options" not in without.to_json()  # a sweep without options is written as before (an older one continues)
