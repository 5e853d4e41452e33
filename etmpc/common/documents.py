"""Reading etmpc's own JSON documents (references, a policy's description): a file that is missing,
unreadable or of another format is one line, in the words its reader gives."""

from __future__ import annotations

import json
from pathlib import Path

from etmpc.common.errors import EtmpcError


def read_document(path: str | Path, format: str, missing: str, unreadable: str, foreign: str) -> dict:
    """The JSON object in ``path`` whose ``format`` field is ``format``; else :class:`EtmpcError` with
    ``missing``, ``unreadable`` (``{error}`` is replaced by what went wrong) or ``foreign``."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise EtmpcError(missing) from None
    except (OSError, ValueError) as exc:
        raise EtmpcError(unreadable.replace("{error}", str(exc))) from None
    if not isinstance(data, dict) or data.get("format") != format:
        raise EtmpcError(foreign)
    return data
