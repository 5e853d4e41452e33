"""The package list: every package under etmpc/, found (not listed by hand), and the data folders
models/ and tasks/, shipped as etmpc._data.models and etmpc._data.tasks (see pyproject.toml)."""

from setuptools import find_packages, setup

setup(packages=find_packages(include=["etmpc", "etmpc.*"]) + ["etmpc._data.models", "etmpc._data.tasks"])
