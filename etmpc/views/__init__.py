"""What people look at, drawn from what the other floors produce; views only receive. Rerun
recordings (:mod:`~etmpc.views.schema`: what a file holds; :mod:`~etmpc.views.recording`: the writer,
of what :class:`etmpc.loop.records.EpisodeRecord` keeps of an episode; :mod:`~etmpc.views.blueprint`:
how it reads in the viewer; :mod:`~etmpc.views.replay`: reading it back; :mod:`~etmpc.views.solves`:
each solve's start and arrival, the plan in force), figures (:mod:`~etmpc.views.figures`,
:mod:`~etmpc.views.curves`) and video (:mod:`~etmpc.views.video`).

This package may import ``etmpc.common``, ``etmpc.control``, ``etmpc.systems``, ``etmpc.loop`` and
``etmpc.policies``; no controller, system or policy imports it (nor Rerun or matplotlib).
"""
