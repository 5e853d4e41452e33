"""A real Ctrl-C or SIGTERM, told apart from the same exceptions raised by someone's code.

A trigger under test runs inside etmpc's loop. If its code raises ``KeyboardInterrupt`` or
``SystemExit``, that must not end the command as if the user had stopped it (silently, with the
trigger's own exit code): it is the trigger's failure, reported as one line naming it. A Ctrl-C the
user typed must still stop the command (exit 130). Within :func:`watching`, SIGINT is noted before
it raises ``KeyboardInterrupt``, so :func:`genuine` can tell the two apart.
"""

from __future__ import annotations

import contextlib
import signal
import threading

from etmpc.common.errors import EtmpcError, Terminated

_received = 0  # SIGINTs noted by the handler of watching()


def _on_sigint(signum, frame):
    global _received
    _received += 1
    raise KeyboardInterrupt


@contextlib.contextmanager
def watching():
    """Note every Ctrl-C while inside (it still raises ``KeyboardInterrupt``). Only in the main thread,
    and only where SIGINT has Python's default handler; elsewhere it changes nothing."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def genuine(exc: BaseException) -> bool:
    """True when ``exc`` is the user's or the system's doing, to let through: an :class:`EtmpcError`
    (already one line), a SIGTERM turned into :class:`Terminated`, or a Ctrl-C. A
    ``KeyboardInterrupt`` counts as a Ctrl-C when :func:`watching` noted one, or where SIGINT keeps
    Python's default handler (nothing tells them apart there); where SIGINT is ignored (a worker
    process) it was raised by code. Anything else (``SystemExit`` included) is code's failure."""
    if isinstance(exc, (EtmpcError, Terminated)):
        return True
    if isinstance(exc, KeyboardInterrupt):
        handler = signal.getsignal(signal.SIGINT)
        return _received > 0 if handler is _on_sigint else handler is signal.default_int_handler
    return False


def described(exc: BaseException) -> str:
    """``Name: message`` of an exception, in one line (``SystemExit(3)`` for an exit)."""
    if isinstance(exc, SystemExit):
        return f"SystemExit({exc.code!r})"
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
