"""Figure 1 of the paper for the battery: what is drawn is the episode's data and the plans' forecasts."""

import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np

from etmpc.figures import forecast_figure
from etmpc.loop import run_episode
from etmpc.policies import parse_policy

ROOT = Path(__file__).resolve().parents[1]


def test_forecast_figure_draws_truth_and_every_plans_forecast(battery_system, battery_testset):
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(0))
    traj = run_episode(battery_system, battery_system.make_env(), parse_policy("every:20", battery_system.error_weights),
                       None, episode)
    fig = forecast_figure(episode, [("every:20", traj)], dt_s=10.0, mean_price=0.05)
    production_ax, price_ax = fig.axes
    for ax, true, key in ((production_ax, episode.production_kw, "production_kw"), (price_ax, episode.price_eur_kwh, "price_eur_kwh")):
        solid = [line for line in ax.get_lines() if line.get_linestyle() == "-" and line.get_marker() in ("None", "")]
        dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
        np.testing.assert_array_equal(solid[0].get_ydata(), true[:100])
        assert len(dashed) == len(traj.plans) == 5
        for line, (k, plan) in zip(dashed, traj.plans):
            np.testing.assert_array_equal(line.get_xdata(), (k + np.arange(20)) * 10.0)
            np.testing.assert_array_equal(line.get_ydata(), plan.forecasts[key])
            assert plan.forecasts[key][0] == true[k]  # the forecast starts at the true value


def test_script_writes_a_png(tmp_path):
    out = tmp_path / "fig1.png"
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "figure_forecasts.py"), "--episode", "5", "--out", str(out)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    image = matplotlib.image.imread(out)
    assert image.shape[0] > 400 and image.shape[1] > 400 and image.std() > 0.05


def test_script_rejects_a_bad_episode(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "figure_forecasts.py"), "--episode", "100",
                             "--out", str(tmp_path / "x.png")], capture_output=True, text=True)
    assert result.returncode == 2 and "out of range" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "x.png").exists()
