"""Reading etmpc's own JSON documents (references, a policy's description, a kept leaderboard row): a
file that is missing, unreadable or of another format is one line, in the words its reader gives.

A document whose numbers are scored against (the references, a kept row) is *sealed*: it carries the
SHA-256 of its own content (:func:`sealed`), and a reader refuses one whose content no longer matches
(:func:`check_seal`), so an edited number is never published unnoticed.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import special, strict


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number (strict JSON writes null)")


def loads(text: str | bytes):
    """``json.loads``, strict: ``NaN``, ``Infinity`` and ``-Infinity``, which JSON does not have, are
    refused (``ValueError``), and so is a document nested deeper than Python's reader goes (which raises
    ``RecursionError`` there): every JSON file etmpc reads, its own or a user's, is read by this."""
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except RecursionError:
        raise ValueError("nested too deeply for a JSON document of etmpc") from None


def yaml_loads(text: str):
    """A YAML document (a settings file, ``--set``'s value) as ``yaml.safe_load`` reads it (plain data, never
    code); one it cannot read, or nested too deeply for it, raises ``ValueError`` saying why."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(" ".join(str(exc).split())) from None
    except RecursionError:
        raise ValueError("nested too deeply for a settings document") from None


def read_document(path: str | Path, format: str, missing: str, unreadable: str, foreign: str) -> dict:
    """The JSON object in ``path`` (strict JSON) whose ``format`` field is ``format``; else :class:`EtmpcError` with
    ``missing``, ``unreadable`` (``{error}`` is replaced by what went wrong) or ``foreign``. A path that is no
    regular file (a FIFO, which would hang the read; a device) is unreadable, and never read."""
    kind = special(Path(path))
    if kind is not None:
        raise EtmpcError(unreadable.replace("{error}", f"it is {kind}, not a regular file"))
    try:
        data = loads(Path(path).read_text())
    except FileNotFoundError:
        raise EtmpcError(missing) from None
    except (OSError, ValueError) as exc:
        raise EtmpcError(unreadable.replace("{error}", str(exc))) from None
    if not isinstance(data, dict) or data.get("format") != format:
        raise EtmpcError(foreign)
    return data


SEAL = "sha256"


def content_sha256(data: dict) -> str:
    """The SHA-256 of ``data`` without its seal, as canonical JSON (sorted keys, no spaces, exact floats) of
    what a file holds: a number not scored (NaN, an infinity) is ``null`` there (:func:`~etmpc.common.outputs.strict`),
    so a row that was not scored is sealed as it is written, and checks when it is read back."""
    content = strict({k: v for k, v in data.items() if k != SEAL})
    return hashlib.sha256(json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()).hexdigest()


def sealed(data: dict) -> dict:
    """``data`` with its seal, the SHA-256 of the rest, last."""
    return {k: v for k, v in data.items() if k != SEAL} | {SEAL: content_sha256(data)}


def check_seal(data: dict, where: str, remedy: str) -> None:
    """Raise :class:`EtmpcError` (one line: ``where``, what is wrong, ``remedy``) unless ``data`` carries
    the seal of its content."""
    seal = data.get(SEAL)
    if not isinstance(seal, str):
        raise EtmpcError(f"{where} carries no checksum of its content; {remedy}")
    try:
        actual = content_sha256(data)
    except (TypeError, ValueError) as exc:  # NaN or a value JSON does not have
        raise EtmpcError(f"{where} holds a value strict JSON does not have ({exc}); {remedy}") from None
    if seal != actual:
        raise EtmpcError(f"{where} does not match its checksum (its content was changed after it was written); {remedy}")
