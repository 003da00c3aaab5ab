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
    with pytest.raises(InputError, match="must be numeric"):
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
