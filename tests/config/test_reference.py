"""docs/parameters.md is generated from the models and must not go stale."""

from pathlib import Path

from afa.config.reference import reference_markdown

DOC = Path(__file__).resolve().parents[2] / "docs" / "parameters.md"


def test_parameter_reference_is_current():
    assert DOC.read_text() == reference_markdown(), (
        "docs/parameters.md is stale: run `python -m afa config reference > docs/parameters.md`")


def test_reference_covers_every_annex_a_section_with_units():
    text = reference_markdown()
    for model in ("NodLaserParameters", "StereoParameters", "ImuParameters",
                  "GpsSokkiaParameters", "WheelOdometryParameters", "TerrainMapParameters",
                  "TraversabilityMapParameters", "ModelServerParameters", "FindPathParameters",
                  "ObstacleAvoidanceParameters", "ObstacleDetectionParameters",
                  "ArcArbiterParameters", "VehicleControlParameters"):
        assert f"## `Raptor::{model}`" in text
    assert "| `Motorrates` | float | 15.0 | deg/s |" in text
