"""Gymnasium's ``RecordVideo`` on an etmpc environment: it writes its MP4 with moviepy, which the ``video`` extra
installs (``pip install 'etmpc[video]'``). The video is read back with PyAV (etmpc's own encoder, independent of
moviepy): one frame at the reset and one per step (less moviepy's own rounding of the last)."""

from __future__ import annotations

import importlib.util
import tomllib

import gymnasium as gym
import pytest

import etmpc  # noqa: F401 (registers the environments)
from tests.conftest import REPO


def test_the_video_extra_installs_moviepy_and_the_base_install_does_not():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert any(req.startswith("moviepy") for req in project["optional-dependencies"]["video"])
    assert not any(req.startswith("moviepy") for req in project["dependencies"])
    assert "video" in next(req for req in project["optional-dependencies"]["test"] if req.startswith("etmpc["))


@pytest.mark.skipif(importlib.util.find_spec("moviepy") is None, reason="moviepy is not installed: pip install 'etmpc[video]'")
def test_record_video_writes_an_mp4_with_a_frame_per_step_and_one_at_the_reset(tmp_path):
    import av

    env = gym.make("etmpc/cart_pendulum-balance-v0", render_mode="rgb_array", width=160, height=120)
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda episode: True, fps=10)
    env.reset(options={"test_episode": 0})
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(int(steps % 4 == 0))
        steps, done = steps + 1, terminated or truncated
    env.close()  # the video is written when its episode ends, at the latest here
    videos = sorted(tmp_path.glob("*.mp4"))
    assert len(videos) == 1, sorted(p.name for p in tmp_path.iterdir())
    with av.open(str(videos[0])) as container:
        frames = [frame.to_ndarray(format="rgb24") for frame in container.decode(container.streams.video[0])]
    assert steps == gym.spec("etmpc/cart_pendulum-balance-v0").max_episode_steps
    # RecordVideo keeps steps + 1 frames; moviepy's ImageSequenceClip may drop the last one when the duration
    # (frames / fps) rounds down in floating point (moviepy issue #2507: 101 frames at 10 fps are 100.999...).
    assert steps <= len(frames) <= steps + 1
    assert frames[0].shape == (120, 160, 3)
