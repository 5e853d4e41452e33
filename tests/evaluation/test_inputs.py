"""What a policy spec reads (``policy_files``): its own file, and through a kind that wraps another (a rollout, an
oracle, a shield with or without its numbers) its base's, so that a kept leaderboard row is played again when the
wrapped file changes and no output may land on it."""

import pytest

from etmpc.evaluation.inputs import policy_files
from tests.conftest import REPO

DPI = REPO / "policies" / "quadrotor" / "waypoints" / "learned.json"


@pytest.mark.parametrize(
    "spec",
    [
        f"rl:{DPI}",
        f"shield:rl:{DPI}",
        f"shield:10:rl:{DPI}",
        f"shield:10:0.25:rl:{DPI}",
        f"rollout:rl:{DPI}:4:10",
        f"oracle:rl:{DPI}",
    ],
)
def test_a_wrapped_policys_file_is_read(spec):
    assert policy_files(spec) == [DPI]


@pytest.mark.parametrize("spec", ["every:3", "shield:10:0.25:every:7", "threshold:0.2:reading", f"shield:10:rl:{DPI}.missing"])
def test_a_spec_that_names_no_existing_file_reads_none(spec):
    assert policy_files(spec) == []
