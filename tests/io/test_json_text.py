"""``robocal.io.json_text``: result files' JSON layout (flat lists on a line, a matrix a row a line), same content."""

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

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


def _to_jsonable_reference(obj):
    """The element-by-element conversion ``to_jsonable`` did before its fast paths (the specification)."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _to_jsonable_reference(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_jsonable_reference(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _to_jsonable_reference(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(float(obj)) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def _same(a, b):
    """Equal and of the same JSON types all the way down (True == 1 and 1.0 == 1 in Python)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(_same, a, b))
    return type(a) is type(b) and a == b


floats_any = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(floats_any, st.integers(-2**70, 2**70), st.booleans(), st.none()), max_size=8))
def test_to_jsonable_of_lists_equals_the_element_by_element_conversion(values):
    from robocal.io import to_jsonable

    assert _same(to_jsonable(values), _to_jsonable_reference(values))
    assert _same(to_jsonable([v for v in values if type(v) is float]),
                 _to_jsonable_reference([v for v in values if type(v) is float]))


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(st.sampled_from(["float64", "float32", "int64", "uint8", "bool"]),
                  hnp.array_shapes(min_dims=0, max_dims=2, min_side=0, max_side=4)))
def test_to_jsonable_of_arrays_equals_the_element_by_element_conversion(arr):
    from robocal.io import to_jsonable

    assert _same(to_jsonable({"a": arr}), _to_jsonable_reference({"a": arr}))


def test_to_jsonable_non_finite_array_elements_become_null():
    import numpy as np

    from robocal.io import to_jsonable

    assert to_jsonable(np.array([[1.0, np.nan], [np.inf, -2.0]])) == [[1.0, None], [None, -2.0]]
    assert to_jsonable(np.array(np.nan)) is None


def test_to_jsonable_a_finite_list_whose_sum_overflows_keeps_its_numbers():
    from robocal.io import to_jsonable

    assert to_jsonable([1e308, 1e308, math.inf, 2]) == [1e308, 1e308, None, 2]
    assert to_jsonable([1e308, 1e308]) == [1e308, 1e308]
    assert to_jsonable([10**400, 1.5]) == [10**400, 1.5]  # sum() overflows converting the int
