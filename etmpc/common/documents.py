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


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number (strict JSON writes null)")


def loads(text: str):
    """``json.loads``, strict: ``NaN``, ``Infinity`` and ``-Infinity``, which JSON does not have, are
    refused (``ValueError``)."""
    return json.loads(text, parse_constant=_refuse_constant)


def read_document(path: str | Path, format: str, missing: str, unreadable: str, foreign: str) -> dict:
    """The JSON object in ``path`` (strict JSON) whose ``format`` field is ``format``; else :class:`EtmpcError` with
    ``missing``, ``unreadable`` (``{error}`` is replaced by what went wrong) or ``foreign``."""
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
    """The SHA-256 of ``data`` without its seal, as canonical JSON (sorted keys, no spaces, exact floats)."""
    content = {k: v for k, v in data.items() if k != SEAL}
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
