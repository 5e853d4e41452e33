"""What starting worker processes asks of the main script.

A spawned worker re-runs the main script (or the module run with ``-m``) as ``__mp_main__``, so that
what it defines unpickles there. That fails when there is no script to re-run (``python -c``, a
notebook, the prompt, stdin), and it runs the script's work again when the script calls etmpc at its top
level, without ``if __name__ == "__main__":``. These are told apart here, so that each is one line.
"""

from __future__ import annotations

import multiprocessing
import os
import sys

from etmpc.common.errors import EtmpcError


def unimportable_main() -> str | None:
    """What ``__main__`` is, if a spawned worker cannot re-create it (multiprocessing re-runs a script
    file, or a module run with ``-m``, in each worker so that what it defines unpickles there): ``python
    -c``, a notebook or the prompt (nothing re-run: its classes are not there), or stdin (``python -``)."""
    main = sys.modules.get("__main__")
    if getattr(main, "__spec__", None) is not None:
        return None
    path = getattr(main, "__file__", None)
    if path is None:
        return "python -c, a notebook or the interactive prompt"
    return missing_main_script()


def missing_main_script() -> str | None:
    """What the main script is, if it names a file that is not there (``<stdin>`` for ``python -``): a
    spawned worker would try to re-run it and die."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if getattr(main, "__spec__", None) is not None or not isinstance(path, str) or os.path.isfile(path):
        return None
    return "a script read from stdin" if path == "<stdin>" else f"{path}, not a file"


# The exit code of a spawned worker that found itself re-running a script without a __main__ guard.
UNGUARDED_EXIT = 86
UNGUARDED = (
    'etmpc.evaluate started worker processes from a script without `if __name__ == "__main__":`: '
    "put your calls under it, or pass workers=1"
)


class UnguardedScript(EtmpcError):
    """Workers were started from a script without a ``__main__`` guard: the run's error, never a policy's."""


def rerunning_main() -> bool:
    """True in a worker being spawned, while multiprocessing re-runs the main script (or module) in it as
    ``__mp_main__`` so that what the script defines can be unpickled there (``multiprocessing.spawn``'s
    ``prepare``). etmpc called then was called by the script's top level, outside an ``if __name__ ==
    "__main__":`` guard. (``multiprocessing.parent_process()`` is only set after that step.)"""
    return bool(getattr(multiprocessing.current_process(), "_inheriting", False))


def refuse_in_rerun_main() -> None:
    """In a worker re-running an unguarded main script: end it at once, quietly, with ``UNGUARDED_EXIT``
    (the parent turns it into the one-line :data:`UNGUARDED` error), rather than run the script's work
    again and die in multiprocessing's own check with a page of traceback per worker."""
    if rerunning_main():
        os._exit(UNGUARDED_EXIT)
