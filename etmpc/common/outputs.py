"""The files a command writes: checked before any work starts, written beside their name and
renamed into place, so that a reader (or the next run) sees the old file or the whole new one,
never a part, and nothing is left behind when writing fails.

* :func:`check_outputs` refuses, before a run, two outputs that name the same file and any output
  that cannot be written (its directory is a file, read-only, or full);
* :func:`atomic_path` gives the temporary name to write to and renames it on success;
* :func:`write_text` and :func:`write_json` are the two common cases; JSON is strict (RFC 8259): a
  missing or non-finite number is ``null``, never ``NaN`` or ``Infinity``, which ``jq`` and JavaScript
  refuse (:func:`strict`).

Every failure is an :class:`~etmpc.common.errors.EtmpcError` that names the file and the reason, so the
command line prints one line.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path

from etmpc.common.errors import EtmpcError

# Bytes the writability probe writes: a full disk fails it, a nearly full one may still fail later
# (the write itself is atomic then: the old file stays, the partial one is removed).
_PROBE_BYTES = 4096


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def output_error(path: Path, exc: OSError) -> EtmpcError:
    return EtmpcError(f"cannot write {path}: {_reason(exc)}")


def _existing_ancestor(path: Path) -> Path:
    """The nearest ancestor of ``path`` that exists (``path`` itself excluded)."""
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


def check_writable(path: Path, option: str, directory: bool = False) -> None:
    """Raise unless ``path`` (a file, or a ``directory``) can be created or replaced: probes the
    directory it goes in with a small file, removed again. Creates nothing that stays."""
    path = Path(path)
    label = f"{option} {path}"
    if path.exists() and path.is_dir() != directory:
        raise EtmpcError(f"{label} is {'not a directory' if directory else 'a directory, not a file'}")
    where = path if (directory and path.is_dir()) else _existing_ancestor(path)
    if not where.is_dir():
        raise EtmpcError(f"cannot write {label}: {where} is not a directory")
    probe = where / f".etmpc-probe-{os.getpid()}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            if os.write(fd, b"\0" * _PROBE_BYTES) < _PROBE_BYTES:  # a short write: the disk is (nearly) full
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise EtmpcError(f"cannot write {label}: {_reason(exc)} ({where})") from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(probe)


def check_outputs(
    outputs: Mapping[str, Path | None],
    directories: Mapping[str, Path | None] | None = None,
    inputs: Mapping[str, Path | str | None] | None = None,
) -> None:
    """Check every output of one command before it runs: ``outputs`` maps an option (``--json``)
    to the file it names (``None``: not asked for), ``directories`` an option to a directory the
    command writes into, ``inputs`` a name to a file the command reads. Two options naming the same
    file, a file inside a named directory, or an output that is an input, are refused."""
    seen: dict[Path, str] = {}
    named = [(o, Path(p), False) for o, p in outputs.items() if p is not None]
    named += [(o, Path(p), True) for o, p in (directories or {}).items() if p is not None]
    for source, path in (inputs or {}).items():
        if path is None:
            continue
        for option, out, _ in named:
            if out.resolve() == Path(path).resolve():
                raise EtmpcError(f"{option} {out} would overwrite the {source} it reads: write it elsewhere")
    for option, path, directory in named:
        resolved = path.resolve()
        if resolved in seen:
            raise EtmpcError(f"{seen[resolved]} and {option} name the same file {path}: give each its own")
        seen[resolved] = option
    for option, path, directory in named:
        if directory:
            inside = [o for o, p, d in named if not d and path.resolve() in p.resolve().parents]
            if inside:
                raise EtmpcError(f"{inside[0]} {outputs[inside[0]]} lies inside {option} {path}: write it elsewhere")
    for option, path, directory in named:
        check_writable(path, option, directory)


@contextlib.contextmanager
def atomic_path(path: Path, suffix: str = "") -> Iterator[Path]:
    """Yields a temporary name beside ``path`` to write to; renames it to ``path`` when the block
    ends normally, removes it otherwise. ``OSError`` becomes an :class:`EtmpcError` naming
    ``path``. ``suffix`` ends the temporary name (some writers choose the format by it)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}{suffix}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise output_error(path, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_bytes(path: Path, data: bytes) -> Path:
    """``data`` written to ``path`` atomically, synced to disk before the rename."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


def write_text(path: Path, text: str) -> Path:
    return write_bytes(path, text.encode())


def strict(data):
    """``data`` with every non-finite float (NaN, an infinity: a number that is missing or was not
    scored) replaced by ``None``, so that it is strict JSON; tuples become lists, as ``json`` writes them."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: strict(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [strict(v) for v in data]
    return data


def dumps(data, indent: int | None = 2) -> str:
    """``data`` as strict JSON text (:func:`strict`)."""
    return json.dumps(strict(data), indent=indent, allow_nan=False)


def write_json(path: Path, data, indent: int | None = 2) -> Path:
    return write_text(path, dumps(data, indent) + "\n")


def foreign_entries(directory: Path, ours) -> list[str]:
    """Names in ``directory`` that ``ours(name)`` does not claim (temporary files of an interrupted
    atomic write, ``.<name>.tmp…``, are always ours). A missing directory has none."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(n for n in os.listdir(directory) if not (n.startswith(".") and ".tmp" in n) and not ours(n))


def refuse_foreign(directory: Path, ours, kind: str, option: str = "--out") -> None:
    """Raise unless everything in ``directory`` is what a ``kind`` writes: a run never writes into
    a directory that holds someone else's files."""
    foreign = foreign_entries(directory, ours)
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise EtmpcError(f"{option} {directory} holds files that are not a {kind}'s ({shown}): choose a new or empty directory")


def what_differs(stored, wanted, limit: int = 3) -> str:
    """The settings that differ between a run's stored ``settings.json`` and the one asked for, named
    one by one (``settings.episodes: 100 in the directory, 20 asked``), at most ``limit`` of them."""
    found: list[str] = []

    def walk(a, b, where: str) -> None:
        if isinstance(a, dict) and isinstance(b, dict):
            for key in sorted(set(a) | set(b), key=str):
                walk(a.get(key, "(absent)"), b.get(key, "(absent)"), f"{where}.{key}" if where else str(key))
        elif a != b:
            found.append(f"{where or 'the file'}: {json.dumps(a)} in the directory, {json.dumps(b)} asked")

    walk(stored, wanted, "")
    more = f" and {len(found) - limit} more" if len(found) > limit else ""
    return "; ".join(found[:limit]) + more
