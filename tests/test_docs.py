"""Examples in the docs run as tests, so the docs cannot rot."""

import asyncio
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _examples():
    for path in sorted(DOCS.rglob("*.md")):
        for index, block in enumerate(re.findall(r"```python\n(.*?)```", path.read_text(), re.S)):
            if "async def main" in block:
                yield pytest.param(block, f"docs_{path.stem}_{index}".replace("-", "_"),
                                   id=f"{path.relative_to(DOCS)}#{index}")


@pytest.mark.parametrize("source, module", list(_examples()))
def test_documented_example_runs(source, module):
    namespace: dict = {"__name__": module}  # one module per example: its own IDL names
    exec(compile(source, "<docs example>", "exec"), namespace)
    asyncio.run(namespace["main"]())
