"""Every bench whose docstring gives a ``python -m bench...`` command runs when so called: it has
the ``if __name__ == "__main__"`` entry point (``sight_match`` once had none, and its documented
command did nothing)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench"


def test_every_documented_bench_command_has_an_entry_point() -> None:
    documented = 0
    missing = []
    for path in sorted(BENCH.rglob("*.py")):
        tree = ast.parse(path.read_text())
        doc = ast.get_docstring(tree) or ""
        module = ".".join(path.relative_to(BENCH.parent).with_suffix("").parts)
        if not re.search(rf"python -m {re.escape(module)}\b", doc):
            continue
        documented += 1
        guarded = any(isinstance(node, ast.If) and "__main__" in ast.unparse(node.test) for node in tree.body)
        if not guarded:
            missing.append(module)
    assert documented > 20
    assert not missing, missing
