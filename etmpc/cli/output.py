"""What every command of the ``etmpc`` command line shares: progress lines on stderr, and the check
that a policy is named once."""

from __future__ import annotations

import sys

from etmpc.common.errors import EtmpcError


def say(line: str) -> None:
    """Progress of a long stage, on stderr (stdout keeps the results)."""
    print(line, file=sys.stderr, flush=True)


def distinct_policies(specs: list[str]) -> None:
    seen = set()
    for spec in specs:
        if spec in seen:
            raise EtmpcError(f"policy {spec} is given twice")
        seen.add(spec)
