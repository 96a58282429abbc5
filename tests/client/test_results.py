"""Each kind's result model in the client mirrors the service's: same fields, same required
ones, all the way down (the client is installed without the service, so it has its own copy)."""

from __future__ import annotations

from typing import Any

import pytest

from tumblescan.jobs.registry import kinds
from tumblescan_client import RESULT_MODELS, UnknownResult, result_model


def _resolve(schema: dict[str, Any], root: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in schema:
        schema = root["$defs"][schema["$ref"].rsplit("/", 1)[-1]]
    for key in ("anyOf", "oneOf"):  # Optional[X]: compare X
        options = [s for s in schema.get(key, []) if s.get("type") != "null"]
        if len(options) == 1:
            return _resolve(options[0], root)
    return schema


def _shape(schema: dict[str, Any], root: dict[str, Any], path: str = "") -> dict[str, Any]:
    """Field names and required flags, recursively, for objects; item shape for arrays."""
    schema = _resolve(schema, root)
    if "properties" in schema:
        required = set(schema.get("required", []))
        return {
            f"{path}.{name}" + ("" if name in required else "?"): _shape(sub, root, f"{path}.{name}")
            for name, sub in schema["properties"].items()
        }
    if schema.get("type") == "array" and isinstance(schema.get("items"), dict):
        return {"[]": _shape(schema["items"], root, path + "[]")}
    return {}


@pytest.mark.parametrize("name", sorted(kinds()))
def test_client_result_model_matches_the_service_schema(name: str) -> None:
    assert name in RESULT_MODELS, f"the client has no result model for kind {name!r}"
    service = kinds()[name].result_model.model_json_schema()
    client = RESULT_MODELS[name].model_json_schema()
    assert _shape(client, client) == _shape(service, service)


def test_an_unknown_kind_gets_a_result_that_keeps_every_field() -> None:
    model = result_model("kind-of-the-future")
    assert model is UnknownResult
    assert model.model_validate({"x": [1, 2], "y": {"z": 3}}).model_dump() == {"x": [1, 2], "y": {"z": 3}}


def test_job_artifacts_read_like_the_dict_of_urls_they_stand_for() -> None:
    from tumblescan_client.models import JobArtifacts

    a = JobArtifacts.model_validate({"cloud": None, "report": "/v1/jobs/j/report", "overlay": "/v1/jobs/j/a/overlay"})
    assert sorted(a.keys()) == ["overlay", "report"]
    assert dict(a.items()) == a.urls() and len(a) == 2
    assert "overlay" in a and "cloud" not in a
    assert a["report"] == "/v1/jobs/j/report" and a.get("cloud") is None and a.get("x", "-") == "-"
    with pytest.raises(KeyError):
        a["cloud"]
