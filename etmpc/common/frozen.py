"""Values a policy is shown and cannot write through: read-only array views and a read-only mapping.

The control loop hands a recomputation policy its own memory (the measured state, the kept plan, the
task's observation). A policy under test must not be able to change what the loop then does with
it, or it would change its own score: so what it is shown is a read-only view (writing into it
raises ``ValueError: assignment destination is read-only``) or a :class:`FrozenMapping` (item
assignment raises ``TypeError``). Views cost no copy; the loop's own arrays stay writable to it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np


def readonly(value: Any) -> Any:
    """A read-only view of an array (the array itself if it is one already); anything else as it is
    (numpy scalars, floats and strings cannot be written through)."""
    if isinstance(value, np.ndarray) and value.flags.writeable:
        value = value.view()
        value.flags.writeable = False
    return value


class FrozenMapping(Mapping):
    """A mapping that cannot be changed, whose arrays are read-only views; it pickles (unlike
    ``types.MappingProxyType``) and compares equal to a dict of the same items."""

    __slots__ = ("_items",)

    def __init__(self, items: Mapping | None = None):
        self._items = {key: readonly(value) if isinstance(value, np.ndarray) else value for key, value in (items or {}).items()}

    def __getitem__(self, key):
        return self._items[key]

    def __iter__(self) -> Iterator:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"FrozenMapping({self._items!r})"

    def __reduce__(self):
        return FrozenMapping, (dict(self._items),)

    def copy(self) -> dict:
        """A plain, writable dict of the same items (the arrays still read-only views)."""
        return dict(self._items)


def frozen(mapping: Mapping | None) -> FrozenMapping | None:
    """``mapping`` as a :class:`FrozenMapping` (``None`` stays ``None``)."""
    if mapping is None or isinstance(mapping, FrozenMapping):
        return mapping
    return FrozenMapping(mapping)
