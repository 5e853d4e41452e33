"""Captions on video frames: what ``etmpc render`` shows of time in the loop (the plan in force, a solve in
flight, a plan coming into force), read back from the encoded video."""

import av
import numpy as np

import etmpc.views.render as render_mod
from etmpc.views.render import render_rollout
from etmpc.views.solves import PLAIN, SOLVING
from etmpc.views.video import caption_frames

W, H = 640, 480


def test_a_caption_is_written_over_the_top_left_corner_only():
    frames = [np.full((120, 160, 3), 90, np.uint8) for _ in range(3)]
    captions = [[("step 0", PLAIN)], [], [("step 2", PLAIN), ("solving (started step 2, arrives step 3)", SOLVING)]]
    out = list(caption_frames(frames, captions))
    assert [f.shape for f in out] == [(120, 160, 3)] * 3 and all(f.dtype == np.uint8 for f in out)
    np.testing.assert_array_equal(out[1], frames[1])  # no lines: the frame as it was
    for frame, before, lines in ((out[0], frames[0], 1), (out[2], frames[2], 2)):
        rows, cols = np.nonzero((frame != before).any(axis=2))
        assert cols.min() == 0 and rows.min() == 0 and rows.max() < 12 * lines + 6  # a band of a line's height each
        np.testing.assert_array_equal(frame[rows.max() + 1 :], before[rows.max() + 1 :])
    r, g, b = (out[2][:30, :, c].astype(int) for c in range(3))
    assert ((r > 180) & (g > 140) & (b < 100)).any()  # the yellow of a solve in flight


def decode(path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(container.streams.video[0])]


def coloured(frame) -> dict[str, int]:
    """How many pixels of the caption band are of each caption's colour: white (the plan in force),
    yellow (a solve in flight), green (a new plan), told apart loosely (the encoder blurs thin text)."""
    r, g, b = (frame[: H // 6, :, c].astype(int) for c in range(3))
    return {
        "plain": int(((r > 170) & (g > 170) & (b > 170)).sum()),
        "solving": int(((r > 150) & (g > 110) & (b < 100) & (r - b > 100)).sum()),
        "new": int(((g > 150) & (g - r > 50)).sum()),
    }


def test_render_captions_each_frame_on_a_late_task_only(tmp_path, monkeypatch):
    """The scene drawn black (fast): what is left is the caption. ``every:3`` on a task whose plans arrive
    an interval late: frames 3, 6, 9, … say "solving", frames 4, 7, 10, … "NEW PLAN"; the paper's task
    gets no caption."""
    monkeypatch.setattr(
        render_mod, "iter_frames", lambda system, env, states, w, h: (np.zeros((h, w, 3), np.uint8) for _ in states)
    )
    result = render_rollout("cart_pendulum/kicks_late", "every:3", 0, tmp_path / "v.mp4", width=W, height=H)
    frames = decode(result.path)
    traj = result.trajectory
    assert len(frames) == traj.steps + 1 == 151
    starts = set(np.flatnonzero(traj.recompute[: traj.steps])) - {0}
    arrivals = set(traj.arrivals)
    assert arrivals == {0} | {s + 1 for s in starts}
    for i, frame in enumerate(frames):
        seen = coloured(frame)
        assert seen["plain"] > 200, (i, seen)  # the plan in force, on every frame
        assert (seen["solving"] > 30) == (i in starts), (i, seen)
        assert (seen["new"] > 30) == (i in arrivals), (i, seen)
        assert frame[H // 6 :].max() < 30  # nothing below the caption
    plain = render_rollout("cart_pendulum/kicks", "every:3", 0, tmp_path / "k.mp4", width=W, height=H)
    assert max(f.max() for f in decode(plain.path)) < 30  # no caption on the paper's task
