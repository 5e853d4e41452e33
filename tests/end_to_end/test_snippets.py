"""Every ```python block of the README and of docs/ runs as written, saved as a script (what a new user
does with it); and what such scripts meet on a first run: ``etmpc.evaluate`` without a ``__main__``
guard, a trigger defined in ``python -c`` or stdin, and the one line said while the compiled MPC is built.

A block runs in a fresh ``.venv`` python, as a script file in a temporary folder: from the checkout's
``examples/`` (on the path too, as for a script saved there) when it imports ``my_trigger``, else from a
temporary folder, where the checkout's folders a block names (``"policies/..."``: "from the checkout")
are linked. The one change: a block that trains (``learn(total_timesteps=...)``, the PPO snippets)
trains for ``SHRUNK_STEPS`` steps, its PPO collecting that many per update (``n_steps``, else a first
update alone is 2048 steps), so that it shows it runs without spending minutes on it.
"""

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from etmpc.evaluation.mainscript import UNGUARDED

from tests.conftest import REPO

EXAMPLES = REPO / "examples"
# Pages generated from the code and runs (docs/results/ by `etmpc reproduce`, docs/reference/ by
# mkdocstrings from the parsers and docstrings): nothing in them is written by hand, so there is no
# hand-written snippet in them to go stale (and tests/end_to_end/test_docs.py builds them).
GENERATED = ("docs/results/", "docs/reference/")
SHRUNK_STEPS = 256
# A block teaches no deprecated form: a deprecation its own lines meet (an old keyword, an old task name; etmpc
# warns at the caller's line, so the warning is the script's, ``__main__``'s) fails it.
DEPRECATED_IS_AN_ERROR = "error::DeprecationWarning:__main__,error::FutureWarning:__main__"
# Blocks known not to run as written: (page, a line of the block) -> why. Strict: a block fixed in its page
# makes its entry fail, to be removed here. None now: keep it that way.
KNOWN_FAILURES: dict[tuple[str, str], str] = {}


def _pages() -> list[Path]:
    pages = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
    return [p for p in pages if not p.relative_to(REPO).as_posix().startswith(GENERATED)]


def _blocks() -> list:
    found = []
    for page in _pages():
        text = page.read_text()
        for match in re.finditer(r"^( *)```python\n(.*?)^\1```[ \t]*$", text, flags=re.S | re.M):
            code = textwrap.dedent(match.group(2))
            name = page.relative_to(REPO).as_posix()
            line = text.count("\n", 0, match.start()) + 1
            known = next((why for (where, marker), why in KNOWN_FAILURES.items() if where == name and marker in code), None)
            marks = [pytest.mark.xfail(reason=known, strict=True)] if known else []
            found.append(pytest.param(name, code, id=f"{name}:{line}", marks=marks))
    return found


BLOCKS = _blocks()


def _run(
    script: str,
    tmp_path: Path,
    cwd: Path | None = None,
    env: dict | None = None,
    args: tuple = (),
    stdin: str | None = None,
    timeout: float = 600,
) -> subprocess.CompletedProcess:
    """``script`` saved as a file and run by this python (or given on stdin, or to ``-c``, by ``args``)."""
    path = tmp_path / "snippet.py"
    path.write_text(script)
    command = [sys.executable, *(args or (str(path),))]
    environment = dict(os.environ, MUJOCO_GL="egl", PYTHONDONTWRITEBYTECODE="1", **(env or {}))
    return subprocess.run(
        command, cwd=cwd or tmp_path, env=environment, capture_output=True, text=True, input=stdin, timeout=timeout
    )


def test_the_blocks_are_found():
    pages = {param.values[0] for param in BLOCKS}
    assert {"README.md", "docs/getting-started.md", "docs/environment.md"} <= pages
    assert sum(p.values[0] == "README.md" for p in BLOCKS) >= 3


@pytest.mark.parametrize(("page", "code"), BLOCKS)
def test_the_python_block_runs_as_a_script(page, code, tmp_path):
    # The one change (see the docstring): fewer training steps.
    code, trains = re.subn(r"(\blearn\(\s*total_timesteps\s*=\s*)[\d_]+", rf"\g<1>{SHRUNK_STEPS}", code)
    if trains:
        code = re.sub(r"\bPPO\((\s*\"MlpPolicy\"\s*,\s*\w+)", rf"PPO(\1, n_steps={SHRUNK_STEPS}, batch_size=64", code)
    examples = "my_trigger" in code
    for name in set(re.findall(r"[\"']([\w.-]+)/", code)):  # "policies/...": the checkout's folder, linked
        if (REPO / name).is_dir() and not (tmp_path / name).exists():
            (tmp_path / name).symlink_to(REPO / name)
    env = {"PYTHONWARNINGS": DEPRECATED_IS_AN_ERROR, **({"PYTHONPATH": str(EXAMPLES)} if examples else {})}
    done = _run(code, tmp_path, cwd=EXAMPLES if examples else None, env=env)
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{page}: exit {done.returncode}\n{output[-3000:]}"
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert UNGUARDED not in output and "failed: " not in output, output[-3000:]  # a scorecard row that failed says so


def test_a_block_that_uses_a_deprecated_form_fails(tmp_path):
    old = 'import etmpc\netmpc.evaluate(domain="cart_pendulum", policies=["every:3"], episodes=1, progress=False)\n'
    done = _run(old, tmp_path, env={"PYTHONWARNINGS": DEPRECATED_IS_AN_ERROR})
    assert done.returncode != 0 and "DeprecationWarning: the keyword domain= is deprecated" in done.stderr
    assert _run(old.replace("domain=", "task="), tmp_path, env={"PYTHONWARNINGS": DEPRECATED_IS_AN_ERROR}).returncode == 0


# -- a script without `if __name__ == "__main__":` ------------------------------------------------------
UNGUARDED_SCRIPT = """
import sys
import etmpc
workers = None if sys.argv[2] == "default" else int(sys.argv[2])
result = etmpc.evaluate("cart_pendulum", ["every:3"], episodes=int(sys.argv[1]), workers=workers, progress=False)
print("done", result.summaries[0].episodes)
"""


def test_a_small_evaluation_from_a_script_without_a_guard_just_works(tmp_path):
    done = _run(UNGUARDED_SCRIPT, tmp_path, args=(str(tmp_path / "snippet.py"), "3", "default"))
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "done 3" and "Traceback" not in done.stderr


def test_workers_started_from_a_script_without_a_guard_end_in_one_line(tmp_path):
    done = _run(UNGUARDED_SCRIPT, tmp_path, args=(str(tmp_path / "snippet.py"), "40", "2"))
    assert done.returncode != 0 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert lines[-1] == f"etmpc.evaluation.mainscript.UnguardedScript: {UNGUARDED}"  # an EtmpcError
    # The script's own traceback, down to etmpc's raise: none of multiprocessing's, nor the workers'.
    assert done.stderr.count("Traceback") == 1 and done.stderr.count(UNGUARDED) == 1
    assert "multiprocessing" not in done.stderr and "concurrent" not in done.stderr and "spawn" not in done.stderr


def test_the_docs_show_the_last_line_an_unguarded_script_ends_with():
    """using.md shows the line the test above finds at the end of the traceback (it once said the script
    "stops with one line")."""
    text = (REPO / "docs" / "using.md").read_text()
    assert f"\netmpc.evaluation.mainscript.UnguardedScript: {UNGUARDED}\n" in text
    assert "stops with one line" not in text


# -- a trigger defined where a worker cannot import it ----------------------------------------------------
MAIN_TRIGGER = """
import sys
from dataclasses import dataclass
import etmpc

@dataclass(frozen=True)
class AngleOrAge:
    spec: str = "angle-or-age"
    stochastic: bool = False
    def decide(self, s, rng) -> bool:
        return bool(abs(s.x[2] - s.x_predicted[2]) > 0.04 or s.age >= 6)

result = etmpc.evaluate("cart_pendulum", ["every:3", AngleOrAge()], episodes=EPISODES, workers=WORKERS, progress=False)
print("done", result.summaries[1].episodes)
"""
REFUSED = (
    "policy angle-or-age: AngleOrAge is defined in __main__ ({}), which worker processes cannot import: "
    'define it in a module (or a script run under `if __name__ == "__main__":`), or use workers=1'
)


@pytest.mark.parametrize("source", ["-c", "stdin"])
def test_a_trigger_of_python_c_or_stdin_is_refused_before_any_work(source, tmp_path):
    script = MAIN_TRIGGER.replace("EPISODES", "40").replace("WORKERS", "2")
    run = dict(args=("-c", script)) if source == "-c" else dict(args=("-",), stdin=script)
    done = _run(script, tmp_path, **run)
    where = "python -c, a notebook or the interactive prompt" if source == "-c" else "a script read from stdin"
    assert done.returncode != 0 and done.stdout == ""
    assert done.stderr.strip().splitlines()[-1] == "etmpc.evaluation.evaluate.MainOnlyError: " + REFUSED.format(where)
    assert "multiprocessing" not in done.stderr and "abruptly" not in done.stderr


def test_a_trigger_of_python_c_plays_here_when_workers_are_not_given(tmp_path):
    script = MAIN_TRIGGER.replace("EPISODES", "40").replace("WORKERS", "None")  # 80 jobs: workers, were it not for it
    done = _run(script, tmp_path, args=("-c", script))
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "done 40"


# -- the first run, with an empty compiled-code cache ------------------------------------------------------
BUILDS = """
import etmpc
if __name__ == "__main__":
    etmpc.evaluate("cart_pendulum", ["every:3"], episodes=2, workers=2, progress=False)
"""


@pytest.mark.slow
def test_a_build_of_the_compiled_mpc_is_said_once_and_a_cached_one_not_at_all(tmp_path):
    cache = tmp_path / "cache"
    env = {"ETMPC_CACHE_DIR": str(cache)}
    first = _run(BUILDS, tmp_path, env=env)  # two workers, both needing the MPC: one builds, the other waits
    assert first.returncode == 0, first.stderr[-3000:]
    said = [line for line in first.stderr.splitlines() if line.startswith("etmpc: compiling")]
    assert said == [f"etmpc: compiling the cart_pendulum MPC to C once (about 5-40 s; cached in {cache})"]
    second = _run(BUILDS, tmp_path, env=env)
    assert second.returncode == 0 and "compiling" not in second.stderr, second.stderr[-3000:]
