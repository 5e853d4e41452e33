"""The files a command writes: checked before any work starts, written beside their name and
renamed into place, so that a reader (or the next run) sees the old file or the whole new one,
never a part, and nothing is left behind when writing fails.

* :func:`check_outputs` refuses, before a run, two outputs that name the same file, an output (or a
  file a command writes inside its output directory) that is one of the run's inputs, any output that
  cannot be written (its directory is a file, read-only, or full), and any input or output that exists
  but is not a regular file where a file is expected (a FIFO, a socket, a device such as ``/dev/null``:
  reading one may hang, writing one writes through it), nor a directory where one is expected;
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
import stat
from collections.abc import Callable, Iterable, Iterator, Mapping
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


_SPECIAL = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def special(path: Path) -> str | None:
    """What ``path`` is when it exists and is neither a regular file nor a directory (``"a FIFO (named
    pipe)"``, ``"a socket"``, a device), else None; a symbolic link is what it points to."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):  # missing, unreachable, or no path at all: the reader says so in its words
        return None
    return next((what for test, what in _SPECIAL if test(mode)), None)


def check_input(path: Path, source: str) -> None:
    """Raise unless ``path``, which a command reads as its ``source`` (``--readme``, ``test set``), is a
    regular file or missing (whose reader says so): a FIFO would hang the command, a device feed it
    anything, and a directory is no file."""
    kind = special(path) or ("a directory" if Path(path).is_dir() else None)
    if kind is not None:
        raise EtmpcError(f"{path} ({source}) is {kind}, not a regular file: name a regular file")


def check_inputs(inputs: Mapping[str, Path | str | None]) -> None:
    """:func:`check_input` on each of ``inputs`` (a name to the file read under it; None: none)."""
    for source, path in inputs.items():
        if path is not None:
            check_input(Path(path), source)


def check_writable(path: Path, option: str, directory: bool = False) -> None:
    """Raise unless ``path`` (a file, or a ``directory``) can be created or replaced: probes the
    directory it goes in with a small file, removed again. Creates nothing that stays. A path that
    exists as something else (a directory for a file, a FIFO or a device for either) is refused: a
    device would be written through, or replaced by the rename."""
    path = Path(path)
    label = f"{option} {path}"
    kind = special(path)
    if kind is not None:
        raise EtmpcError(f"{label} is {kind}, not a {'directory' if directory else 'regular file'}: name another path")
    if path.exists() and path.is_dir() != directory:
        raise EtmpcError(
            f"{label} is {'not a directory: name a directory' if directory else 'a directory, not a file: name a file'}"
        )
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


#: What a command writes inside one of its output directories: the names of the files (relative to it:
#: ``"leaderboard.md"``, ``"battery/trading/references.json"``), or, when they are not known before the
#: run, a test of the name of an entry of it (a learner's ``owns``): what it claims, and all beneath.
Writes = Iterable[str] | Callable[[str], bool]


def _written(directory: Path, writes: Writes) -> list[Path]:
    """The files ``writes`` names in ``directory``: those listed, or every path there, at any depth, in an
    entry that it claims (a resumed run reads them back)."""
    if not callable(writes):
        return [directory / name for name in writes]
    found = []
    for name in sorted(os.listdir(directory)) if directory.is_dir() else []:
        if writes(name):
            found.append(directory / name)
            if (directory / name).is_dir() and not (directory / name).is_symlink():
                found += [Path(root) / n for root, dirs, files in os.walk(directory / name) for n in files + dirs]
    return found


def _claims(directory: Path, writes: Writes, path: Path) -> bool:
    """Whether ``path`` (resolved) is, or lies in, a file or folder that ``writes`` claims in ``directory``."""
    root = directory.resolve()
    if callable(writes):
        return root in path.parents and writes(path.relative_to(root).parts[0])
    return any(path == (root / name).resolve() or (root / name).resolve() in path.parents for name in writes)


def _or(option: str) -> str:
    """``" or choose another --out"`` for an option the user gave (a label such as "the kept rows' directory" is none)."""
    return f" or choose another {option}" if option.startswith("--") else ""


def _refuse_special_written(folders: dict[str, Path], claimed: Mapping[str, Writes]) -> None:
    """Raise if a file a directory gets (``claimed``) exists as a FIFO or a device (a resumed run would read it
    back, or write through it), or, where a file is named, as a directory."""
    for option, writes in claimed.items():
        for path in _written(folders[option], writes):
            kind = special(path) or ("a directory" if path.is_dir() and not callable(writes) else None)
            if kind is not None:
                where = f"{option} {folders[option]} holds {path}, {kind}, where it writes a file"
                raise EtmpcError(f"{where}: move it away{_or(option)}")


def check_outputs(
    outputs: Mapping[str, Path | None],
    directories: Mapping[str, Path | None] | None = None,
    inputs: Mapping[str, Path | str | None] | None = None,
    writes: Mapping[str, Writes] | None = None,
    edits: Mapping[str, Path | None] | None = None,
) -> None:
    """Check every output of one command before it runs: ``outputs`` maps an option (``--json``)
    to the file it names (``None``: not asked for), ``directories`` an option to a directory the
    command writes into, ``writes`` such an option to the files it writes there (:data:`Writes`),
    ``inputs`` a name to a file the command reads, and ``edits`` an option to a file it reads and
    rewrites in place (a README's table: an input, and an output no other may land on). Refused: an
    input, an edited file or a file a directory gets that exists but is no regular file; an output, or a
    file written in a directory, that is an input or an edited file; two options naming the same file; a
    file inside a named directory; an output that cannot be written."""
    reads = {source: Path(p) for source, p in (inputs or {}).items() if p is not None}
    edited = {option: Path(p) for option, p in (edits or {}).items() if p is not None}
    check_inputs({**reads, **edited})
    folders = {option: Path(p) for option, p in (directories or {}).items() if p is not None}
    claimed = {option: w for option, w in (writes or {}).items() if option in folders}
    _refuse_special_written(folders, claimed)
    files = [(o, Path(p)) for o, p in outputs.items() if p is not None] + list(edited.items())
    for source, path in [*reads.items(), *edited.items()]:
        does = "edits" if source in edited else "reads"
        resolved = path.resolve()
        for option, out in files:
            if option != source and out.resolve() == resolved:
                raise EtmpcError(f"{option} {out} would overwrite the {source} it {does}: write it elsewhere")
        for option, w in claimed.items():
            if _claims(folders[option], w, resolved):
                raise EtmpcError(
                    f"{option} {folders[option]} would write over the {source} it {does} ({path}): move {path.name} "
                    f"out of it{_or(option)}"
                )
    seen: dict[Path, str] = {}
    for option, path in [*files, *folders.items()]:
        resolved = path.resolve()
        if resolved in seen:
            raise EtmpcError(f"{seen[resolved]} and {option} name the same file {path}: give each its own")
        seen[resolved] = option
    for option, path in folders.items():  # an edited file may lie in one: it is no file a run creates there
        inside = [o for o, p in files if o not in edited and path.resolve() in p.resolve().parents]
        if inside:
            raise EtmpcError(f"{inside[0]} {outputs[inside[0]]} lies inside {option} {path}: write it elsewhere")
    for option, path in files:
        check_writable(path, option)
    for option, path in folders.items():
        check_writable(path, option, directory=True)


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
