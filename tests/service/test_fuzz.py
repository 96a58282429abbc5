"""The API fuzzed from its own OpenAPI schema (schemathesis, a bounded number of examples):
no 5xx, every response as the schema says."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from ..live import serve

pytestmark = pytest.mark.slow
CHECKS = "not_a_server_error,response_schema_conformance,status_code_conformance,content_type_conformance"


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with serve(tmp_path_factory.mktemp("fuzz") / "data", workers=1) as u:
        yield u


def test_schemathesis_finds_no_server_errors(url: str) -> None:
    st = shutil.which("st", path=str(Path(sys.executable).parent))
    if st is None:
        pytest.skip("schemathesis is not installed (pip install schemathesis)")
    cmd = [st, "run", f"{url}/openapi.json", "--checks", CHECKS, "--max-examples", "30"]
    cmd += ["--phases", "examples,coverage,fuzzing", "--seed", "20261121", "--no-color"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-5000:] + proc.stderr[-2000:]
    assert "passed" in proc.stdout
