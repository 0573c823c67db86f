"""Event bodies built from values a component made itself, without pydantic's validation.

Validating an IDL model checks every array's dtype and shape and runs the model's own
invariant checks (a map's ``_check`` scans every layer): the right thing for input from
elsewhere, a cost without a purpose for arrays a component has just computed, whose
tests check those invariants. The maps publish a few such bodies a second, each with
tens of thousands of cells.

:func:`trusted` builds the same model as validation would from valid input: array
fields are converted to their declared dtype and made read-only (copied first if
writable, as :class:`idl._base.Array` does), ``float`` and ``int`` fields are converted to
their type, the rest is taken as given. Nothing else is checked: invalid values give an
invalid body. ``tests/components/test_trusted.py`` checks that the bodies equal validated
ones, field by field and dtype by dtype.
"""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np

from idl._base import Array, IDLModel

__all__ = ["trusted"]

M = TypeVar("M", bound=IDLModel)

_CONVERTERS: dict[type[Any], dict[str, Any]] = {}


def trusted(cls: type[M], **values: Any) -> M:
    """``cls(**values)`` without validation (module docstring)."""
    converters = _converters(cls)
    for name, value in values.items():
        convert = converters.get(name)
        if convert is not None:
            values[name] = convert(value)
    return cls.model_construct(**values)


def _converters(cls: type[IDLModel]) -> dict[str, Any]:
    """Per field of ``cls``, the conversion validation would apply to a valid value."""
    known = _CONVERTERS.get(cls)
    if known is None:
        known = {}
        for name, info in cls.model_fields.items():
            array = next((m for m in info.metadata if isinstance(m, Array)), None)
            if array is not None:
                known[name] = _array_converter(np.dtype(array.dtype))
            elif info.annotation in (float, int):
                known[name] = info.annotation
        _CONVERTERS[cls] = known
    return known


def _array_converter(dtype: np.dtype[Any]) -> Any:
    def convert(value: Any) -> np.ndarray:
        array = np.asarray(value, dtype=dtype)
        if array.flags.writeable:
            array = array.copy()
            array.flags.writeable = False
        return array
    return convert
