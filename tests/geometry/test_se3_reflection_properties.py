"""Property tests of rigid transforms (_se3) and plane reflections (_reflection)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes

from robocal.errors import DegenerateGeometryError, NonFiniteError, ShapeError
from robocal.geometry import (
    apply_rotation,
    apply_transform,
    compose,
    householder_from_normal,
    invert_transform,
    matrix_from_rotvec,
    pq_from_transform,
    reflect_frame,
    reflect_points,
    reflection_from_plane,
    rotation_angle,
    rotation_from_transform,
    rotvec_translation_from_transform,
    skew,
    transform_from,
    transform_from_pq,
    transform_from_rotvec,
    translation_from_transform,
)

SETTINGS = settings(max_examples=50, deadline=None)
seeds = st.integers(0, 2**32 - 1)
batch_shapes = array_shapes(min_dims=0, max_dims=2, min_side=1, max_side=3)


def random_transforms(seed, shape=()):
    """Transforms with generic, near-identity and near-half-turn rotations."""
    rng = np.random.default_rng(seed)
    k = rng.normal(size=shape + (3,))
    k /= np.linalg.norm(k, axis=-1, keepdims=True)
    kind = rng.integers(0, 3, size=shape)
    theta = np.select(
        [kind == 0, kind == 1],
        [rng.uniform(0, np.pi, size=shape), 10.0 ** rng.uniform(-9, -4, size=shape)],
        np.pi - 10.0 ** rng.uniform(-9, -4, size=shape),
    )
    return transform_from(matrix_from_rotvec(k * theta[..., None]), rng.normal(scale=2.0, size=shape + (3,)))


def random_planes(seed, shape=()):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=shape + (3,))
    return n / np.linalg.norm(n, axis=-1, keepdims=True), rng.normal(size=shape)


@SETTINGS
@given(seeds)
def test_group_axioms(seed):
    A, B, C = random_transforms(seed, (3,))
    I = np.eye(4)
    np.testing.assert_allclose(compose(compose(A, B), C), compose(A, compose(B, C)), atol=1e-12)
    np.testing.assert_allclose(compose(A, I), A)
    np.testing.assert_allclose(compose(I, A), A)
    np.testing.assert_allclose(compose(A, invert_transform(A)), I, atol=1e-12)
    np.testing.assert_allclose(compose(invert_transform(A), A), I, atol=1e-12)
    np.testing.assert_allclose(invert_transform(compose(A, B)), compose(invert_transform(B), invert_transform(A)), atol=1e-12)
    np.testing.assert_allclose(invert_transform(invert_transform(A)), A, atol=1e-12)
    np.testing.assert_allclose(compose(A, B, C), A @ B @ C, atol=1e-12)


@SETTINGS
@given(seeds)
def test_frame_convention_T_a_b_maps_b_points_into_a(seed):
    T_a_b, T_b_c = random_transforms(seed, (2,))
    p_c = np.random.default_rng(seed).normal(size=(5, 3))
    p_b = apply_transform(T_b_c, p_c)
    np.testing.assert_allclose(apply_transform(T_a_b, p_b), apply_transform(compose(T_a_b, T_b_c), p_c), atol=1e-12)
    np.testing.assert_allclose(apply_transform(invert_transform(T_b_c), p_b), p_c, atol=1e-12)
    np.testing.assert_allclose(apply_rotation(rotation_from_transform(T_a_b), p_c) + translation_from_transform(T_a_b), apply_transform(T_a_b, p_c))


@SETTINGS
@given(seeds, batch_shapes)
def test_pq_and_rotvec_round_trips_keep_batch_shape(seed, shape):
    T = random_transforms(seed, shape)
    pq = pq_from_transform(T)
    assert pq.shape == shape + (7,)
    assert np.all(pq[..., 6] >= 0)
    np.testing.assert_allclose(transform_from_pq(pq), T, atol=1e-12)
    np.testing.assert_allclose(transform_from_pq(np.concatenate([pq[..., :3], -pq[..., 3:]], -1)), T, atol=1e-12)
    rv, t = rotvec_translation_from_transform(T)
    assert rv.shape == t.shape == shape + (3,)
    np.testing.assert_allclose(transform_from_rotvec(rv, t), T, atol=1e-12)
    assert invert_transform(T).shape == T.shape
    assert compose(T, invert_transform(T)).shape == T.shape
    assert apply_transform(T, np.zeros(3)).shape == shape + (3,)


def test_transform_from_broadcasts():
    T = transform_from(np.eye(3), np.zeros((4, 3)))
    assert T.shape == (4, 4, 4)
    assert np.all(T[:, 3, 3] == 1)


@SETTINGS
@given(seeds, batch_shapes)
def test_householder_is_an_involutive_reflection(seed, shape):
    n, _ = random_planes(seed, shape)
    H = householder_from_normal(3.7 * n)  # normalised inside
    assert H.shape == shape + (3, 3)
    np.testing.assert_allclose(np.linalg.det(H), -1.0, atol=1e-12)
    np.testing.assert_allclose(H @ H, np.broadcast_to(np.eye(3), H.shape), atol=1e-12)
    np.testing.assert_allclose(H, np.swapaxes(H, -1, -2))
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", H, n), -n, atol=1e-12)


@SETTINGS
@given(seeds)
def test_reflect_points_mirror_in_the_plane(seed):
    (n, d) = random_planes(seed)
    p = np.random.default_rng(seed + 1).normal(size=(6, 3))
    q = reflect_points(p, n, d)
    mid = 0.5 * (p + q)
    np.testing.assert_allclose(mid @ n, d, atol=1e-12)  # midpoints on the plane
    np.testing.assert_allclose(np.cross(q - p, n), 0.0, atol=1e-12)  # displacement along the normal
    np.testing.assert_allclose(reflect_points(q, n, d), p, atol=1e-12)
    np.testing.assert_allclose(apply_transform(reflection_from_plane(n, d), p), q, atol=1e-12)
    M = reflection_from_plane(n, d)
    np.testing.assert_allclose(M @ M, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(M[:3, :3]), -1.0)


@SETTINGS
@given(seeds, st.integers(0, 2))
def test_reflect_frame_is_right_handed_and_involutive(seed, axis):
    T = random_transforms(seed)
    n, d = random_planes(seed + 7)
    M = reflect_frame(T, n, d, flip_axis=axis)
    R = M[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)  # right-handed
    np.testing.assert_allclose(M[:3, 3], reflect_points(T[:3, 3], n, d), atol=1e-12)  # origin mirrored
    # the flipped axis is the mirror image of -axis; the others are mirror images
    H = householder_from_normal(n)
    for k in range(3):
        sign = -1.0 if k == axis else 1.0
        np.testing.assert_allclose(R[:, k], sign * H @ T[:3, k], atol=1e-12)
    np.testing.assert_allclose(reflect_frame(M, n, d, flip_axis=axis), T, atol=1e-12)


def test_reflection_errors():
    with pytest.raises(DegenerateGeometryError, match="zero length"):
        householder_from_normal([0.0, 0.0, 0.0])
    with pytest.raises(NonFiniteError):
        householder_from_normal([np.nan, 0.0, 1.0])
    with pytest.raises(NonFiniteError):
        reflect_points([[0.0, np.inf, 0.0]], [0, 0, 1], 0.0)
    with pytest.raises(NonFiniteError):
        transform_from_pq([0, 0, 0, 0, 0, np.nan, 1])
    with pytest.raises(NonFiniteError):
        pq_from_transform(np.full((4, 4), np.nan))


@pytest.mark.parametrize("call, name", [
    (lambda: invert_transform(np.eye(3)), "T must have shape \\(\\.\\.\\., 4, 4\\), got \\(3, 3\\)"),
    (lambda: apply_transform(np.eye(4), np.ones((5, 2))), "points must have shape \\(\\.\\.\\., 3\\)"),
    (lambda: transform_from(np.eye(3), [1.0, 2.0]), "t must have shape"),
    (lambda: compose(np.eye(4), np.eye(3)), "transform 1 must have shape"),
    (lambda: skew([1.0, 2.0]), "v must have shape"),
    (lambda: rotation_angle(np.eye(4)), "R must have shape"),
])
def test_small_helpers_name_a_wrong_shape(call, name):
    # an IndexError or a silent broadcast deep in NumPy otherwise
    with pytest.raises(ShapeError, match=name):
        call()
