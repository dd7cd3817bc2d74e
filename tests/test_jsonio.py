"""aicalib_tf.jsonio: strict JSON out (NaN -> null), capped and depth-limited JSON in."""

from __future__ import annotations

import doctest
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aicalib_tf import jsonio


def test_doctests():
    assert doctest.testmod(jsonio).failed == 0


def test_jsonable_maps_numpy_and_non_finite_numbers():
    out = jsonio.jsonable({"a": np.float32(1.5), "b": np.array([1.0, np.nan, -np.inf]), 3: (np.int64(2), math.inf)})
    assert out == {"a": 1.5, "b": [1.0, None, None], "3": [2, None]}
    assert json.loads(jsonio.dumps(out), parse_constant=lambda c: pytest.fail(c)) == out


def test_nan_for_null_inverts_jsonable():
    value = {"a": [1.0, float("nan")], "b": {"c": float("nan"), "d": "x"}}
    back = jsonio.nan_for_null(jsonio.loads(jsonio.dumps(value)))
    assert math.isnan(back["a"][1]) and math.isnan(back["b"]["c"]) and back["b"]["d"] == "x" and back["a"][0] == 1.0


def test_dumps_never_writes_nan():
    text = jsonio.dumps({"x": [float("nan"), np.float64("inf")]})
    assert "NaN" not in text and "Infinity" not in text and text.endswith("\n")


@pytest.mark.parametrize("text, message", [
    ("[NaN]", "NaN is not a JSON number"), ("[-Infinity]", "-Infinity is not a JSON number"),
    ("[1e400]", "out of the float range"), ("{", "not valid JSON"), ("[" * 65 + "]" * 65, "nested 65 deep"),
    ("[" * 200_000, "nested 200000 deep"),
])
def test_loads_refuses(text, message):
    with pytest.raises(ValueError, match=f"x.json: .*{message}"):
        jsonio.loads(text, "x.json")


def test_brackets_inside_strings_do_not_count():
    text = json.dumps({"a": "[[[[" * 100, "b": ["\\\"[[[" * 50]})
    assert jsonio.json_depth(text.encode()) == 2
    assert jsonio.loads(text)["a"].startswith("[[[[")
    assert jsonio.json_depth(b'["abc') == 1  # an unclosed string: nothing after it is structure


@settings(max_examples=60, deadline=None)
@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
                    lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=3), kids, max_size=3),
                    max_leaves=20))
def test_any_value_round_trips_strictly(value):
    back = jsonio.loads(jsonio.dumps(value))
    assert back == jsonio.jsonable(value)


def test_read_json_caps_and_names_the_file(tmp_path, monkeypatch):
    path = tmp_path / "a.json"
    path.write_text('{"a": [1, 2]}')
    assert jsonio.read_json(path) == {"a": [1, 2]}
    for data, message in ((b"", "empty file"), (b"{\x00}", "holds NUL bytes"), (b"\xff{}", "not UTF-8")):
        path.write_bytes(data)
        with pytest.raises(ValueError, match=f"a.json: {message}"):
            jsonio.read_json(path)
    path.write_text("[" + "1, " * 10 + "1]")
    monkeypatch.setattr(jsonio, "MAX_FILE_BYTES", 16)
    with pytest.raises(ValueError, match="a.json: file is larger than 16 bytes"):
        jsonio.read_json(path)
