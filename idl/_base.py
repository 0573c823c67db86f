"""Foundations of the IDL: immutable pydantic models, numpy array fields, interfaces.

This module imports only the standard library, numpy and pydantic, so the IDL can be
used by tools that do not load the framework.

- :class:`IDLModel` is the base of every event body and polled value. Instances are
  frozen and numpy fields are read-only, so one event body can be delivered to every
  subscriber without copies and without one consumer changing what another sees.
  Every model has two lossless forms: the binary wire form of :mod:`idl.wire` (arrays
  as raw buffers beside a JSON header: logs, the network, the console) and a JSON form,
  :meth:`IDLModel.to_json` / :meth:`IDLModel.from_json` (arrays as dtype, shape and
  base64), for people and tools that only speak JSON.
- One rule for non-finite floats in JSON, in both forms: ``"Infinity"``,
  ``"-Infinity"`` and ``"NaN"`` as strings (a browser's ``JSON.parse`` accepts them and
  ``Number("Infinity")`` converts; pydantic reads them back).
- Every public model is registered under a qualified, versioned *type name*
  (:func:`type_name`, e.g. ``idl.sensors.GpsIDL@1``); a second class claiming a
  registered name is refused.
- :func:`Array` annotates a numpy field with its dtype and shape (``None`` for a free
  dimension): ``Annotated[np.ndarray, Array("float64", (None, 3))]``.
- :func:`field` declares a field with its unit and description.
- :class:`Interface` is the base of polled interfaces: subclasses declare ``async``
  methods with the seed's names and type annotations, and nothing else.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import inspect
import re
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import Any, ClassVar

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field, GetCoreSchemaHandler, GetJsonSchemaHandler
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema
from pydantic_core.core_schema import ValidationInfo

__all__ = ["IDLModel", "Array", "field", "Interface", "MethodSpec", "idl_types", "type_name",
           "TypeRegistryError"]

_TYPES: dict[str, type[IDLModel]] = {}


class TypeRegistryError(TypeError):
    """Two IDL classes claim one type name."""


def idl_types() -> Mapping[str, type[IDLModel]]:
    """Every registered IDL model class by qualified name (without the version)."""
    return _TYPES


def type_name(cls: type[IDLModel]) -> str:
    """The qualified, versioned name a model travels under: ``module.Class@version``."""
    return f"{cls.idl_name}@{cls.idl_version}"


class IDLModel(BaseModel):
    """Base of every IDL struct: frozen, no unknown fields, lossless serialisation.

    ``idl_name`` (default ``module.QualifiedName``) and ``idl_version`` (default 1) name
    the type on the wire; raise the version when a change makes old data unreadable.
    Classes whose name starts with ``_`` and classes defined inside functions without an
    explicit ``idl_name`` are not registered (they can still be encoded, and decoded
    when the class is given).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True,
                              ser_json_inf_nan="strings")

    idl_name: ClassVar[str] = ""
    idl_version: ClassVar[int] = 1

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        super().__pydantic_init_subclass__(**kwargs)
        if "idl_name" not in cls.__dict__:
            cls.idl_name = f"{cls.__module__}.{cls.__qualname__}"
            if "<locals>" in cls.__qualname__:
                return
        if cls.__name__.startswith("_"):
            return
        known = _TYPES.get(cls.idl_name)
        if known is not None and known is not cls:
            raise TypeRegistryError(
                f"IDL type name {cls.idl_name!r} is already taken by {known.__module__}."
                f"{known.__qualname__}; give {cls.__qualname__} another idl_name")
        _TYPES[cls.idl_name] = cls

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
#: The dtype strings arrays are described with: byte order, kind (bool, int, unsigned,
#: float), item size. Nothing else (objects, strings, deprecated aliases) is accepted.
_DTYPE_TEXT = re.compile(r"[<>|=][biuf][1248]")
#: Context key under which :mod:`idl.wire` collects (encoding) or supplies (decoding) the
#: raw array buffers that travel beside the JSON header.
WIRE_BUFFERS = "afa.wire.buffers"


def field(default: Any = ..., *, unit: str = "", description: str = "", **kwargs: Any) -> Any:
    """A model field with its unit (``"m"``, ``"rad/s"``, ``"1"`` for dimensionless)."""
    extra: dict[str, Any] = {"unit": unit} if unit else {}
    return Field(default, description=description, json_schema_extra=extra or None,  # type: ignore[arg-type]
                 **kwargs)


@dataclass(frozen=True, slots=True)
class Array:
    """Annotation for a numpy field: dtype and shape (``None`` = any length)."""

    dtype: str
    shape: tuple[int | None, ...]
    # derived once: validation runs for every array of every event body
    _numpy_dtype: np.dtype[Any] = dataclass_field(init=False, repr=False, compare=False)
    _fixed: tuple[tuple[int, int], ...] = dataclass_field(init=False, repr=False,
                                                          compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_numpy_dtype", np.dtype(self.dtype))
        object.__setattr__(self, "_fixed", tuple((axis, size) for axis, size
                                                 in enumerate(self.shape) if size is not None))

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.with_info_plain_validator_function(
            self._validate,
            serialization=core_schema.plain_serializer_function_ser_schema(
                self._serialize, info_arg=True
            ),
        )

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        """An array is an object with its dtype and shape, and either its bytes in base64
        (the JSON form) or the index of a buffer beside the header (the wire form)."""
        dims = len(self.shape)
        return {
            "type": "object",
            "title": f"ndarray[{self.dtype}, {tuple('n' if d is None else d for d in self.shape)}]",
            "properties": {
                "dtype": {"type": "string", "description": "numpy dtype string, e.g. '<f4'"},
                "shape": {"type": "array", "items": {"type": "integer", "minimum": 0},
                          "minItems": dims, "maxItems": dims},
                "data": {"type": "string", "contentEncoding": "base64",
                         "description": "C-order bytes (JSON form)"},
                "$array": {"type": "integer", "minimum": 0,
                           "description": "index of the raw buffer (wire form)"},
            },
            "required": ["dtype", "shape"],
            "x-afa-array": {"dtype": self.dtype, "shape": list(self.shape)},
        }

    def _validate(self, value: Any, info: ValidationInfo) -> np.ndarray:
        if not isinstance(value, np.ndarray) and isinstance(value, Mapping) \
                and "dtype" in value:
            value = self._from_mapping(value, info.context)
        try:
            array = np.asarray(value, dtype=self._numpy_dtype)
        except (TypeError, ValueError) as exc:
            raise PydanticCustomError("ndarray", "not an array of {dtype}: {err}",
                                      {"dtype": self.dtype, "err": str(exc)}) from None
        shape = array.shape
        fits = len(shape) == len(self.shape)
        if fits:
            for axis, size in self._fixed:
                if shape[axis] != size:
                    fits = False
                    break
        if not fits:
            raise PydanticCustomError(
                "ndarray_shape", "array shape {got} does not match {want}",
                {"got": shape, "want": tuple("n" if d is None else d for d in self.shape)},
            )
        if array.flags.writeable:
            array = array.copy()
            array.flags.writeable = False
        return array

    def _from_mapping(self, value: Mapping[str, Any], context: Any) -> Any:
        """An array from its JSON (base64) or wire (buffer index) description."""
        try:
            text = value["dtype"]
            if not (isinstance(text, str) and _DTYPE_TEXT.fullmatch(text)):
                raise ValueError(f"dtype {text!r} is not a plain numeric dtype string")
            dtype = np.dtype(text)
            if dtype.newbyteorder("=") != np.dtype(self.dtype).newbyteorder("="):
                raise ValueError(f"dtype {text} where {self.dtype} is declared")
            shape = tuple(int(n) for n in value["shape"])
            if any(n < 0 for n in shape):
                raise ValueError("negative dimensions are refused")
            if "$array" in value:
                buffers = context.get(WIRE_BUFFERS) if isinstance(context, Mapping) else None
                if buffers is None:
                    raise ValueError("a wire array reference outside a wire frame")
                raw = buffers[int(value["$array"])]
            else:
                raw = base64.b64decode(value["data"], validate=True)
            return np.frombuffer(raw, dtype=dtype).reshape(shape)
        except (KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            raise PydanticCustomError("ndarray", "bad array description: {err}",
                                      {"err": str(exc)}) from None

    def _serialize(self, value: np.ndarray, info: Any) -> Any:
        context = info.context
        if isinstance(context, dict):  # the wire codec's context first: it is the hot path
            wire_buffers = context.get(WIRE_BUFFERS)
            if wire_buffers is not None and info.mode == "json":
                contiguous = np.ascontiguousarray(value)
                wire_buffers.append(contiguous)
                return {"dtype": contiguous.dtype.str, "shape": list(contiguous.shape),
                        "$array": len(wire_buffers) - 1}
        if info.mode != "json":
            return value
        if context is _FINGERPRINT:
            return _fingerprint_head(value)
        contiguous = np.ascontiguousarray(value)
        return {"dtype": contiguous.dtype.str, "shape": list(contiguous.shape),
                "data": base64.b64encode(contiguous.tobytes()).decode("ascii")}


#: The fingerprint heads of recent frozen arrays, by identity (see :func:`_fingerprint_head`).
_HEADS: dict[int, tuple[np.ndarray, dict[str, Any]]] = {}
_HEADS_KEPT = 256
#: Only small arrays are remembered: the ones carried again are votes and arc sets (a
#: few hundred bytes); a map's or an image's arrays are new every time, and keeping
#: them alive would only hold memory.
_HEAD_BYTES = 16384


def _fingerprint_head(value: np.ndarray) -> dict[str, Any]:
    """An array's part of :meth:`IDLModel.fingerprint`: dtype, shape and SHA-256.

    Event bodies often carry the same array objects again (a vote re-stamped, the arc
    set's curvatures in every vote and decision), so the heads of the last few hundred
    small arrays (``_HEAD_BYTES``) that own their memory and are read-only (as
    validation leaves them) are kept by identity; the cache holds the array itself, so
    its ``id`` cannot be reused while the entry lives. (Writing into such an array after
    making it read-only is already a broken producer: every subscriber shares it.)
    """
    key = id(value)
    known = _HEADS.get(key)
    if known is not None and known[0] is value:
        return known[1]
    contiguous = np.ascontiguousarray(value)
    head = {"dtype": contiguous.dtype.str, "shape": list(contiguous.shape),
            "sha256": hashlib.sha256(contiguous.data).hexdigest()}
    if value.base is None and not value.flags.writeable and value.nbytes <= _HEAD_BYTES:
        if len(_HEADS) >= _HEADS_KEPT:
            del _HEADS[next(iter(_HEADS))]
        _HEADS[key] = (value, head)
    return head


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

    @functools.cached_property
    def arguments_model(self) -> type[IDLModel]:
        """An IDL model whose fields are the method's parameters: how a call's arguments
        travel through :mod:`idl.wire` (to another process, into a log)."""
        hints = self.hints()
        fields: dict[str, Any] = {}
        for name in self.parameters:
            default = self.signature.parameters[name].default
            fields[name] = (hints.get(name, Any),
                            ... if default is inspect.Parameter.empty else default)
        return self._model("arguments", fields)

    @functools.cached_property
    def result_model(self) -> type[IDLModel]:
        """An IDL model with one field, ``result``: how a call's result travels."""
        return self._model("result", {"result": (self.hints().get("return", type(None)), ...)})

    def _model(self, what: str, fields: dict[str, Any]) -> type[IDLModel]:
        owner = self.function.__qualname__.rpartition(".")[0]
        model: type[IDLModel] = pydantic.create_model(  # type: ignore[call-overload]
            f"{owner}.{self.name}.{what}", __base__=IDLModel,
            __module__=self.function.__module__, **fields)
        return model


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
