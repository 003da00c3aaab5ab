"""Property tests of the rotation helpers (robocal.geometry._so3).

Samples include near-identity (angles down to 1e-9 rad) and near-half-turn
(pi - 1e-9 rad) rotations, where conversion formulas are usually fragile, and
arbitrary batch shapes. Quaternions are compared up to sign (q and -q are the
same rotation).
"""

import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

from robocal.errors import DegenerateGeometryError, NonFiniteError, ShapeError
from robocal.geometry import (
    matrix_from_angle,
    compose_gibbs,
    euler_from_matrix,
    gibbs_from_matrix,
    matrix_from_euler,
    matrix_from_gibbs,
    matrix_from_quaternion,
    matrix_from_rotvec,
    project_to_rotation,
    quaternion_from_matrix,
    rotation_angle,
    rotation_distance,
    rotvec_from_matrix,
    skew,
    small_rotation_update,
    unskew,
)

SETTINGS = settings(max_examples=60, deadline=None)

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
axes = arrays(np.float64, 3, elements=finite).filter(lambda v: np.linalg.norm(v) > 0.1).map(
    lambda v: v / np.linalg.norm(v)
)
# Generic angles plus the fragile ends of [0, pi].
angles = st.one_of(
    st.floats(0.0, np.pi, allow_nan=False),
    st.floats(1e-9, 1e-4),
    st.floats(np.pi - 1e-4, np.pi - 1e-9),
)
batch_shapes = array_shapes(min_dims=0, max_dims=2, min_side=1, max_side=3)


def random_rotvecs(seed, shape):
    """Rotation vectors of a batch shape mixing generic, near-0 and near-pi angles."""
    rng = np.random.default_rng(seed)
    k = rng.normal(size=shape + (3,))
    k /= np.linalg.norm(k, axis=-1, keepdims=True)
    kind = rng.integers(0, 3, size=shape)
    theta = np.where(
        kind == 0,
        rng.uniform(0, np.pi, size=shape),
        np.where(kind == 1, 10.0 ** rng.uniform(-9, -4, size=shape), np.pi - 10.0 ** rng.uniform(-9, -4, size=shape)),
    )
    return k * theta[..., None]


def is_rotation(R, atol=1e-12):
    RtR = np.swapaxes(R, -1, -2) @ R
    return np.allclose(RtR, np.eye(3), atol=atol) and np.allclose(np.linalg.det(R), 1.0, atol=atol)


@SETTINGS
@given(axes, angles)
def test_rotvec_round_trip(k, theta):
    v = k * theta
    R = matrix_from_rotvec(v)
    assert is_rotation(R)
    assert np.isclose(rotation_angle(R), theta, atol=1e-12)
    back = rotvec_from_matrix(R)
    np.testing.assert_allclose(matrix_from_rotvec(back), R, atol=1e-12)
    if theta < np.pi - 1e-6:  # unique away from the half-turn
        np.testing.assert_allclose(back, v, atol=1e-9)


@SETTINGS
@given(axes, angles)
def test_rodrigues_formula_matches(k, theta):
    # Seed 000 eq. 15: R = cos I + sin [k]x + (1 - cos) k k^T
    R = np.cos(theta) * np.eye(3) + np.sin(theta) * skew(k) + (1 - np.cos(theta)) * np.outer(k, k)
    np.testing.assert_allclose(matrix_from_rotvec(k * theta), R, atol=1e-12)


@SETTINGS
@given(arrays(np.float64, 4, elements=st.floats(-2, 2)).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_quaternion_round_trip_and_sign(q):
    R = matrix_from_quaternion(q)
    assert is_rotation(R)
    np.testing.assert_allclose(matrix_from_quaternion(-q), R, atol=1e-12)  # q and -q: same rotation
    back = quaternion_from_matrix(R)
    assert back[3] >= 0  # canonical scalar-last: w >= 0
    qn = q / np.linalg.norm(q)
    assert min(np.abs(back - qn).max(), np.abs(back + qn).max()) < 1e-9
    # scalar-last: the rotation angle is 2 acos|w|
    assert np.isclose(rotation_angle(R), 2 * np.arccos(min(abs(qn[3]), 1.0)), atol=1e-6)


def test_quaternion_order_is_scalar_last():
    q = np.array([np.sin(0.25), 0.0, 0.0, np.cos(0.25)])  # 0.5 rad about x
    np.testing.assert_allclose(matrix_from_quaternion(q), matrix_from_angle("x", 0.5), atol=1e-15)


@SETTINGS
@given(axes, st.floats(0.0, np.pi - 1e-3))
def test_gibbs_round_trip(k, theta):
    g = np.tan(theta / 2) * k
    R = matrix_from_gibbs(g)
    np.testing.assert_allclose(R, matrix_from_rotvec(k * theta), atol=1e-9)
    np.testing.assert_allclose(gibbs_from_matrix(R), g, rtol=1e-7, atol=1e-9)


@SETTINGS
@given(axes, st.floats(0.0, np.pi - 1e-2), axes, st.floats(0.0, np.pi - 1e-2))
def test_compose_gibbs_is_matrix_product(k1, t1, k2, t2):
    """Seed 000 eq. 19: R(r1 (x) r2) = R(r1) R(r2)."""
    r1, r2 = np.tan(t1 / 2) * k1, np.tan(t2 / 2) * k2
    assume(abs(1 - r1 @ r2) > 1e-3)  # product is not (close to) a half-turn
    r3 = compose_gibbs(r1, r2)
    np.testing.assert_allclose(matrix_from_gibbs(r3), matrix_from_gibbs(r1) @ matrix_from_gibbs(r2), atol=1e-8)


def test_gibbs_half_turn_raises():
    with pytest.raises(DegenerateGeometryError, match="pi"):
        gibbs_from_matrix(matrix_from_angle("x", np.pi))
    r = np.array([1.0, 0.0, 0.0])  # 90 deg about x twice = half-turn
    with pytest.raises(DegenerateGeometryError, match="half-turn"):
        compose_gibbs(r, r)


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.sampled_from(["xyz", "XYZ", "zyx", "ZYX", "zxz", "ZYZ"]))
def test_euler_round_trip(seed, seq):
    R = matrix_from_rotvec(random_rotvecs(seed, (5,)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # SciPy's gimbal-lock notice; matrices still agree
        e = euler_from_matrix(seq, R)
        e_deg = euler_from_matrix(seq, R, degrees=True)
    # Within ~1e-7 rad of gimbal lock SciPy sets the third angle to 0, so the
    # round trip is exact only to that level there (1e-9 elsewhere).
    np.testing.assert_allclose(matrix_from_euler(seq, e), R, atol=1e-6)
    np.testing.assert_allclose(matrix_from_euler(seq, e_deg, degrees=True), R, atol=1e-6)


def test_ros_rpy_is_extrinsic_xyz():
    r, p, y = 0.1, -0.4, 2.0
    np.testing.assert_allclose(matrix_from_euler("xyz", [r, p, y]), matrix_from_angle("z", y) @ matrix_from_angle("y", p) @ matrix_from_angle("x", r), atol=1e-15)


@SETTINGS
@given(st.integers(0, 2**32 - 1), batch_shapes)
def test_batch_shapes_preserved(seed, shape):
    v = random_rotvecs(seed, shape)
    R = matrix_from_rotvec(v)
    assert R.shape == shape + (3, 3)
    assert rotvec_from_matrix(R).shape == shape + (3,)
    q = quaternion_from_matrix(R)
    assert q.shape == shape + (4,)
    np.testing.assert_allclose(matrix_from_quaternion(q), R, atol=1e-12)
    assert euler_from_matrix("xyz", R).shape == shape + (3,)
    assert rotation_angle(R).shape == shape
    assert skew(v).shape == shape + (3, 3)
    np.testing.assert_allclose(unskew(skew(v)), v)
    # each batch element equals the unbatched call
    flat_v, flat_R = v.reshape(-1, 3), R.reshape(-1, 3, 3)
    for i in range(flat_v.shape[0]):
        np.testing.assert_allclose(matrix_from_rotvec(flat_v[i]), flat_R[i], atol=1e-15)


@SETTINGS
@given(arrays(np.float64, 3, elements=st.floats(-5, 5)), arrays(np.float64, 3, elements=st.floats(-5, 5)))
def test_skew_is_cross_product(v, u):
    np.testing.assert_allclose(skew(v) @ u, np.cross(v, u), atol=1e-12)
    np.testing.assert_allclose(skew(v), -skew(v).T)


@SETTINGS
@given(st.integers(0, 2**32 - 1))
def test_rotation_distance_and_angle(seed):
    v = random_rotvecs(seed, (2,))
    Ra, Rb = matrix_from_rotvec(v)
    d = rotation_distance(Ra, Rb)
    assert np.isclose(d, rotation_distance(Rb, Ra), atol=1e-12)
    assert np.isclose(rotation_distance(Ra, Ra), 0.0, atol=1e-7)
    assert np.allclose(rotation_angle(matrix_from_rotvec(v)), np.linalg.norm(v, axis=-1), atol=1e-9)
    assert 0.0 <= d <= np.pi


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.floats(1e-6, 0.3))
def test_project_to_rotation(seed, noise):
    rng = np.random.default_rng(seed)
    R = matrix_from_rotvec(random_rotvecs(seed, (4,)))
    np.testing.assert_allclose(project_to_rotation(R), R, atol=1e-12)
    P = project_to_rotation(R + noise * rng.normal(size=R.shape))
    assert is_rotation(P, atol=1e-10)
    # a reflection is mapped to a proper rotation, never to itself
    P2 = project_to_rotation(-R)
    assert np.all(np.linalg.det(P2) > 0)


@SETTINGS
@given(st.integers(0, 2**32 - 1))
def test_small_rotation_update(seed):
    v = random_rotvecs(seed, (2,))
    R, W = matrix_from_rotvec(v)
    w = 1e-3 * v[1] / max(np.linalg.norm(v[1]), 1e-12)
    np.testing.assert_allclose(small_rotation_update(R, w), matrix_from_rotvec(w) @ R, atol=1e-15)
    np.testing.assert_allclose(small_rotation_update(R, w, left=False), R @ matrix_from_rotvec(w), atol=1e-15)


@pytest.mark.parametrize(
    "fn, arg",
    [
        (matrix_from_rotvec, [0.1, np.nan, 0.0]),
        (rotvec_from_matrix, np.where(np.eye(3) > 0, np.inf, 0.0)),
        (matrix_from_quaternion, [0.0, 0.0, np.nan, 1.0]),
        (quaternion_from_matrix, np.full((3, 3), np.nan)),
        (matrix_from_gibbs, [np.nan, 0.0, 0.0]),
        (gibbs_from_matrix, np.full((2, 3, 3), np.nan)),
        (lambda a: matrix_from_euler("xyz", a), [0.0, np.nan, 0.0]),
        (lambda a: compose_gibbs(a, [0.0, 0.0, 0.1]), [np.inf, 0.0, 0.0]),
    ],
)
def test_non_finite_input_raises(fn, arg):
    with pytest.raises(NonFiniteError, match="NaN or infinity"):
        fn(arg)


@SETTINGS
@given(st.integers(0, 2**32 - 1), batch_shapes)
def test_nan_anywhere_in_a_batch_raises(seed, shape):
    v = random_rotvecs(seed, shape)
    rng = np.random.default_rng(seed)
    v.reshape(-1)[rng.integers(v.size)] = np.nan
    with pytest.raises(NonFiniteError):
        matrix_from_rotvec(v)


@pytest.mark.parametrize(
    "fn, bad",
    [
        (matrix_from_rotvec, np.zeros(4)),
        (matrix_from_rotvec, np.zeros((3, 2))),
        (rotvec_from_matrix, np.zeros((3, 4))),
        (matrix_from_quaternion, np.zeros(3)),
        (matrix_from_gibbs, np.zeros((2, 2))),
    ],
)
def test_wrong_shapes_raise(fn, bad):
    with pytest.raises(ShapeError, match="must have shape"):
        fn(bad)


def test_zero_quaternion_raises():
    with pytest.raises(DegenerateGeometryError, match="zero norm"):
        matrix_from_quaternion([0.0, 0.0, 0.0, 0.0])


def test_wrap_angle_range_and_representative():
    from robocal.geometry import wrap_angle

    a = np.array([-np.pi, np.pi, 3 * np.pi, 4.0, -7.0, 0.0])
    w = wrap_angle(a)
    assert np.all((w > -np.pi) & (w <= np.pi)) and w[0] == w[1] == w[2] == np.pi
    np.testing.assert_allclose(np.exp(1j * w), np.exp(1j * a), atol=1e-12)
    ref = np.radians(270.0)
    assert np.isclose(ref + wrap_angle(np.radians(-88.7) - ref), np.radians(271.3))  # near the reference


def test_so3_left_jacobian_is_the_derivative_of_exp_under_left_perturbation():
    from robocal.geometry import matrix_from_rotvec, rotvec_from_matrix, so3_left_jacobian

    rng = np.random.default_rng(11)
    w = np.vstack([rng.normal(size=(4, 3)), [[1e-8, -2e-8, 3e-9]]])
    J = so3_left_jacobian(w)
    assert J.shape == (5, 3, 3)
    h = 1e-7
    for k in range(len(w)):
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            # exp(w + e) exp(w)^-1 = exp(J e): the rotation vector of the left increment, per unit step
            d = rotvec_from_matrix(matrix_from_rotvec(w[k] + e) @ matrix_from_rotvec(w[k]).T) / h
            np.testing.assert_allclose(J[k][:, j], d, atol=1e-6)
