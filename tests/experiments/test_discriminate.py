"""``etmpc discriminate``: the periodic schedules, the task's event triggers, the clairvoyant reference and the
rollout policy on the first test-set episodes, each state-dependent policy against the periodic front at its
own rate; the table it prints and the JSON it writes agree with the evaluations they come from."""

import json

import numpy as np

from etmpc.cli import main
from etmpc.systems import make_system


def test_discriminate_picks_the_best_periodic_schedule_and_compares_at_equal_rate(tmp_path, capsys):
    out = tmp_path / "sub" / "discriminate.json"
    price = 1e-3
    assert (
        main(
            [
                "discriminate",
                "--task",
                "cart_pendulum",
                "--episodes",
                "2",
                "--price",
                str(price),
                "--workers",
                "1",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    found = json.loads(out.read_text())
    system = make_system("cart_pendulum")
    assert found["price"] == price and found["priced"]["recompute_price"] == price
    assert found["fixed"]["recompute_price"] == system.recompute_price  # the fixed policies at the task's own price

    runs = found["fixed"]["runs"] + found["priced"]["runs"]
    by_policy = {}
    for run in runs:
        by_policy.setdefault(run["policy"], []).append(run)
    assert all(sorted(r["episode"] for r in played) == [0, 1] for played in by_policy.values())
    periodic = [f"every:{t}" for t in range(1, system.horizon + 1)]
    mean = {spec: np.mean([r["control_objective"] + price * r["recomputes"] for r in by_policy[spec]]) for spec in periodic}
    best = min(periodic, key=lambda spec: (mean[spec], spec))
    assert found["best_periodic"] == best and printed.startswith(
        f"cart_pendulum: best periodic schedule at price {price:g}: {best}; 2 episodes, "
    )
    events = [f"threshold:{x:g}" for x in system.benchmark.sweep_thresholds]
    assert list(found["rows"]) == [*events, f"oracle:{best}", f"rollout:{best}:4:20"]
    assert set(by_policy) == {*periodic, *found["rows"]}

    compared = 0
    for spec, row in found["rows"].items():
        if row is None:
            assert f"{spec:28s} outside the periodic schedules' range of rates" in printed
            continue
        compared += 1
        assert row["episodes"] == 2 and set(row["between"]) <= set(periodic)
        assert row["computations"] == np.mean([r["recomputes"] for r in by_policy[spec]])
        assert np.isclose(row["control_objective"], np.mean([r["control_objective"] for r in by_policy[spec]]), rtol=1e-12)
        ci = f"{row['gain_percent_ci95']:.2f} %"
        line = f"{spec:28s} {row['computations']:12.1f}  {row['gain_percent']:+18.2f} % ± {ci:>8s}  {row['better_episodes']}/2"
        assert line in printed.splitlines()
    assert compared >= 1 and printed.rstrip().endswith(f"wrote {out}")


def test_discriminate_refuses_bad_input_before_playing(tmp_path, capsys):
    assert main(["discriminate", "--task", "pendulum"]) == 2
    assert "unknown task 'pendulum'" in capsys.readouterr().err
    assert main(["discriminate", "--task", "battery", "--episodes", "0"]) == 2
    assert "--episodes" in capsys.readouterr().err
    assert main(["discriminate", "--task", "battery", "--json", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a directory" in err
