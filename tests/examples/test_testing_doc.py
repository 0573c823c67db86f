"""docs/testing.md shows tests/examples/test_imu_example.py as it is."""

from pathlib import Path

HERE = Path(__file__).resolve().parent
DOC = HERE.parents[1] / "docs" / "testing.md"


def test_the_testing_guide_shows_the_example_file_verbatim():
    example = (HERE / "test_imu_example.py").read_text()
    assert f"```python\n{example}```" in DOC.read_text()
