"""``robocal.io.json_text``: result files' JSON layout (flat lists on a line, a matrix a row a line), same content."""

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal.io import json_text

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=8))
# strings that look like the writer's own row separator must not be cut
tricky = st.sampled_from(["], [", "[", "]", ",\n", '"', "\\", "\u00e9", "\x00"])
values = st.recursive(
    st.one_of(scalars, tricky),
    lambda kids: st.one_of(st.lists(kids, max_size=5), st.dictionaries(st.one_of(st.text(max_size=6), tricky), kids,
                                                                       max_size=5)),
    max_leaves=40)


@settings(max_examples=300, deadline=None)
@given(values)
def test_the_text_loads_back_to_what_json_dumps_writes(obj):
    text = json_text(obj)
    assert text.endswith("\n")
    assert json.loads(text) == json.loads(json.dumps(obj))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(), min_size=1, max_size=4),
                min_size=1, max_size=6))
def test_a_matrix_is_one_row_a_line_with_every_digit(rows):
    text = json_text({"m": rows})
    lines = text.splitlines()
    assert len(lines) == len(rows) + 4  # {, "m": [, the rows, ], }
    assert json.loads(text)["m"] == rows  # repr's shortest round-trip digits: equal, not close


def test_layout():
    text = json_text({"a": [1, 2.5, None, "x"], "b": {}, "c": [], "d": [[1, 0], [0, 1]],
                      "e": [{"k": 1}, [1, [2]]], 3: True})
    assert text == (
        '{\n  "a": [1, 2.5, null, "x"],\n  "b": {},\n  "c": [],\n  "d": [\n    [1, 0],\n    [0, 1]\n  ],\n'
        '  "e": [\n    {\n      "k": 1\n    },\n    [1, [2]]\n  ],\n  "3": true\n}\n'.replace("[1, [2]]", "[\n      1,\n      [2]\n    ]"))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", ["value", "list", "matrix"])
def test_nan_and_infinity_are_refused_as_json_dumps_refuses_them(bad, where):
    obj = {"value": bad, "list": [1.0, bad], "matrix": [[1.0], [bad]]}[where]
    with pytest.raises(ValueError):
        json.dumps(obj, allow_nan=False)
    with pytest.raises(ValueError):
        json_text({"x": obj})


def test_keys_that_are_not_strings_are_written_as_json_dumps_writes_them():
    obj = {1: "a", 2.5: "b", None: "c", False: "d"}
    assert json.loads(json_text(obj)) == json.loads(json.dumps(obj))
    with pytest.raises(TypeError):
        json_text({(1, 2): "tuple key"})
