"""The levels study's baselines from the field: the advanced-step RTI's extra iterations and an iteration budget
of one control interval, derived from the task's platform and checked by playing them."""

import numpy as np

from etmpc.control.timing import ITERATE
from etmpc.evaluation import testsets
from etmpc.experiments.studies import levels
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system


def test_the_budget_is_the_iterations_that_fit_in_one_interval_and_its_plans_all_arrive_one_interval_later():
    specs = levels.baselines()
    assert sorted(specs.values()) == ["iterate:1:2", "iterate:1:3", "iterate:2:3"]  # 100 ms / 30 ms: 3 fit, as AS-RTI + 2
    assert specs["AS-RTI, 2 extra iterations = budget of 3 iterations (one interval), every interval"] == "iterate:1:3"
    system = make_system(levels.TASK)
    budget = next(spec for name, spec in specs.items() if "budget" in name and name.endswith("every interval"))
    arrays = testsets.load(testsets.default_path(system.domain, "kicks"), system.domain, "kicks").episode_arrays(1)
    traj = run_episode(system, system.make_env(), parse_policy(budget, system), None, system.episode_from_arrays(arrays))
    n = traj.steps
    late = [
        arrived - started
        for started, arrived in zip(traj.starts, traj.arrivals)
        if started < n and traj.level[started] == ITERATE
    ]
    assert len(late) > 50 and set(late) == {1}  # the whole budget fits in the interval
    assert traj.work[:n][traj.level[:n] == ITERATE].max() == 3
    # one more iteration would not fit: 4 x 30 ms is past the 100 ms interval
    assert np.ceil(4 * system.config.latency.iteration_s / system.control_interval_s) == 2


def test_the_page_shows_the_baselines_and_their_best_and_a_document_made_before_them_has_no_such_section():
    row = {"spec": "iterate:1:2", "objective": 40.0, "gain": -3.5, "gain_ci95": 1.25, "recomputes": 150.0, "failures": 0.1}
    document = {"validation_episodes": 200, "iteration_s": 0.03, "baselines": {"AS-RTI, 1 extra iteration": row}}
    lines = levels._baselines_section(document)
    assert lines[0] == "## Baselines from the field (200 validation episodes)"
    assert "| AS-RTI, 1 extra iteration | `iterate:1:2` | 40.000 | -3.5 % ± 1.2 | 150.0 | 0.10 |" in lines
    assert lines[-2] == "The best of them, AS-RTI, 1 extra iteration, gains -3.5 % ± 1.2 over `iterate:1`."
    assert "30 ms" in lines[2]
    assert levels._baselines_section({"validation_episodes": 200}) == []
