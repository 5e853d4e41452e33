"""A real Ctrl-C or SIGTERM, told apart from the same exceptions raised by someone's code.

A policy under test runs inside etmpc's loop. If its code raises ``KeyboardInterrupt`` or
``SystemExit``, that must not end the command as if the user had stopped it (silently, with the
policy's own exit code): it is the policy's failure, reported as one line naming it. A Ctrl-C the
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
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
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


MAX_MESSAGE = 300  # characters of someone's exception message kept in the one line


def described(exc: BaseException) -> str:
    """``Name: message`` of an exception, in one line of bounded length (``SystemExit(3)`` for an exit);
    a message that cannot even be turned into text is said to be so."""
    try:
        if isinstance(exc, SystemExit):
            return f"SystemExit({exc.code!r})"[:MAX_MESSAGE]
        text = " ".join(str(exc).split())
    except Exception:  # its __str__ or __repr__ fails too
        text = "(its message cannot be printed)"
    if len(text) > MAX_MESSAGE:
        text = text[:MAX_MESSAGE] + "…"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


READ_ONLY_HINT = "what a policy is shown is read-only: copy what you change, e.g. np.array(s.x)"


def failed(what: str, exc: BaseException) -> EtmpcError:
    """Someone's code failed: one line saying where and how (``what raised Name: message``), with a hint
    when it wrote into a read-only value it was shown."""
    hint = ""
    if (isinstance(exc, ValueError) and "read-only" in str(exc)) or (
        isinstance(exc, TypeError) and "does not support item assignment" in str(exc)
    ):
        hint = f" ({READ_ONLY_HINT})"
    return EtmpcError(f"{what} raised {described(exc)}{hint}")


@contextlib.contextmanager
def users_code(what: str):
    """Run someone's code (a policy's import, factory, members, pickling): whatever it raises, short of
    a real Ctrl-C or SIGTERM, becomes one :class:`EtmpcError` line, ``what raised Name: message``."""
    try:
        yield
    except BaseException as exc:
        if genuine(exc):
            raise
        raise failed(what, exc) from None
