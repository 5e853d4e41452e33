"""The loop's two modes (etmpc.loop.modes), chosen once when a ClosedLoop is made: a recording loop starts
episodes and never resumes a snapshot, a light loop continues a snapshot and never starts an episode. A
refused call leaves the loop as it was: it then plays what the other mode plays, bit for bit."""

import numpy as np
import pytest

from etmpc.loop import ClosedLoop, Snapshot
from etmpc.systems import make_system


def test_each_mode_refuses_the_others_start_and_then_plays_as_the_other_does():
    system = make_system("cart_pendulum/kicks")
    recording = ClosedLoop(system, system.make_env()).reset(system.draw_episode(np.random.default_rng(0)))
    recording.step(True)
    snapshot = Snapshot.take(recording.observed_state(context=True).context)
    with pytest.raises(RuntimeError, match="only a light loop"):
        recording.resume(snapshot)

    light = ClosedLoop(system, system.make_env(), records=False)
    with pytest.raises(RuntimeError, match="use resume"):
        light.reset()
    assert not hasattr(light, "trajectory")  # nothing was started
    light.resume(snapshot)

    for answer in (False, False, True, False):
        assert light.step(answer) == recording.step(answer)
        assert np.array_equal(light.x, recording.x) and light.age == recording.age
    assert recording.trajectory.steps == light.step_index == 5
