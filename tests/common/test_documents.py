"""The shared readers of what a user hands in: JSON and YAML of any depth are one ``ValueError`` (never a
``RecursionError``), a sealed document with a number not scored checks when read back, and a record's fields
are checked against the types its dataclass annotates (the one check of settings and of rows read from files)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

from etmpc.common import checks
from etmpc.common.documents import check_seal, loads, sealed, yaml_loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import dumps


@pytest.mark.parametrize("read", [loads, yaml_loads])
def test_a_document_nested_past_the_readers_depth_is_a_value_error(read):
    with pytest.raises(ValueError, match="nested too deeply"):
        read("[" * 100_000 + "]" * 100_000)
    assert read("[[[1]]]") == [[[1]]]  # a shallow one reads


def test_strict_json_refuses_the_constants_json_does_not_have():
    for text in ("NaN", "[Infinity]", '{"a": -Infinity}'):
        with pytest.raises(ValueError, match="is not a JSON number"):
            loads(text)


def test_a_sealed_row_with_a_number_not_scored_checks_when_read_back_and_an_edit_does_not():
    row = {"key": {"spec": "every:3"}, "row": {"score": math.nan, "objective_mean": math.inf, "episode_scores": [1.5]}}
    read = loads(dumps(sealed(row)))
    assert read["row"]["score"] is None and read["row"]["objective_mean"] is None  # as the file holds it
    check_seal(read, "row", "delete it")  # no ValueError: NaN is sealed as the null it is written as
    read["row"]["episode_scores"] = [1.6]
    with pytest.raises(EtmpcError, match="does not match its checksum"):
        check_seal(read, "row", "delete it")


@dataclass(frozen=True)
class Record:
    count: int = 1
    price: float = 0.5
    names: tuple[str, ...] = ("always",)
    limit: int | None = None
    cpu: dict[str, float] = field(default_factory=dict)
    on: bool = False


@pytest.mark.parametrize(
    "values, finite, says",
    [
        ({"count": True}, False, "count must be a whole number in -1e9..1e9, got True"),  # a bool is no count
        ({"count": 2.0}, False, "count must be a whole number"),
        ({"count": 10**23}, False, "count must be a whole number in -1e9..1e9, got 100000000000000000000000"),
        ({"price": "0.5"}, False, "price must be a number, got '0.5'"),
        ({"price": math.nan}, True, "price must be a number (finite), got nan"),
        ({"price": -math.inf}, True, "price must be a number (finite), got -inf"),
        ({"names": ("always", 3)}, False, "names must be a list of text, got ('always', 3)"),
        ({"names": "always"}, False, "names must be a list of text"),
        ({"limit": "4"}, False, "limit must be a whole number in -1e9..1e9 or null, got '4'"),
        ({"cpu": {"solve": "1"}}, False, "cpu must be an object of a number"),
        ({"cpu": [1.0]}, False, "cpu must be an object of a number"),
        ({"on": "no"}, False, "on must be true or false, got 'no'"),
        ({"on": 1}, False, "on must be true or false, got 1"),
    ],
)
def test_a_field_of_another_type_is_named_with_what_it_must_be(values, finite, says):
    with pytest.raises(checks.BadValue, match="^" + says.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
        checks.typed(Record(**values), finite=finite, most=checks.MAX_COUNT)
    assert isinstance(checks.BadValue("x"), ValueError) and isinstance(checks.BadValue("x"), EtmpcError)


def test_fields_of_their_types_pass_nan_where_a_number_may_be_missing():
    checks.typed(Record(count=3, price=math.nan, names=(), limit=7, cpu={"solve": 1.0}, on=True))  # no finite: NaN is null
    import numpy as np

    checks.typed(Record(count=np.int64(3), price=np.float64(0.25)), finite=True, most=checks.MAX_COUNT)
