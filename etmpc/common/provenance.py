"""What made a generated file: the checkout's commit, whether it had uncommitted changes, and the date."""

from __future__ import annotations

import datetime
import subprocess

from etmpc.common.resources import data_root


def commit_and_date() -> dict:
    """``{"commit", "uncommitted_changes", "date"}`` of the checkout etmpc runs from (the repository's
    ``git``; an installed copy says it is not a checkout)."""

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=data_root(), capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "--short", "HEAD")
    dirty = bool(git("status", "--porcelain", "--untracked-files=no")) if commit else None
    return {
        "commit": commit or "(not a git checkout)",
        "uncommitted_changes": dirty,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }
