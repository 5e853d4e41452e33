"""Where a recording's episodes go (:class:`Destinations`): a ``.rrd`` file, and a Rerun viewer to stream to, as
Rerun users expect.

* **A file**: written beside its name and renamed when complete, so a file under its name is always whole.
* **Connect** to a viewer (or a Rerun server) already running: its URL, ``rerun+http://HOST:PORT/proxy``, the
  one ``rerun`` prints when it starts (``rerun://`` and ``rerun+https://`` too). ``tcp://HOST:PORT``, how
  viewers were addressed before Rerun 0.23, means the same gRPC server: ``rerun+http://HOST:PORT/proxy``.
* **Spawn** a viewer for the run (``--spawn``, Rerun's ``spawn``): where there is a screen only.

Each is checked when the recording is made, before any episode is played: a URL that nothing answers, or a
viewer that cannot start here, is one line (Rerun itself would log errors at the end of the run and drop the
data). The episodes themselves are logged by :class:`etmpc.views.recording.Recorder`, the same for every sink.
"""

from __future__ import annotations

import os
import shutil
import socket
import sys
import time
from pathlib import Path
from urllib.parse import urlsplit

from etmpc.common.errors import EtmpcError

#: The URL schemes of a viewer to connect to (Rerun's own three, and the old address form).
SCHEMES = ("rerun://", "rerun+http://", "rerun+https://", "tcp://")
#: The port a spawned viewer listens on when nothing is given (Rerun's default); another free one if taken.
SPAWN_PORT = 9876
#: How long a viewer has to answer: a connection refused answers at once, a silent host takes this long.
REACH_TIMEOUT_S = 3.0
SPAWN_TIMEOUT_S = 10.0


def is_url(target) -> bool:
    """Whether ``target`` (what ``--record`` or ``record=`` was given) names a viewer rather than a file."""
    return isinstance(target, str) and target.lower().startswith(SCHEMES)


def viewer_url(text: str) -> str:
    """The gRPC URL Rerun connects to for ``text``: a Rerun URL as it is, ``tcp://HOST:PORT`` as
    ``rerun+http://HOST:PORT/proxy``. Anything else, or a URL without a host, is refused in one line."""
    if not is_url(text):
        raise EtmpcError(f"{text!r} is not a viewer's URL: rerun+http://HOST:PORT/proxy (or tcp://HOST:PORT)")
    parts = urlsplit(text)
    try:
        port = parts.port
    except ValueError:
        port = None
        parts = parts._replace(netloc="")  # a port that is no number: said below
    if not parts.hostname or (parts.scheme == "tcp" and port is None):
        raise EtmpcError(f"{text!r}: a viewer's URL names its host and port, e.g. rerun+http://127.0.0.1:9876/proxy")
    if parts.scheme == "tcp":
        return f"rerun+http://{parts.hostname}:{port}/proxy"
    return text


def _address(url: str) -> tuple[str, int]:
    parts = urlsplit(url)
    default = 443 if parts.scheme in ("rerun", "rerun+https") else 80
    assert parts.hostname is not None  # a URL viewer_url let through: it names its host
    return parts.hostname, parts.port or default


def _answers(host: str, port: int, timeout_s: float) -> OSError | None:
    """None if something accepts a connection at ``host:port``, else why not."""
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        return exc
    return None


def check_reachable(url: str) -> None:
    """Refuse, in one line, a viewer's URL that nothing answers (before any episode is played)."""
    host, port = _address(url)
    why = _answers(host, port, REACH_TIMEOUT_S)
    if why is not None:
        reason = why.strerror or type(why).__name__
        raise EtmpcError(f"no Rerun viewer answers at {url} ({reason}): start one with `rerun`, or write a file")


def _free_port() -> int:
    """Rerun's default port if nothing listens there, else one the system gives."""
    if _answers("127.0.0.1", SPAWN_PORT, 0.2) is not None:
        return SPAWN_PORT
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def check_screen() -> None:
    """A spawned viewer is a window: refused in one line where there is no screen."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise EtmpcError(
            "--spawn opens a Rerun viewer window and there is no screen here (DISPLAY is not set): write a file "
            "(--record PATH.rrd) and open it elsewhere, or stream to a viewer running elsewhere (--record rerun+http://HOST:9876/proxy)"
        )


def spawn_viewer(stream) -> str:
    """Start a Rerun viewer with Rerun's own ``spawn`` (not connected yet: the recording's sinks are set
    together) and return its URL once it listens. The viewer is the one installed with the SDK (beside this
    Python, where a virtual environment is not on PATH)."""
    check_screen()
    port = _free_port()
    beside = Path(sys.executable).parent
    path = os.environ.get("PATH", "")
    if shutil.which("rerun") is None and (beside / "rerun").is_file():
        os.environ["PATH"] = f"{beside}{os.pathsep}{path}"
    try:
        stream.spawn(port=port, connect=False)
    except RuntimeError as exc:
        raise EtmpcError(f"cannot spawn a Rerun viewer: {str(exc).strip().splitlines()[0]}") from None
    finally:
        os.environ["PATH"] = path
    deadline = time.monotonic() + SPAWN_TIMEOUT_S
    while _answers("127.0.0.1", port, 0.5) is not None:
        if time.monotonic() > deadline:
            raise EtmpcError(f"the spawned Rerun viewer did not start listening on port {port} within {SPAWN_TIMEOUT_S:g} s")
        time.sleep(0.2)
    return f"rerun+http://127.0.0.1:{port}/proxy"


class Destinations:
    """A recording's sinks: the ``.rrd`` file ``path`` (or None), the viewer at ``connect`` (a URL, or None) and,
    with ``spawn``, a viewer spawned for it; each checked here, before any episode is played. ``rerun``: a
    function that returns the imported ``rerun`` module (the recorder imports it in a thread), asked only to
    spawn."""

    def __init__(self, path: str | Path | None = None, connect: str | None = None, spawn: bool = False, rerun=None):
        if path is None and connect is None and not spawn:
            raise EtmpcError("a recording needs somewhere to go: a .rrd file, a viewer's URL, or a spawned viewer")
        self.path = None if path is None else Path(path)
        self.urls: list[str] = []
        if self.path is not None:
            self._tmp = self._check_file(self.path)
        if connect is not None:
            self.urls.append(viewer_url(connect))
            check_reachable(self.urls[-1])
        if spawn:
            import_rerun = rerun or (lambda: __import__("rerun"))
            self.urls.append(spawn_viewer(import_rerun().RecordingStream("etmpc-spawn")))

    @staticmethod
    def _check_file(path: Path) -> Path:
        """The partial file written beside ``path``, touched: a path that cannot be written fails here."""
        if path.suffix != ".rrd":
            raise EtmpcError(f"a recording is a .rrd file, got {path}")
        if path.is_dir():
            raise EtmpcError(f"{path} is a directory, not a file")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.partial")
        try:
            tmp.touch()
        except OSError as exc:
            raise EtmpcError(f"cannot write {path}: {exc.strerror or exc}") from None
        return tmp

    def __str__(self) -> str:
        """Where the episodes go, as a message names it."""
        return " and ".join([str(self.path)] * (self.path is not None) + self.urls)

    def attach(self, rr, stream) -> None:
        """Send ``stream`` to every destination (Rerun's own sinks: ``FileSink``, ``GrpcSink``)."""
        sinks = [rr.FileSink(self._tmp)] if self.path is not None else []
        stream.set_sinks(*sinks, *(rr.GrpcSink(url) for url in self.urls))

    def failed(self, exc: BaseException) -> EtmpcError:
        """The one line for a destination that failed while the recording was written or streamed."""
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc).strip().splitlines()[0]
        return EtmpcError(f"cannot write {self}: {reason}" + (" (is the disk full?)" if not self.urls else ""))

    def finish(self, keep: bool) -> None:
        """The file under its name if ``keep``, else no file at all."""
        if self.path is None:
            return
        if keep:
            self._tmp.replace(self.path)
        else:
            self._tmp.unlink(missing_ok=True)
