"""``etmpc render``: play one test-set episode as ``evaluate`` does, and write its video (and recording).
On a task with time in the loop each frame is captioned: the plan in force, a new plan coming into force,
a solve in flight (``etmpc.views.solves.frame_captions``)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.progress import Progress
from etmpc.evaluation.workers import context, play_test_episode
from etmpc.loop import Trajectory, announcer
from etmpc.policies import parse_policy
from etmpc.evaluation.inputs import check_shipped
from etmpc.evaluation.testsets import check_options_act
from etmpc.systems import SystemKey, system_class, system_key
from etmpc.views.recording import Recorder
from etmpc.views.solves import frame_captions
from etmpc.views.video import caption_frames, check_display, check_framebuffer, check_scene, check_size, iter_frames, write_video


@dataclass(frozen=True)
class RenderResult:
    path: Path
    frames: int  # frames written: the trajectory's steps + 1 (its finite states)
    fps: float
    trajectory: Trajectory


def render_rollout(
    domain: str | SystemKey,
    policy_spec: str,
    episode: int,
    out: str | Path,
    seed: int = 0,
    width: int = 640,
    height: int = 480,
    fps: float | None = None,
    testset_path: str | None = None,
    record: str | Path | None = None,
    progress: bool = True,
) -> RenderResult:
    """Play test-set ``episode`` of task ``domain`` (its name, or a :class:`~etmpc.systems.SystemKey` with its
    options) under ``policy_spec`` exactly as ``etmpc evaluate`` does (repeat 0 of ``seed``) and write its video
    to ``out``, at one frame per control interval by default. With ``record``, also write the episode, its
    frames included, into that Rerun recording. ``progress``: the frames drawn and the time left, on stderr."""
    check_display()  # before any domain is imported: an on-screen backend warns without a display
    domain = system_key(domain)  # a task's name, or a SystemKey (a task with its options)
    check_options_act(domain, testset_path, takes_test_set=False)  # an option the stored episodes cannot feel
    check_scene(system_class(domain.task))
    check_size(width, height)
    system, env, _ = context(domain, testset_path)
    check_framebuffer(env.physics, width, height)
    check_shipped(policy_spec)
    policy = parse_policy(policy_spec, system)
    # An out-of-range index raises TestSetError (an EtmpcError) before anything is drawn.
    played = play_test_episode(domain, policy, seed, 0, episode, testset_path)
    system, env, traj = played.system, played.env, played.trajectory
    fps = 1.0 / env.control_timestep() if fps is None else fps
    states = traj.states[: traj.steps + 1]
    states = states[np.all(np.isfinite(states), axis=1)]  # an episode that diverged ends on a NaN row
    kept = played.record(policy_spec, announcer(policy))
    with Progress(len(states), enabled=progress, unit="frames") as bar:  # the frames drawn, as the encoder takes them
        frames: Iterable[np.ndarray] = _counted(iter_frames(system, env, states, width, height), bar)
        if kept.timed:  # time in the loop: each frame says which plan is in force, and which solve is in flight
            frames = caption_frames(frames, frame_captions(kept, bool(system.compute_levels)))
        if record is None:  # frames go straight into the encoder
            count = write_video(frames, out, fps)
        else:
            frames = list(frames)
            count = write_video(frames, out, fps)
            with Recorder(record) as recorder:
                recorder.log_episode(kept, frames)
    return RenderResult(path=Path(out), frames=count, fps=fps, trajectory=traj)


def _counted(frames: Iterable[np.ndarray], bar: Progress) -> Iterator[np.ndarray]:
    """``frames``, each counted on ``bar`` as the encoder takes it."""
    for frame in frames:
        bar.update()
        yield frame
