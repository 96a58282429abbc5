"""What every command shares (cli/common.py): bad input is exit code 2 and one line."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from tumblescan.cli import app

runner = CliRunner()


def test_json_nested_too_deeply_is_one_line_for_every_estimate(tmp_path: Path) -> None:
    # The readers of each kind call json.loads; the shared wrapper catches what they let through.
    deep = tmp_path / "deep.json"
    deep.write_text('{"observations": ' + "[" * 100_000 + "]" * 100_000 + "}")
    for group in ("linescan-motion", "marker-pose-graph", "bearings"):
        r = runner.invoke(app, [group, "estimate", str(deep)])
        assert r.exit_code == 2, r.output
        assert r.output.count("\n") == 1 and "nests too deeply" in r.output, r.output
