"""A recorded episode in 3-D, for a system that declares where its scene sits
(:class:`etmpc.systems.space.Space`, carried by :attr:`EpisodeRecord.space <etmpc.loop.records.EpisodeRecord>`).

Under the episode's root, in ``space/`` (z up; each entity in metres):

- ``path``: the realised position, steps ``0..S``, as one line (static: the whole flight);
- ``position``: the position at each step, a point on the ``step`` and ``time`` timelines, so the
  viewer's time cursor moves it;
- ``plan``: each plan's predicted positions as a line, logged at the step it came into force (the
  step it was made for, on a task without latency), coloured by when it was made (as its time series):
  at any step the view shows the plan in force;
- ``target``: the target at each step (a red point), from the episode's signals;
- ``force``: the force on the body at each step (a force's signals), an arrow from the position,
  ``Space.force_scale`` metres per newton; none at a step without force;
- ``box``: the box the body must stay in, as its edges (static).

A system without a space gets none of these: its recording is what it was.
"""

from __future__ import annotations

import numpy as np

from etmpc.views import blueprint as look
from etmpc.views.layout import _timeline
from etmpc.loop.records import EpisodeRecord

TARGET = (230, 40, 40)  # red
FORCE = (240, 200, 40)  # yellow
POINT_RADIUS_M, TARGET_RADIUS_M = 0.04, 0.05


def log_space(rr, stream, root: str, record: EpisodeRecord, dt: float) -> list[str]:
    """Log the episode's ``space/…`` entities (none without a space); returns their paths, relative to ``root``."""
    space = record.space
    if space is None:
        return []
    n = record.steps
    at = [record.state_names.index(name) for name in space.position]
    where = f"{root}/space"
    written = ["space"]
    stream.log(where, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def send(entity, steps, columns, **style):
        stream.send_columns(f"{where}/{entity}", _timeline(steps, dt), columns)
        if style:
            stream.log(f"{where}/{entity}", getattr(rr, style.pop("kind")).from_fields(**style), static=True)
        written.append(f"space/{entity}")

    flight = record.states[: n + 1, at]
    line = rr.Radius.ui_points(look.REALISED_WIDTH)
    stream.log(f"{where}/path", rr.LineStrips3D([flight], colors=[look.REALISED], radii=[line]), static=True)
    written.append("space/path")
    send(
        "position",
        np.arange(n + 1),
        rr.Points3D.columns(positions=flight),
        kind="Points3D",
        colors=[look.REALISED],
        radii=[POINT_RADIUS_M],
    )
    if record.plans:
        made = np.array([k for k, *_ in record.plans])
        arrived = np.array(record.arrivals) if len(record.arrivals) == len(made) else made
        strips = [states[:, at] for _, states, *_ in record.plans]
        send(
            "plan",
            arrived,
            rr.LineStrips3D.columns(strips=strips, colors=look.plan_colours(made, n)),
            kind="LineStrips3D",
            radii=[rr.Radius.ui_points(look.PLAN_WIDTH)],
        )
    if space.target is not None:
        target = np.column_stack([record.signals[name][:n] for name in space.target])
        send(
            "target",
            np.arange(n),
            rr.Points3D.columns(positions=target),
            kind="Points3D",
            colors=[TARGET],
            radii=[TARGET_RADIUS_M],
        )
    if space.force is not None:
        force = np.column_stack([record.signals[name][:n] if name else np.zeros(n) for name in space.force])
        on = np.any(force != 0, axis=1)  # an arrow where there is a force, none elsewhere
        arrows = rr.Arrows3D.columns(vectors=force[on] * space.force_scale, origins=flight[:n][on])
        send("force", np.arange(n), arrows.partition(on.astype(np.int64)), kind="Arrows3D", colors=[FORCE])
    if space.box is not None:
        low, high = (np.asarray(corner, float) for corner in space.box)
        box = rr.Boxes3D(centers=[(low + high) / 2], half_sizes=[(high - low) / 2], colors=[look.BOUND])
        stream.log(f"{where}/box", box, static=True)
        written.append("space/box")
    return written
