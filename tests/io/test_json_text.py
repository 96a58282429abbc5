"""JSON read at the door: each refusal is an InputError naming the part, never the parser's own."""

from __future__ import annotations

import pytest

from tumblescan.errors import InputError, MalformedInputError
from tumblescan.io.json_text import parse_json
from tumblescan.io.manifest import first_non_finite, manifest_object


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (b"[" * 100_000 + b"]" * 100_000, "part: the JSON nests too deeply to read"),
        (b'{"a": 1', "part: not valid JSON (Expecting ',' delimiter at line 1 column 8)"),
        (b"\xff\xfe{", "part: not valid JSON"),
    ],
)
def test_what_is_not_json_is_refused_naming_the_part(data: bytes, words: str) -> None:
    with pytest.raises(MalformedInputError) as err:
        parse_json(data, "part", error=MalformedInputError)
    assert words in str(err.value) and err.value.field == "part"


def test_json_round_trips_with_nan_left_for_validation() -> None:
    assert parse_json('{"a": [1, 2.5, "x", null]}', "part") == {"a": [1, 2.5, "x", None]}
    assert first_non_finite(parse_json('{"a": [1, {"b": NaN}]}', "part")) == "a.1.b"


def test_a_manifest_as_deep_as_the_parser_allows_is_walked_without_overflow() -> None:
    depth = 900  # under json's own limit, deep enough to overflow a recursive walk beside it
    doc = '{"schema": "s", "x": ' + '{"a": ' * depth + "NaN" + "}" * depth + "}"
    with pytest.raises(InputError) as err:
        manifest_object(doc, "s")
    assert err.value.field == "x" + ".a" * depth


def test_the_first_non_finite_value_is_the_first_in_document_order() -> None:
    assert first_non_finite({"a": [1.0, float("inf")], "b": float("nan")}) == "a.1"
    assert first_non_finite([{"ok": 1}, {"x": [float("nan")]}]) == "1.x.0"
    assert first_non_finite({"a": [1, 2], "b": "text"}) is None
