import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from robocal.errors import InputError, NonFiniteError, NotEnoughDataError, RobocalError, ShapeError
from robocal.validation import check_array, check_points, check_positive, check_rotation_matrix, check_transform


def test_shape_messages_show_expected_and_got():
    with pytest.raises(ShapeError, match=r"points must have shape \(N, 3\), got \(4, 2\)"):
        check_points(np.zeros((4, 2)))
    with pytest.raises(ShapeError, match=r"R must have shape \(\.\.\., 3, 3\)|R must have shape \(3, 3\)"):
        check_rotation_matrix(np.zeros((2, 2)))
    with pytest.raises(NotEnoughDataError, match="at least 3 points, got 2"):
        check_points(np.zeros((2, 3)), min_count=3)


def test_rotation_and_transform_checks():
    check_rotation_matrix(np.eye(3))
    with pytest.raises(InputError, match="rotation matrix"):
        check_rotation_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(InputError, match="rotation matrix"):
        check_rotation_matrix(np.eye(3) * 1.01)
    T = np.eye(4)
    T[3, 0] = 1
    with pytest.raises(InputError, match="last row"):
        check_transform(T)


def test_nonfinite_and_nonnumeric():
    with pytest.raises(NonFiniteError, match=r"x contains NaN or infinity \(first at index \(1,\)\)"):
        check_array([1.0, np.nan], "x")
    with pytest.raises(InputError, match=r"x must contain numbers only, got a string \('a'\) at index \(0,\)"):
        check_array(["a"], "x")
    with pytest.raises(InputError, match="must be > 0"):
        check_positive([1.0, 0.0], "h")


@settings(max_examples=80, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 5), st.integers(0, 5)), elements=st.floats(allow_nan=True, allow_infinity=True)))
def test_fuzz_check_points_never_passes_bad_data(a):
    try:
        out = check_points(a)
    except RobocalError:
        return
    assert out.shape[1] == 3 and np.all(np.isfinite(out))


@pytest.mark.parametrize(
    "got, shape, message",
    [
        ((3, 3), (..., 2), "x must have shape (..., 2), got (3, 3)"),
        ((4, 3, 3), (1,), "x must have shape (..., 1), got (4, 3, 3)"),
        ((2,), (3,), "x must have shape (3,), got (2,)"),
        ((5, 4, 4), (4, 3), "x must have shape (..., 4, 3), got (5, 4, 4)"),
    ],
)
def test_shape_messages_read_as_expected_vs_got(got, shape, message):
    with pytest.raises(ShapeError) as info:
        check_array(np.zeros(got), "x", shape=shape)
    assert str(info.value) == message


def test_leading_ellipsis_means_any_batch():
    assert check_array(np.zeros((7, 5, 2)), "x", shape=(..., 2)).shape == (7, 5, 2)


@pytest.mark.parametrize(
    "x, message",
    [
        (True, "x must be a number, got a boolean (true)"),
        (np.False_, "x must be a number, got a boolean (false)"),
        ([1.0, True], "x must contain numbers only, got a boolean (true) at index (1,)"),
        ([[1.0, 2.0], (3.0, np.False_)], "x must contain numbers only, got a boolean (false) at index (1, 1)"),
    ],
)
def test_booleans_are_not_numbers(x, message):
    # A YAML 'true' must not become 1.0.
    with pytest.raises(InputError) as info:
        check_array(x, "x")
    assert str(info.value) == message
    with pytest.raises(InputError, match="boolean"):
        check_positive(x, "x")


@pytest.mark.parametrize(
    "x, message",
    [
        ("2.9", "x must be a number, got a string ('2.9')"),
        (np.str_("1e3"), "x must be a number, got a string ('1e3')"),
        ([1.0, "2"], "x must contain numbers only, got a string ('2') at index (1,)"),
        ([[1.0, 2.0], (3.0, b"4")], "x must contain numbers only, got a string ('4') at index (1, 1)"),
        (np.array(["1.0", "2.0"]), "x must be numeric, got an array of strings (dtype <U3)"),
    ],
)
def test_strings_are_not_numbers(x, message):
    # A quoted "2.9" from a file must not become 2.9 by numpy's string parsing.
    with pytest.raises(InputError) as info:
        check_array(x, "x")
    assert str(info.value) == message
    assert check_array(x, "x", dtype=object) is not None  # a non-numeric target dtype is not refused


def test_boolean_arrays_and_numbers_still_convert():
    # an ndarray of bools is an explicit mask: converted as numpy does
    np.testing.assert_array_equal(check_array(np.array([True, False]), "mask"), [1.0, 0.0])
    np.testing.assert_array_equal(check_array([1, 2.5, np.int64(3)], "x"), [1.0, 2.5, 3.0])
    assert check_array(True, "flag", dtype=bool) == np.True_  # a boolean target dtype is not refused


def test_unconvertible_input_is_an_input_error():
    with pytest.raises(InputError, match=r"x must be numeric, got int \(int too large"):
        check_array(10**400, "x")
    with pytest.raises(InputError, match=r"x must be numeric, got list"):
        check_array([1, 10**400], "x")
    loop = [1.0]
    loop.append(loop)  # what a YAML alias like '&a [1, *a]' gives
    with pytest.raises(InputError, match="must be numeric"):
        check_array(loop, "x")


def test_boolean_search_walks_shared_lists_once():
    from robocal.validation import _first_leaf

    shared = [1.0]
    for _ in range(60):  # YAML aliases can share lists: 2**60 leaves if walked naively
        shared = [shared, shared]
    assert _first_leaf(shared, lambda v: isinstance(v, bool)) is None
    assert _first_leaf([[1.0], [2.0, [False]]], lambda v: isinstance(v, bool)) == (1, 1, 0)


@pytest.mark.parametrize(
    "x, where",
    [
        ([[1.0, 2.0], [3.0]], "row 0 has 2 entries, row 1 has 1 entry"),
        ([[1.0, 2.0], 3.0], "row 0 has 2 entries, row 1 has a single number"),
        ([[[1, 2], [3, 4]], [[1, 2], [3]]], r"index \(1, 0\) has 2 entries, index \(1, 1\) has 1 entry"),
    ],
)
def test_ragged_lists_name_the_first_short_row(x, where):
    with pytest.raises(InputError, match=f"v has rows of different lengths: {where}"):
        check_array(x, "v")
