"""What a run reads, so that nothing it writes lands on it.

A command names its outputs (``--json``, ``--record``, ``--out`` and the files it writes in that
directory) and reads inputs: a test set, the stored references, policy files and the descriptions beside
them, a hyperparameter file, a card, a README whose table it rewrites. Before any work,
:func:`check_run_outputs` refuses, in one line, an input or output that exists but is not a regular file
(a FIFO, a device), an output that is one of those inputs, and one that lies in one of the
:func:`data_folders` (the package's models, stored test sets and references and shipped policies, and
every installed task plugin's data folder): the suite's stored numbers are never written over by a run,
whatever path a user types. (A maintainer's rebuild of them is written elsewhere and copied in by hand.)
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Iterable, Mapping
from pathlib import Path

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import Writes, check_outputs
from etmpc.common.resources import data_root
from etmpc.policies.specs import MAX_NESTING, check_size, find
from etmpc.systems import data_dir
from etmpc.systems.registry import domains

DATA = ("models", "tasks", "policies")  # the package's own data folders, under data_root()


def data_folders() -> list[Path]:
    """The folders of data that runs read and never write: the package's own (``models/``, ``tasks/``,
    ``policies/``) and each installed domain's data folder (a plugin's ``DATA``)."""
    folders = [data_root() / name for name in DATA] + [data_dir(name) for name in domains()]
    return list(dict.fromkeys(f.resolve() for f in folders))


def policy_files(spec: str) -> list[Path]:
    """The files that exist among those a policy spec is read from: the file a kind with a path names
    (``rl:PATH``, ``self:PATH``, ``sb3:PATH``), the description beside a model (``sb3:X.zip`` reads
    ``X.json`` too), and for a kind that wraps another (``rollout:BASE:K:H``, ``oracle:BASE``,
    ``shield:AGE:MARGIN:BASE``), its base's files. Nothing is parsed or loaded: a spec that names no file has none.
    A path that exists but is no regular file (a FIFO, a device) is among them, so that it is refused before it is read."""
    check_size(spec)  # a spec past the parser's bounds is refused before it is looked into

    @functools.cache
    def files(stretch: str, depth: int) -> tuple[Path, ...]:
        kind = find(stretch)
        if kind is None or depth > MAX_NESTING:  # wrapped deeper than the parser takes: it refuses the spec
            return ()
        arg = stretch.partition(":")[2]
        if kind.path:
            named = Path(arg)
            if not arg or not named.name:
                return ()
            return tuple(f for f in dict.fromkeys([named, named.with_suffix(".json")]) if f.exists() and not f.is_dir())
        if kind.simulates or kind.wraps:  # BASE may end in :K[:H] or follow AGE:MARGIN: every stretch of the argument
            tokens = arg.split(":")
            stretches = (":".join(tokens[i:j]) for i in range(len(tokens)) for j in range(len(tokens), i, -1))
            return tuple(dict.fromkeys(f for part in stretches for f in files(part, depth + 1)))
        return ()

    return list(files(spec, 0))


def run_inputs(policies: Iterable, test_set: str | Path | None = None) -> dict[str, Path]:
    """What a run of ``policies`` (specs; an object names no file) reads, by name: the test set and its
    checksum, and each policy's files."""
    found: dict[str, Path] = {}
    if test_set is not None:
        found["test set"] = Path(test_set)
        found["test set's checksum"] = Path(f"{test_set}.sha256")
    for policy in policies:
        if isinstance(policy, str):
            for i, path in enumerate(policy_files(policy)):
                found[f"policy file {path}" if i else f"policy {policy}"] = path
    return found


def check_run_outputs(
    outputs: Mapping[str, Path | str | None],
    directories: Mapping[str, Path | str | None] | None = None,
    inputs: Mapping[str, Path | str | None] | None = None,
    writes: Mapping[str, Writes] | None = None,
    edits: Mapping[str, Path | str | None] | None = None,
) -> None:
    """:func:`~etmpc.common.outputs.check_outputs` (an input or output that is no regular file, an output
    or a file written in an output directory that is an input or an ``edits`` file, two outputs on one
    file, an output that cannot be written), and no output or edited file inside a :func:`data_folders`
    folder, nor an output directory that holds one."""
    files = {o: Path(p) for o, p in outputs.items() if p is not None}
    folders = {o: Path(p) for o, p in (directories or {}).items() if p is not None}
    edited = {o: Path(p) for o, p in (edits or {}).items() if p is not None}
    if files or folders or edited:
        data = data_folders()
        for option, path in [*files.items(), *edited.items(), *folders.items()]:
            resolved = path.resolve()
            hit = next(
                (d for d in data if resolved == d or d in resolved.parents or (option in folders and resolved in d.parents)), None
            )
            if hit is not None:
                where = "holds" if resolved in hit.parents else "lies in"
                raise EtmpcError(
                    f"{option} {path} {where} etmpc's data folder {hit} (stored test sets, references, "
                    "models, policies), which a run never writes: write it elsewhere"
                )
    check_outputs(files, folders, inputs, writes, edited)


MANIFEST = "SHA256SUMS"  # in policies/: the SHA-256 of every shipped policy file, as sha256sum writes them


def shipped_digests() -> dict[Path, str]:
    """The shipped policies' SHA-256 by resolved path, from ``policies/SHA256SUMS`` (none without one:
    an installed wheel ships no policy)."""
    folder = (data_root() / "policies").resolve()
    try:
        lines = (folder / MANIFEST).read_text().splitlines()
    except FileNotFoundError:
        return {}
    found = {}
    for line in lines:
        digest, _, name = line.partition("  ")
        if line.strip():
            found[(folder / name).resolve()] = digest
    return found


def check_shipped(spec: str) -> None:
    """Raise :class:`EtmpcError` if a file ``spec`` reads lies among the shipped policies but is not the
    file shipped (``policies/SHA256SUMS``): a shipped policy retrained in place, or swapped, is never
    scored under its name."""
    folder = (data_root() / "policies").resolve()
    files = [f.resolve() for f in policy_files(spec)]
    shipped = [f for f in files if folder in f.parents]
    if not shipped:
        return
    digests = shipped_digests()
    for path in shipped:
        expected = digests.get(path)
        if expected is None:
            raise EtmpcError(
                f"{path} lies among the shipped policies but is not one of them ({folder / MANIFEST}): "
                "keep your own policies elsewhere"
            )
        if hashlib.sha256(path.read_bytes()).hexdigest() != expected:
            raise EtmpcError(
                f"{path} is not the policy etmpc ships (its SHA-256 differs from {folder / MANIFEST}'s): "
                "a changed policy is scored from a file of its own, elsewhere"
            )
