"""Foundations of the IDL: immutable pydantic models, numpy array fields, interfaces.

This module imports only the standard library, numpy and pydantic, so the IDL can be
used by tools that do not load the framework.

- :class:`IDLModel` is the base of every event body and polled value. Instances are
  frozen and numpy fields are read-only, so one event body can be delivered to every
  subscriber without copies and without one consumer changing what another sees.
  Every model serialises losslessly with :meth:`IDLModel.to_json` /
  :meth:`IDLModel.from_json` (arrays as dtype, shape and base64 bytes).
- :func:`Array` annotates a numpy field with its dtype and shape (``None`` for a free
  dimension): ``Annotated[np.ndarray, Array("float64", (None, 3))]``.
- :func:`field` declares a field with its unit and description.
- :class:`Interface` is the base of polled interfaces: subclasses declare ``async``
  methods with the seed's names and type annotations, and nothing else.
"""

from __future__ import annotations

import base64
import hashlib
import inspect
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, GetCoreSchemaHandler
from pydantic_core import PydanticCustomError, core_schema

__all__ = ["IDLModel", "Array", "field", "Interface", "MethodSpec", "idl_types"]

_TYPES: dict[str, type[IDLModel]] = {}


def idl_types() -> Mapping[str, type[IDLModel]]:
    """Every IDL model class by name (the names used when events are serialised)."""
    return _TYPES


class IDLModel(BaseModel):
    """Base of every IDL struct: frozen, no unknown fields, lossless JSON."""

    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        super().__pydantic_init_subclass__(**kwargs)
        if not cls.__name__.startswith("_"):
            _TYPES[cls.__name__] = cls

    def to_json(self) -> bytes:
        """Serialise losslessly (numpy arrays included)."""
        return self.model_dump_json().encode()

    def fingerprint(self) -> bytes:
        """:meth:`to_json` with each array's bytes replaced by their SHA-256: equal for
        equal values, different when any field or array element differs, and cheap to
        hash for big arrays (no base64). For comparing runs, not for reading back."""
        return self.model_dump_json(context=_FINGERPRINT).encode()

    @classmethod
    def from_json(cls, data: bytes | str) -> typing.Self:
        """Inverse of :meth:`to_json`."""
        return cls.model_validate_json(data)

    def __eq__(self, other: object) -> bool:  # arrays compare by value, not identity
        if type(other) is not type(self):
            return NotImplemented
        for name in type(self).model_fields:
            a, b = getattr(self, name), getattr(other, name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not (
                    isinstance(a, np.ndarray)
                    and isinstance(b, np.ndarray)
                    and a.dtype == b.dtype
                    and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
                ):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]


#: Serialisation context of :meth:`IDLModel.fingerprint` (compared by identity).
_FINGERPRINT: dict[str, bool] = {"fingerprint": True}


def field(default: Any = ..., *, unit: str = "", description: str = "", **kwargs: Any) -> Any:
    """A model field with its unit (``"m"``, ``"rad/s"``, ``"1"`` for dimensionless)."""
    extra = {"unit": unit} if unit else {}
    return Field(default, description=description, json_schema_extra=extra or None, **kwargs)


@dataclass(frozen=True, slots=True)
class Array:
    """Annotation for a numpy field: dtype and shape (``None`` = any length)."""

    dtype: str
    shape: tuple[int | None, ...]

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.no_info_plain_validator_function(
            self._validate,
            serialization=core_schema.plain_serializer_function_ser_schema(
                self._serialize, info_arg=True
            ),
        )

    def _validate(self, value: Any) -> np.ndarray:
        if isinstance(value, Mapping) and "data" in value and "dtype" in value:
            raw = base64.b64decode(value["data"])
            value = np.frombuffer(raw, dtype=np.dtype(value["dtype"])).reshape(value["shape"])
        try:
            array = np.asarray(value, dtype=np.dtype(self.dtype))
        except (TypeError, ValueError) as exc:
            raise PydanticCustomError("ndarray", "not an array of {dtype}: {err}",
                                      {"dtype": self.dtype, "err": str(exc)}) from None
        if array.ndim != len(self.shape) or any(
            want is not None and got != want
            for got, want in zip(array.shape, self.shape, strict=True)
        ):
            raise PydanticCustomError(
                "ndarray_shape", "array shape {got} does not match {want}",
                {"got": array.shape, "want": tuple("n" if d is None else d for d in self.shape)},
            )
        if array.flags.writeable:
            array = array.copy()
            array.flags.writeable = False
        return array

    def _serialize(self, value: np.ndarray, info: Any) -> Any:
        if info.mode == "json":
            contiguous = np.ascontiguousarray(value)
            if info.context is _FINGERPRINT:
                content = {"sha256": hashlib.sha256(contiguous).hexdigest()}
            else:
                content = {"data": base64.b64encode(contiguous.tobytes()).decode("ascii")}
            return {"dtype": contiguous.dtype.str, "shape": list(contiguous.shape), **content}
        return value


@dataclass(frozen=True)
class MethodSpec:
    """One method of a polled interface, with its argument and result types."""

    name: str
    signature: inspect.Signature
    function: Callable[..., Any]
    doc: str

    @property
    def parameters(self) -> list[str]:
        return [p for p in self.signature.parameters if p != "self"]

    def hints(self) -> dict[str, Any]:
        """Resolved annotations (parameters and ``return``)."""
        return typing.get_type_hints(self.function, include_extras=True)


class Interface:
    """Base of polled interfaces (Miro's IDL ``interface``).

    Declare methods as ``async def name(self, arg: T) -> R: ...`` with the seed's
    names. Class attributes: ``call_timeout`` (seconds a client waits for any call) and
    ``wait_timeout`` (how long a ``getWait…`` waits for the next sample). Servers do not
    subclass an interface; they serve it (see :meth:`afa.Component.serve`).
    """

    methods: ClassVar[Mapping[str, MethodSpec]] = {}
    call_timeout: ClassVar[float] = 5.0
    wait_timeout: ClassVar[float] = 1.0

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        methods: dict[str, MethodSpec] = {}
        for klass in reversed(cls.__mro__):
            for name, value in vars(klass).items():
                if name.startswith("_") or not inspect.iscoroutinefunction(value):
                    continue
                methods[name] = MethodSpec(
                    name, inspect.signature(value), value, inspect.getdoc(value) or ""
                )
        cls.methods = methods
