"""The ``etmpc`` command: ``reproduce``, ``evaluate``, ``score``, ``verify``, ``sweep``, ``train``, ``train-self``,
``render``, ``replay``, ``bench``, ``testset``, ``discriminate`` and ``figure``.

Bad input (unknown task or policy, bad numbers, missing or corrupt files) prints one line on
stderr and exits with code 2, without a traceback. The options are :mod:`etmpc.cli.options`'s (their
value types :mod:`etmpc.cli.types`'s), the commands :mod:`etmpc.cli.commands`'s; ``score``'s both are
:mod:`etmpc.cli.scoring`'s, ``train``'s :mod:`etmpc.cli.training`'s (its deprecated flags and
``train-self`` :mod:`etmpc.cli.legacy`'s), ``discriminate``'s :mod:`etmpc.cli.discriminate`'s and
``figure``'s :mod:`etmpc.cli.figures`'s. This package sits on top: it may import any floor of etmpc.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import warnings

from etmpc.common import interrupts, progress
from etmpc.common.errors import EtmpcError, Terminated

# MuJoCo's OpenGL backends on Linux (mujoco/rendering/classic/gl_context.py): anything else makes
# importing dm-control fail, so the command checks it before importing anything that renders.
GL_BACKENDS = (
    "egl",
    "osmesa",
    "glfw",
    "glx",
    "enable",
    "enabled",
    "on",
    "true",
    "1",
    "",
    "disable",
    "disabled",
    "off",
    "false",
    "0",
)


def _check_gl() -> None:
    backend = os.environ.get("MUJOCO_GL", "")
    if backend.lower().strip() not in GL_BACKENDS:
        raise EtmpcError(
            f"MUJOCO_GL={backend} is not an OpenGL backend MuJoCo knows: use egl (headless, the default), "
            "osmesa (software) or glfw (with a display)"
        )


def _terminate(signum, frame):
    raise Terminated


def main(argv: list[str] | None = None) -> int:
    """Run the command; returns the exit code: 0, 2 for any error (one line on stderr), 130 for
    Ctrl-C and 143 for SIGTERM (each also one line), and 141, silently, when what reads the output closes
    it early (a pipe into ``head``), as a shell's own commands do."""
    # Rerun's own log lines (its file writer's errors) stay off stderr: a failure to write a
    # recording is reported as one line by etmpc itself. Set RUST_LOG to see them.
    os.environ.setdefault("RUST_LOG", "off")
    # The numerical libraries run single-threaded (the work is spread over processes instead), so
    # their sums do not depend on how many cores the machine has; set these yourself to override.
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    plain = warnings.formatwarning  # etmpc's own warnings (a broken plugin's, a deprecated name), one line each
    warnings.formatwarning = lambda message, category, *where: (
        f"etmpc: warning: {' '.join(str(message).removeprefix('etmpc: ').split())}\n"
        if issubclass(category, (RuntimeWarning, FutureWarning)) and str(message).startswith("etmpc: ")
        else plain(message, category, *where)
    )
    try:
        _check_gl()
        from etmpc.cli import commands, options, tasks  # after the OpenGL check: importing dm-control picks the backend

        args = options.build_parser().parse_args(argv)
        tasks.resolve(args)  # the task given the older way, with its deprecation line
        # a Ctrl-C is told apart from a policy that raises KeyboardInterrupt; progress lines name the command
        with interrupts.watching(), progress.command(f"etmpc {args.command}"):
            commands.COMMANDS[args.command](args)
    except EtmpcError as exc:  # one line, whatever a name in it (a spec, a path) holds
        print(f"etmpc: error: {' '.join(str(exc).splitlines())}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (`etmpc tasks | head`): nothing to say, and nobody to say it to
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # Python's flush at exit then finds no pipe
        return 128 + signal.SIGPIPE
    except OSError as exc:  # the machine refused (a full disk, a vanished directory): one line, no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"etmpc: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("etmpc: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("etmpc: terminated", file=sys.stderr)
        return 143
    finally:
        warnings.formatwarning = plain
        if in_main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    return 0
