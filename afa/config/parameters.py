"""Parameter models: the validated, typed form of a configuration section.

Each component declares one :class:`Parameters` subclass whose field names are the
Miro parameter names exactly as the seed's Annex A prints them (``EventName``,
``Motorrates``, ``SickLaser1_ID``) and whose defaults are the seed's defaults. Models are
frozen and reject unknown fields. Values arrive from the XML as strings and are
converted by pydantic, except ``bool``: Miro writes exactly ``true`` or ``false``, so
``1`` or ``yes`` is an error here rather than a silent truth.

A model is registered under its Miro type name (``Raptor::NodLaserParameters`` by
default: ``namespace`` + class name), which is what the XML's ``<parameter name=…>`` /
``<instance type=…>`` elements name.
"""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

__all__ = ["Parameters", "param", "parameter_types", "check_grid", "MAX_GRID_CELLS"]

_REGISTRY: dict[str, type[Parameters]] = {}


def parameter_types() -> dict[str, type[Parameters]]:
    """Registered parameter models by Miro type name."""
    return dict(_REGISTRY)


def param(default: Any = ..., *, unit: str = "", description: str = "") -> Any:
    """Declare a parameter with its unit and the seed's description."""
    extra: dict[str, Any] = {"unit": unit} if unit else {}
    return Field(default, description=description, json_schema_extra=extra or None)


class Parameters(BaseModel):
    """Base of every parameter model. Numbers must be finite (NaN and infinity are
    refused, with the parameter's line) unless a field says otherwise
    (``Field(allow_inf_nan=True)``)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    namespace: ClassVar[str] = "Raptor"
    miro_type: ClassVar[str] = ""
    #: The section a model is conventionally read from, when it is not named after the
    #: model (a section several components share); ``config defaults`` writes it so.
    section_name: ClassVar[str] = ""

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        super().__pydantic_init_subclass__(**kwargs)
        if "miro_type" not in cls.__dict__:
            cls.miro_type = f"{cls.namespace}::{cls.__name__}"
        _REGISTRY[cls.miro_type] = cls

    @field_validator("*", mode="before", check_fields=False)
    @classmethod
    def _miro_booleans(cls, value: Any, info: ValidationInfo) -> Any:
        field = cls.model_fields.get(info.field_name or "")
        if field is not None and field.annotation is bool and isinstance(value, str):
            if value not in ("true", "false"):
                raise ValueError(f"a bool is written exactly 'true' or 'false', not {value!r}")
            return value == "true"
        return value


#: Cells one configured grid may hold (2048 × 2048: 250 m at 0.125 m). A map is allocated
#: when its component is built, so a larger grid is refused with the parameter's line
#: instead of exhausting memory; the shipped grids hold at most 250,000 cells.
MAX_GRID_CELLS = 1 << 22


def check_grid(model: Parameters, *grids: tuple[str, str]) -> None:
    """Check ``model``'s grids, each named by its (depth, width) fields in mm, against its
    ``Gridsize`` (mm): whole cells and at most :data:`MAX_GRID_CELLS`. Raises ValueError."""
    gridsize = model.Gridsize  # type: ignore[attr-defined]
    for depth_name, width_name in grids:
        for name in (depth_name, width_name):
            if getattr(model, name) % gridsize:
                raise ValueError(f"{name} ({getattr(model, name)} mm) is not a whole number "
                                 f"of Gridsize ({gridsize} mm) cells")
        cells = (getattr(model, depth_name) // gridsize) * (getattr(model, width_name) // gridsize)
        if cells > MAX_GRID_CELLS:
            raise ValueError(f"{depth_name} × {width_name} at Gridsize {gridsize} mm is "
                             f"{cells:,} cells, more than {MAX_GRID_CELLS:,}")
