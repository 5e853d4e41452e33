"""Rendering: the state goes back into MuJoCo with the system's conventions, the video holds one
frame per state, and a failed render leaves nothing under the final name."""

import av
import numpy as np
import pytest

from etmpc.systems.cart_pendulum.model import Parameters
from etmpc.common.errors import EtmpcError
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.views.render import render_rollout
from etmpc.views.video import render_frames, write_video
from etmpc.evaluation.workers import policy_rng

W, H = 160, 120


@pytest.fixture(scope="module")
def rollout(tmp_path_factory):
    return render_rollout(
        "cart_pendulum", "every:3", episode=0, out=tmp_path_factory.mktemp("video") / "x.mp4", width=W, height=H
    )


def decode(path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264" and stream.codec_context.pix_fmt == "yuv420p"
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(stream)]


def test_video_has_one_frame_per_state(rollout):
    traj = rollout.trajectory
    assert traj.steps == 100 and not traj.nonfinite
    assert rollout.frames == traj.steps + 1 and rollout.fps == pytest.approx(10.0)
    frames = decode(rollout.path)
    assert len(frames) == traj.steps + 1
    assert all(f.shape == (H, W, 3) for f in frames)
    assert not list(rollout.path.parent.glob(".*.part"))  # the temporary file was renamed
    # The pendulum moves: the first and a late frame differ a lot, and most consecutive frames differ.
    first, late = frames[0].astype(int), frames[80].astype(int)
    assert np.abs(first - late).max() > 100
    moving = [np.abs(a.astype(int) - b.astype(int)).max() > 30 for a, b in zip(frames, frames[1:])]
    assert np.mean(moving) > 0.8


def test_video_shows_the_trajectory(rollout, cart_system):
    """The decoded video is the rendering of the trajectory's states (up to lossy compression)."""
    env = cart_system.make_env()
    env.reset()
    traj = rollout.trajectory
    frames = decode(rollout.path)
    for i in (0, 50, traj.steps):
        (expected,) = render_frames(cart_system, env, traj.states[i : i + 1], W, H)
        assert expected.shape == (H, W, 3) and expected.dtype == np.uint8
        assert np.abs(expected.astype(int) - frames[i].astype(int)).mean() < 4


def test_state_to_physics_matches_the_geometry(cart_system):
    """Pole tip at (eta + 2 l sin beta, 0, 2 l cos beta): positive beta tips the pole towards +x."""
    env = cart_system.make_env()
    env.reset()
    physics = env.physics
    length = 2 * Parameters().pole_half_length_m  # the MJCF pole runs from the pivot (cart origin) to its tip site
    for x in ([0.0, 0.0, 0.0, 0.0], [1.5, 0.3, 0.4, -0.2], [-2.0, -1.0, -0.7, 1.0], [0.5, 0.0, np.pi / 2, 0.0]):
        eta, v, beta, omega = x
        render_frames(cart_system, env, np.array([x]), W, H)
        tip = physics.named.data.site_xpos["tip"]
        np.testing.assert_allclose(tip, [eta + length * np.sin(beta), 0.0, length * np.cos(beta)], atol=1e-9)
        np.testing.assert_allclose(physics.named.data.xpos["cart"], [eta, 0.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(
            physics.named.data.cam_xpos[cart_system.camera][0], eta, atol=1e-12
        )  # the camera follows the cart
        np.testing.assert_allclose(physics.named.data.qvel[["slider", "hinge"]], [v, omega])


def test_state_round_trips_through_the_observation(cart_system, cart_testset):
    """Setting the state the system read from a time step reproduces that time step's physics."""
    env = cart_system.make_env()
    env.task.use_episode(cart_system.episode_from_arrays(cart_testset.episode_arrays(3)))
    env.reset()
    for _ in range(5):
        timestep = env.step(np.array([7.0]))
    qpos, qvel = env.physics.data.qpos.copy(), env.physics.data.qvel.copy()
    x = cart_system.state(timestep)
    other = cart_system.make_env()
    other.reset()
    render_frames(cart_system, other, x[None], W, H)
    np.testing.assert_array_equal(other.physics.data.qpos, qpos)
    np.testing.assert_array_equal(other.physics.data.qvel, qvel)


def test_bad_requests_fail_cleanly(tmp_path):
    out = tmp_path / "sub" / "x.mp4"
    with pytest.raises(EtmpcError, match="battery.*no 3-D scene"):
        render_rollout("battery", "every:3", episode=0, out=out, width=W, height=H)
    with pytest.raises(EtmpcError, match="out of range"):
        render_rollout("cart_pendulum", "every:3", episode=10**6, out=out, width=W, height=H)
    with pytest.raises(EtmpcError, match="unknown task"):
        render_rollout("nope", "every:3", episode=0, out=out)
    with pytest.raises(ValueError, match="even"):
        render_rollout("cart_pendulum", "every:3", episode=0, out=out, width=W + 1, height=H)
    assert not out.exists()
    with pytest.raises(ValueError, match="even"):
        write_video([np.zeros((H, W + 1, 3), np.uint8)], out, 10)
    assert not out.exists()


def test_failed_encoding_leaves_no_partial_file(tmp_path):
    out = tmp_path / "x.mp4"
    good = [np.full((H, W, 3), 40 * i, np.uint8) for i in range(5)]
    bad = good + [np.zeros((H + 2, W, 3), np.uint8)]  # fails after five frames went into the temporary file
    with pytest.raises(ValueError, match="frame 5"):
        write_video(bad, out, 10)
    assert list(tmp_path.iterdir()) == []
    # An existing video survives a failed rewrite untouched, and a good one replaces it.
    assert write_video(good, out, 10) == 5
    before = out.read_bytes()
    with pytest.raises(ValueError):
        write_video(iter(bad), out, 10)
    assert out.read_bytes() == before and list(tmp_path.iterdir()) == [out]
    assert len(decode(out)) == 5


def test_rollout_is_the_evaluated_episode(rollout, cart_system, cart_testset):
    """The rendered episode is repeat 0 of seed 0 on test-set episode 0, as `etmpc evaluate` plays it."""
    traj = run_episode(
        cart_system,
        cart_system.make_env(),
        parse_policy("every:3", cart_system),
        policy_rng(0, 0, 0),
        cart_system.episode_from_arrays(cart_testset.episode_arrays(0)),
    )
    np.testing.assert_array_equal(traj.states, rollout.trajectory.states)
    assert traj.recomputes == rollout.trajectory.recomputes


def test_a_frame_is_drawn_with_a_shadow_map_of_its_size_and_a_larger_one_after_it_as_from_a_fresh_physics(cart_system):
    """A small frame gets a small shadow map (MuJoCo draws the whole map at every frame); a larger frame
    after it makes the context again with a larger map, and is then the picture a physics that never drew
    a small frame draws; the model keeps its own shadowsize."""
    from etmpc.common.display import render

    camera = cart_system.camera
    drawn, fresh = cart_system.make_env().physics, cart_system.make_env().physics
    model_size = int(drawn.model.vis.quality.shadowsize)
    assert model_size == 4096  # the models' <quality shadowsize>
    small = render(drawn, 48, 64, camera)
    assert drawn.contexts.mujoco.ptr.shadowSize == 512 and drawn.model.vis.quality.shadowsize == model_size
    assert small.shape == (48, 64, 3) and small.std() > 10
    large = render(drawn, 480, 640, camera)
    assert drawn.contexts.mujoco.ptr.shadowSize == model_size
    np.testing.assert_array_equal(large, render(fresh, 480, 640, camera))
    np.testing.assert_array_equal(render(drawn, 48, 64, camera), render(fresh, 48, 64, camera))  # kept, not shrunk
    assert drawn.contexts.mujoco.ptr.shadowSize == model_size
