"""What people look at, drawn from what the floors below produce; views receive, and draw. Rerun
recordings (:mod:`~etmpc.views.schema`: what a file holds; :mod:`~etmpc.views.recording`: the writer,
of what :class:`etmpc.loop.records.EpisodeRecord` keeps of an episode; :mod:`~etmpc.views.blueprint`:
how it reads in the viewer; :mod:`~etmpc.views.replay`: reading it back; :mod:`~etmpc.views.solves`:
each solve's start and arrival, the plan in force), figures (:mod:`~etmpc.views.figures`,
:mod:`~etmpc.views.curves`) and video (:mod:`~etmpc.views.video`; ``etmpc render``,
:mod:`~etmpc.views.render`, plays one episode as ``evaluate`` does and draws it). A recording goes to a file or
a live viewer (:mod:`~etmpc.views.sinks`); :class:`~etmpc.views.logger.RerunLogger` records any Gymnasium
episode of an etmpc environment.

This package may import every floor below it: ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``,
``etmpc.loop``, ``etmpc.policies``, ``etmpc.evaluation``, ``etmpc.envs`` and ``etmpc.learning``; none of
them imports it (nor Rerun or matplotlib): evaluation and learning are given what records and draws.
"""


def __getattr__(name: str):
    """``etmpc.views.RerunLogger`` (:mod:`etmpc.views.logger`), imported when first asked for: ``import
    etmpc.views.video`` loads no Rerun."""
    if name == "RerunLogger":
        from etmpc.views.logger import RerunLogger

        return RerunLogger
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
