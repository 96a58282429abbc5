"""The package's shape: no import circle (function-level imports included), arrows point
inward only (numerical cores import no job, web or CLI code), and the package imports cheaply."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[2] / "service" / "tumblescan"
OUTER = ("tumblescan.jobs", "tumblescan.api", "tumblescan.cli")
HEAVY = ("scipy", "open3d", "cv2", "gtsam", "plotly", "sqlalchemy", "fastapi", "huey", "matplotlib")


def module_name(path: Path) -> str:
    parts = ("tumblescan", *path.relative_to(PKG).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PKG.rglob("*.py")}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """Every tumblescan module ``name`` imports, anywhere in the file."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in known else target)
    return {m for m in found if m in known and m != name}


def graph() -> dict[str, set[str]]:
    mods = modules()
    return {name: imports_of(name, path, set(mods)) for name, path in mods.items()}


def test_no_import_circle() -> None:
    g = graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(g[m]):
            if state.get(n) == 1:
                cycle = stack[stack.index(n) :] + [n]
                pytest.fail("import circle: " + " -> ".join(cycle))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m)


def test_cores_import_no_outer_layer() -> None:
    bad = [
        f"{m} imports {n}"
        for m, deps in graph().items()
        if not m.startswith(OUTER) and m not in ("tumblescan", "tumblescan.__main__")
        for n in deps
        if n.startswith(OUTER)
    ]
    assert not bad, bad


def test_shared_packages_import_no_kind() -> None:
    shared = ("tumblescan.geometry", "tumblescan.numerics", "tumblescan.io", "tumblescan.target", "tumblescan.report")
    kinds = ("tumblescan.linescan", "tumblescan.bearings", "tumblescan.panel_axis", "tumblescan.marker_pose")
    bad = [
        f"{m} imports {n}" for m, deps in graph().items() if m.startswith(shared) for n in deps if n.startswith(kinds)
    ]
    assert not bad, bad


@pytest.mark.parametrize("statement", ["import tumblescan", "import tumblescan.cli"])
def test_import_loads_no_heavy_library(statement: str) -> None:
    code = f"{statement}; import sys; print(' '.join(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"{statement} loaded {out}"
