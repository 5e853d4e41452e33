"""Where a task's scene sits in 3-D, for the recordings' 3-D view (:mod:`etmpc.views.space`): which of
its states are a position, which of its signals a target and a force on the body, and the box it must
stay in. A system that has one declares it as a class attribute, ``space = Space(...)``; a system
without one (``getattr(system, "space", None)`` is None) is drawn in time series only.

It names states and signals (``System.state_names``, ``System.signals``) rather than holding arrays,
so it is small and picklable: the recording's :class:`~etmpc.loop.records.EpisodeRecord` carries it.
"""

from __future__ import annotations

from dataclasses import dataclass

Triple = tuple[float, float, float]


@dataclass(frozen=True)
class Space:
    """A position in 3-D (m) and what is drawn about it."""

    position: tuple[str, str, str]  # the state names of x, y, z (m)
    target: tuple[str, str, str] | None = None  # the signal names of a target's x, y, z (m), per step
    force: tuple[str | None, str | None, str | None] | None = None  # the signal names of a force's components (None: 0)
    box: tuple[Triple, Triple] | None = None  # (lowest corner, highest corner) (m): a geofence, drawn as its edges
    force_scale: float = 1.0  # the force's arrow, in metres per newton

    def __post_init__(self):
        triples = [self.position, self.target, self.force, *(self.box or ())]
        if any(t is not None and len(t) != 3 for t in triples):
            raise ValueError(f"a space's position, target, force and box corners each have three entries: {self}")
        if self.force is not None and all(name is None for name in self.force):
            raise ValueError("a space's force names at least one signal")
