"""The package list: every package under etmpc/, found (not listed by hand), and the data folders
models/, tasks/ and the
hyperparameter files of policies/, shipped as etmpc._data.models, etmpc._data.tasks and etmpc._data.policies (see pyproject.toml)."""

from setuptools import find_packages, setup

setup(packages=find_packages(include=["etmpc", "etmpc.*"]) + ["etmpc._data.models", "etmpc._data.tasks", "etmpc._data.policies"])
