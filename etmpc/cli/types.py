"""The ``etmpc`` command line's argument types, one per kind of value: each refuses bad input with a
one-line message (argparse turns it into ``argument --NAME: ...``), with the checks the Python API
shares (:mod:`etmpc.common.checks`)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from etmpc.common.documents import yaml_loads
from etmpc.common import checks

MAX_FPS = 1000.0


def whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def checked(check, value):
    """``check(value)`` (one of :mod:`etmpc.common.checks`, which the Python API uses too) as argparse's error."""
    try:
        return check(value)
    except checks.BadValue as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def positive_int(text: str) -> int:
    return checked(lambda v: checks.at_least(v, 1), whole(text))


def non_negative_int(text: str) -> int:
    return checked(lambda v: checks.at_least(v, 0), whole(text))


def workers(text: str) -> int:
    return checked(checks.workers, whole(text))


def seed(text: str) -> int:
    return checked(checks.seed, whole(text))


def index(text: str) -> int:
    value = whole(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def fps(text: str) -> float:
    value = number(text)
    if not (math.isfinite(value) and 0 < value <= MAX_FPS):
        raise argparse.ArgumentTypeError(f"frames per second must be in (0, {MAX_FPS:g}], got {text}")
    return value


def price(text: str) -> float:
    return checked(checks.price, number(text))


def prices(text: str) -> tuple[float, ...]:
    return tuple(price(part.strip()) for part in text.split(","))


def json_path(text: str) -> Path:
    path = Path(text)
    if path.exists() and path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory, not a file")
    return path


def png_path(text: str) -> Path:
    path = json_path(text)
    if path.suffix != ".png":
        raise argparse.ArgumentTypeError(f"{text} does not end in .png")
    return path


def rrd_path(text: str) -> Path:
    path = json_path(text)
    if path.suffix != ".rrd":
        raise argparse.ArgumentTypeError(f"{text} does not end in .rrd")
    return path


def recording(text: str) -> Path | str:
    """``--record``: a ``.rrd`` file's path, or a Rerun viewer's URL to stream to (``rerun+http://HOST:PORT/proxy``,
    ``tcp://HOST:PORT``), checked for its form here and for an answer when the recording opens."""
    from etmpc.common.errors import EtmpcError
    from etmpc.views.sinks import is_url, viewer_url

    if not is_url(text):
        return rrd_path(text)
    try:
        return viewer_url(text)
    except EtmpcError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def setting(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` (``--set``): the key, and the value read as YAML (``yaml.safe_load``: numbers, words,
    ``[a, b]`` lists, ``null``; never evaluated as code)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE (a setting's name, =, its value)")
    try:
        return key, yaml_loads(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{key}: cannot read {value[:60]!r} ({exc})") from None
