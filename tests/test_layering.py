"""The import rules that keep the layers apart (STYLE.md, 'Layout and layering')."""

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("path", modules("idl"), ids=lambda p: p.name)
def test_idl_imports_only_the_standard_library_numpy_and_pydantic(path):
    allowed = set(sys.stdlib_module_names) | {"numpy", "pydantic", "pydantic_core", "idl",
                                               "typing_extensions"}
    for name in imports(path):
        assert name.split(".")[0] in allowed, f"{path.name} imports {name}"


@pytest.mark.parametrize("path", modules("afa"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_framework_never_imports_components(path):
    assert not any(n.split(".")[0] == "components" for n in imports(path)), path


@pytest.mark.parametrize("path", modules("afa") + modules("components") + modules("idl"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_runtime_code_never_imports_the_test_helpers(path):
    if path == ROOT / "afa" / "testing.py":
        return
    assert "afa.testing" not in imports(path), path


@pytest.mark.parametrize("path", modules("afa") + modules("components"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_only_the_serial_transport_imports_pyserial(path):
    if path == ROOT / "afa" / "transport.py":
        return
    assert not any(n.split(".")[0] in ("serial", "serial_asyncio") for n in imports(path)), path


@pytest.mark.parametrize("path", modules("afa") + modules("components"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_components_take_time_from_the_injected_clock(path):
    if path.name in ("clock.py", "cli.py", "diagnostics.py"):
        return  # the clocks themselves; the CLI's wall timing; processing-time statistics
    if path == ROOT / "afa" / "meter.py":  # the cost of loop steps, for diagnostics (afa top)
        return
    if path.parent == ROOT / "afa" / "tools":  # command-line tools: outside any System
        return
    text = path.read_text()
    assert "time" not in {n.split(".")[0] for n in imports(path)}, f"{path} imports time"
    assert "asyncio.sleep(" not in text.replace("asyncio.sleep(0)", ""), f"{path} sleeps"


@pytest.mark.parametrize("path", modules("afa") + modules("components") + modules("idl"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_tasks_are_created_only_by_the_module_that_owns_them(path):
    """Every task belongs to a task group (afa.tasks): no bare create_task,
    ensure_future or asyncio.TaskGroup elsewhere."""
    if path == ROOT / "afa" / "tasks.py":
        return
    text = path.read_text()
    for call in ("create_task(", "ensure_future(", "asyncio.TaskGroup("):
        assert call not in text, f"{path} calls {call}"
