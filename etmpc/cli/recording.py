"""``--record`` and ``--spawn`` on the command line. A recording's file arrives as a ``Path``, a viewer's URL as
a ``str`` (:func:`etmpc.cli.types.recording`). A file is opened by the command that writes it; a viewer to stream
to (a URL, ``--spawn``) is opened here, and so checked before any work, and closed if the run fails."""

from __future__ import annotations

import contextlib
from pathlib import Path


def file_of(record) -> Path | None:
    """``--record``'s file, or None (none given, or a viewer's URL)."""
    return record if isinstance(record, Path) else None


@contextlib.contextmanager
def viewer(args):
    """A :class:`~etmpc.views.recording.Recorder` streaming to ``--record URL`` or a ``--spawn``-ed viewer (and
    writing ``--record``'s file too, if one is given with ``--spawn``), or None when no viewer is asked for;
    closed without keeping its file if the run fails (else the run closes it)."""
    live = None
    if args.spawn or isinstance(args.record, str):
        from etmpc.views.recording import Recorder

        live = Recorder(args.record, spawn=args.spawn)
    try:
        yield live
    except BaseException:
        if live is not None:
            live.close(keep=False)
        raise


def recorded(record, live) -> str:
    """The line that says where the episodes went."""
    if live is None:
        return f"wrote {record} (open it with: rerun {record}; summarise it with: etmpc replay {record})"
    wrote = f" and wrote {live.destinations.path}" if live.destinations.path is not None else ""
    return f"streamed the episodes to {', '.join(live.destinations.urls)}{wrote}"
