"""``threshold:X:iterate`` on a task with compute levels: one SQP iteration exactly where the weighted prediction
error exceeds X (the norm written out here), a keep elsewhere; refused where there are no levels."""

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.control.timing import ITERATE, KEEP, SOLVE
from etmpc.loop import run_episode
from etmpc.policies import AugmentedState, parse_policy
from etmpc.systems import make_system

LEVELS = "cart_pendulum/kicks_levels"


def test_it_iterates_exactly_where_the_weighted_error_exceeds_the_threshold():
    system = make_system(LEVELS)
    policy, plain = parse_policy("threshold:0.2:iterate", system), parse_policy("threshold:0.2", system)
    assert policy.spec == "threshold:0.2:iterate" and plain.spec == "threshold:0.2"
    rng, seen = np.random.default_rng(3), set()
    for _ in range(300):
        x, predicted = rng.normal(scale=0.1, size=4), rng.normal(scale=0.1, size=4)
        s = AugmentedState(x, np.zeros(4), 2, predicted)
        fired = np.sqrt(np.sum((system.error_weights * (x - predicted)) ** 2)) > 0.2
        answer = policy.decide(s, None)
        assert answer == (ITERATE if fired else KEEP) and plain.decide(s, None) == fired  # plain: True is a full solve
        seen.add(answer)
    assert seen == {ITERATE, KEEP}


def test_played_it_starts_iterations_and_only_the_loop_forces_full_solves():
    system = make_system(LEVELS)
    episode = system.draw_episode(np.random.default_rng(0))
    traj = run_episode(system, system.make_env(), parse_policy("threshold:0.05:iterate", system), None, episode)
    n = traj.steps
    levels = traj.level[:n]
    assert (levels == ITERATE).any()
    assert np.all(traj.forced[:n][levels == SOLVE])  # every full solve was the loop's, not the policy's


@pytest.mark.parametrize(
    ("task", "spec", "message"),
    [
        ("cart_pendulum/kicks", "threshold:0.2:iterate", "has none"),
        (LEVELS, "threshold:0.2:solve", "only ':iterate' .* may follow"),
        (LEVELS, "threshold:-1:iterate", "finite number >= 0"),
    ],
)
def test_bad_specs_are_one_line(task, spec, message):
    with pytest.raises(EtmpcError, match=message):
        parse_policy(spec, make_system(task))
