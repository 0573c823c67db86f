"""Bodies built without validation (components/trusted.py) equal validated ones."""

from __future__ import annotations

import numpy as np

from components.trusted import trusted
from idl import EgoMapArrayEventIDL, MapArrayEventIDL, TimeIDL


def _values() -> dict:
    rng = np.random.default_rng(7)
    elevation = rng.normal(size=(4, 5))  # float64: the IDL declares float32
    elevation[0, 0] = np.nan
    return {"time": TimeIDL(sec=3, usec=250), "frame": "World", "mapPose": np.eye(4),
            "initialUTM": [451000.0, 5030000.0, 60.0], "gridsize": 1, "originX": -2,
            "originY": 0.5, "rows": 4, "cols": 5, "elevation": elevation,
            "minHeight": elevation - 0.1, "maxHeight": elevation + 0.1,
            "pointCount": np.arange(20, dtype=np.int64).reshape(4, 5),
            "variance": np.abs(elevation)}


def test_a_trusted_body_equals_the_validated_one_field_by_field():
    for cls in (MapArrayEventIDL, EgoMapArrayEventIDL):
        validated = cls(**_values())
        built = trusted(cls, **_values())
        assert type(built) is cls
        assert built.model_fields_set == validated.model_fields_set
        assert built.model_dump_json() == validated.model_dump_json()
        for name in cls.model_fields:
            mine, theirs = getattr(built, name), getattr(validated, name)
            assert type(mine) is type(theirs), name
            if isinstance(mine, np.ndarray):
                assert mine.dtype == theirs.dtype and not mine.flags.writeable, name
                np.testing.assert_array_equal(mine, theirs)


def test_a_trusted_body_does_not_share_the_callers_writable_arrays():
    values = _values()
    elevation = values["elevation"].astype(np.float32)
    body = trusted(MapArrayEventIDL, **{**values, "elevation": elevation})
    elevation[1, 1] = 99.0
    assert body.elevation[1, 1] != 99.0
    frozen = elevation.copy()
    frozen.flags.writeable = False
    assert trusted(MapArrayEventIDL, **{**values, "elevation": frozen}).elevation is frozen
