# The README quick start: `make reproduce` (the main job) and `make test`. `make sweep` adds the trade-off
# curves to the same run; `make evaluate` is a shorter look.
# Each creates the virtual environment in .venv on first use and install the project into it.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
export MUJOCO_GL ?= egl

.PHONY: reproduce sweep leaderboard evaluate example test types docs dist setup clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

# The main job: the paper's experiments on every task, with REPORT.md and results.json. Running it
# again after an interruption continues.
reproduce: setup
	$(BIN)/etmpc reproduce --out results/reproduce

# The trade-off curve of every task (the price of a computation swept), added to the same run: its
# finished stages are reused, and REPORT.md gains the equal-rate answer. Continues after an interruption.
sweep: setup
	$(BIN)/etmpc reproduce --sweep --out results/reproduce

# The leaderboard: every built-in trigger scored on every task's stored test set (etmpc score
# --leaderboard), written to docs/leaderboard.md and .json with the profile figure; the README's headline
# table is rewritten from it. Finished rows are kept in results/leaderboard, in git: an interrupted run continues, and
# a fresh checkout plays only the rows whose task, policy file or etmpc changed.
# Play it on an otherwise idle machine: its CPU column grows when heavy work shares the cores.
leaderboard: setup
	$(BIN)/etmpc score --leaderboard --out docs --readme README.md

# A shorter look: compare recomputation policies on the stored 100-episode test set of each system,
# and draw the paper's Figure 1 (battery forecasts).
evaluate: setup
	$(BIN)/etmpc evaluate --task cart_pendulum --policy always --policy never \
		--policy every:2 --policy every:5 --policy every:10 \
		--policy threshold:0.1 --policy threshold:0.3 --json results/cart_pendulum.json
	$(BIN)/etmpc evaluate --task battery --policy always --policy never \
		--policy every:2 --policy every:5 --policy every:10 \
		--policy threshold:0.01 --policy threshold:0.02 --json results/battery.json
	$(BIN)/etmpc figure forecasts --policy every:20 --policy every:5 --out results/figure1_battery_forecasts.png

# A trigger of your own (examples/my_trigger.py) against the built-in ones, with the paired table.
example: setup
	cd examples && ../$(BIN)/python my_trigger.py

test: setup
	$(BIN)/python -m pytest -q

# The type checker alone: mypy over etmpc/ with pyproject.toml's [tool.mypy] (`make test` runs it too,
# tests/end_to_end/test_types.py, and requires zero errors).
types: setup
	$(BIN)/python -m mypy

# The documentation site into site/ (mkdocs.yml; strict: a broken link or anchor fails it). `make test`
# builds it too (tests/end_to_end/test_docs.py); `$(BIN)/mkdocs serve` shows it while you write.
docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

# The release artifacts: the sdist and the wheel (built from the sdist) into dist/, then `twine check`
# (the metadata, and the README as PyPI renders it). tests/end_to_end/test_packaging.py builds and checks them too.
dist: setup
	rm -rf dist
	$(BIN)/python -m build --outdir dist .
	$(BIN)/twine check --strict dist/*

clean:
	rm -rf $(VENV) results
