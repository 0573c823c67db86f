"""docs/tutorial.ipynb, executed as a user would run it: in a fresh kernel, cell by cell,
from the docs folder. Any cell that raises fails the test (nbclient's
CellExecutionError names the cell and shows its traceback).

To refresh the outputs saved in the notebook after editing it::

    python tests/test_tutorial_notebook.py --write
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "docs" / "tutorial.ipynb"


def execute(notebook: Path = NOTEBOOK) -> Any:
    """Run every cell of ``notebook`` in a new kernel started in its folder; returns the
    executed notebook. The kernel imports this checkout's afa (PYTHONPATH)."""
    nb = nbformat.read(notebook, as_version=4)
    path = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([path] if path else []))
    try:
        NotebookClient(nb, timeout=240, kernel_name="python3",
                       resources={"metadata": {"path": str(notebook.parent)}}).execute()
    finally:
        if path is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = path
    return nb


def outputs(nb: Any) -> tuple[str, int]:
    """All text the cells printed or returned, and how many images they drew."""
    text, images = [], 0
    for cell in nb.cells:
        for output in cell.get("outputs", ()):
            if output.output_type == "stream":
                text.append(output.text)
            elif "data" in output:
                text.append(output.data.get("text/plain", ""))
                images += "image/png" in output.data
    return "\n".join(text), images


@pytest.mark.timeout(300)
def test_the_tutorial_notebook_runs_cell_by_cell_in_a_fresh_kernel():
    nb = execute()
    text, images = outputs(nb)
    assert "paused: True" in text
    assert "mission finished: True" in text
    assert "it cannot be started again: build a new one" in text
    assert images == 1


def test_the_saved_notebook_was_executed_and_has_no_errors():
    """The notebook in the repository shows its outputs (readers see them on GitHub)."""
    nb = nbformat.read(NOTEBOOK, as_version=4)
    code = [cell for cell in nb.cells if cell.cell_type == "code"]
    assert code and all(cell.get("execution_count") for cell in code)
    assert not any(output.output_type == "error" for cell in code
                   for output in cell.get("outputs", ()))
    assert outputs(nb)[1] == 1


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/test_tutorial_notebook.py --write")
    nbformat.write(execute(), NOTEBOOK)
    print(f"executed and saved {NOTEBOOK.relative_to(ROOT)}")
