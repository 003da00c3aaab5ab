"""Frames and composition of seed 002: the patent's chain vs the Householder form."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal.camera import MarkerRectangle
from robocal.errors import DegenerateGeometryError, InputError
from robocal.geometry import (
    matrix_from_rotvec,
    reflect_points,
    rotation_angle,
    transform_from,
)
from robocal.rigs.mirror.model import (
    F_X,
    T_M_OM,

    MirrorScene,
    householder_compose,
    mirror_plane,
    patent_compose,
    ri_from_r_points,
    virtual_transform,
)
from robocal.rigs.mirror.scene import PUBLISHED, default_body_points, published_scene


def random_scene(rng):
    """Random robot pose and a mirror in front of the camera (d in 0.5..3 m)."""
    T_c_r = transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(scale=0.5, size=3))
    R_c_m = matrix_from_rotvec(rng.normal(size=3))
    n = R_c_m[:, 2]
    if n[2] < 0:  # keep z_m facing away from the camera
        R_c_m = R_c_m @ np.diag([1.0, -1.0, -1.0])
    t_c_m = R_c_m[:, 2] * rng.uniform(0.5, 3.0) + rng.normal(scale=0.3, size=3) * (1 - np.abs(R_c_m[:, 2]))
    return T_c_r, transform_from(R_c_m, t_c_m)


def test_constants():
    assert np.allclose(T_M_OM[:3, :3], matrix_from_rotvec([0, np.pi, 0]), atol=1e-15)
    assert np.linalg.det(F_X) == -1
    assert np.allclose(ri_from_r_points([[1.0, 2.0, 3.0]]), [[-1.0, 2.0, 3.0]])


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_patent_steps_agree_with_householder(seed):
    rng = np.random.default_rng(seed)
    T_c_r, T_c_m = random_scene(rng)
    n, d = mirror_plane(T_c_m)
    T_c_ri = virtual_transform(T_c_r, n, d)
    steps = patent_compose(T_c_m, T_c_ri)
    T_hh = householder_compose(T_c_m, T_c_ri)
    assert np.allclose(steps.T_c_r, T_c_r, atol=1e-12)
    assert np.allclose(T_hh, T_c_r, atol=1e-12)
    assert np.allclose(steps.T_r_c @ T_c_r, np.eye(4), atol=1e-12)
    # every intermediate is a proper rigid transform
    for k, T in steps.as_dict().items():
        assert np.isclose(np.linalg.det(T[:3, :3]), 1.0), k


def test_literal_equality_in_eq4_is_wrong():
    # The spec paraphrases eq. [4] as (R_omr, T_omr) = (R_mri, T_mri); taken
    # literally it misses the x flips and gives a wrong answer.
    rng = np.random.default_rng(1)
    errs = []
    for _ in range(20):
        T_c_r, T_c_m = random_scene(rng)
        n, d = mirror_plane(T_c_m)
        steps = patent_compose(T_c_m, virtual_transform(T_c_r, n, d), literal_eq4=True)
        errs.append(rotation_angle(steps.T_c_r[:3, :3] @ T_c_r[:3, :3].T))
    assert min(errs) > 1e-3


def test_ri_points_are_the_virtual_points():
    # Body points in ri, mapped by T_c_ri, land on the mirror images of the real points.
    rng = np.random.default_rng(2)
    T_c_r, T_c_m = random_scene(rng)
    n, d = mirror_plane(T_c_m)
    p_r = rng.normal(size=(10, 3))
    T_c_ri = virtual_transform(T_c_r, n, d)
    via_ri = (T_c_ri[:3, :3] @ ri_from_r_points(p_r).T).T + T_c_ri[:3, 3]
    p_c = (T_c_r[:3, :3] @ p_r.T).T + T_c_r[:3, 3]
    assert np.allclose(via_ri, reflect_points(p_c, n, d), atol=1e-12)
    assert np.isclose(np.linalg.det(T_c_ri[:3, :3]), 1.0)


def test_batched_composition():
    rng = np.random.default_rng(3)
    pairs = [random_scene(rng) for _ in range(5)]
    T_c_r = np.stack([p[0] for p in pairs])
    T_c_m = np.stack([p[1] for p in pairs])
    n, d = mirror_plane(T_c_m)
    T_c_ri = virtual_transform(T_c_r, n, d)
    assert np.allclose(patent_compose(T_c_m, T_c_ri).T_c_r, T_c_r, atol=1e-12)
    assert np.allclose(householder_compose(T_c_m, T_c_ri), T_c_r, atol=1e-12)


def test_published_scene_reproduces_published_translations():
    s = published_scene()
    assert np.allclose(s.T_c_m[0][:3, 3] * 1e3, PUBLISHED["T_cm_mm"], atol=1e-9)
    assert np.allclose(s.T_c_ri()[0][:3, 3] * 1e3, PUBLISHED["T_cri_mm"], atol=1e-6)
    assert np.allclose(s.T_r_c[:3, 3] * 1e3, PUBLISHED["T_rc_mm"], atol=1e-9)
    # and the chain run on the scene's T_c_m, T_c_ri gives back T_rc
    steps = patent_compose(s.T_c_m[0], s.T_c_ri()[0])
    assert np.allclose(steps.T_r_c[:3, 3] * 1e3, PUBLISHED["T_rc_mm"], atol=1e-6)
    assert (s.rectangle.width, s.rectangle.height) == (0.366, 0.256)
    # virtual points behind the mirror, real ones in front
    n, d = s.planes()
    assert np.all(s.virtual_points_c()[0] @ n[0] > d[0])
    assert np.all(s.body_points_c() @ n[0] < d[0])


def test_scene_rejects_camera_behind_mirror_and_points_behind_mirror():
    s = published_scene()
    flipped = s.T_c_m[0] @ np.diag([1.0, -1.0, -1.0, 1.0])
    with pytest.raises(DegenerateGeometryError, match="behind the mirror"):
        MirrorScene(s.T_c_r, flipped, default_body_points())
    far = default_body_points() + np.array([5.0, 0, 0])
    with pytest.raises(InputError, match="behind the mirror plane"):
        MirrorScene(s.T_c_r, s.T_c_m, far)


def test_rectangle_validation():
    with pytest.raises(InputError):
        MarkerRectangle(-0.1, 0.2)
    pts = MarkerRectangle(0.3, 0.2).object_points()
    assert np.allclose(pts[2], [0.3, 0.2, 0.0])
