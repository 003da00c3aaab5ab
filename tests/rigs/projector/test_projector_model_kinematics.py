"""Projector kinematics: seed 000 eqs. (5)-(10), round trips, singular set, reach."""

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal.errors import InputError, NonFiniteError, SingularConfigurationError
from robocal.geometry import matrix_from_angle
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel, UnreachablePointError

SETTINGS = settings(max_examples=60, deadline=None)


def seed_eq5(t1, t2, d1, d2):
    s1, c1, s2, c2 = np.sin(t1), np.cos(t1), np.sin(t2), np.cos(t2)
    z, o = np.zeros_like(s1), np.ones_like(s1)
    rows = [[s1 * c2, c1, s1 * s2, d2 * s1 * s2], [c1 * c2, -s1, c1 * s2, d2 * c1 * s2],
            [s2, z, -c2, -d2 * c2 - d1], [z, z, z, o]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


@pytest.fixture
def model():
    return ProjectorModel(H=2.9, d1=0.12, d2=0.05, tilt_limit=math.radians(80))


def working_range(rng, n, tilt_max=math.radians(80)):
    return np.column_stack([rng.uniform(-math.pi + 1e-9, math.pi, n), rng.uniform(1e-3, tilt_max, n)])


def test_chain_reproduces_eq5_and_spot_eq6(model):
    rng = np.random.default_rng(0)
    th = working_range(rng, 400)
    assert np.abs(model.pose(th) - seed_eq5(th[:, 0], th[:, 1], model.d1, model.d2)).max() < 1e-14
    # eq. (6) closed form == beam/floor intersection of the D-H chain
    f = model.spot(th)
    assert np.abs(f - model.spot_from_chain(th)).max() < 1e-12
    assert np.all(f[:, 2] == -model.H)
    h = model.H - model.d1
    expect = np.column_stack([h * np.sin(th[:, 0]) * np.tan(th[:, 1]), h * np.cos(th[:, 0]) * np.tan(th[:, 1])])
    assert np.abs(f[:, :2] - expect).max() < 1e-12
    # eq. (7): the spot is g along z_E from the laser origin
    T = model.pose(th)
    g = model.beam_range(th)
    assert np.abs(T[:, :3, 3] + g[:, None] * T[:, :3, 2] - f).max() < 1e-12


def test_offsets_enter_the_chain_theta_column():
    m = ProjectorModel(H=3.0, d1=0.1, offsets=(0.02, -0.01))
    th = np.array([[0.3, 0.5], [-2.0, 1.0]])
    ideal = ProjectorModel(H=3.0, d1=0.1)
    assert np.allclose(m.spot(th), ideal.spot(th + [0.02, -0.01]), atol=1e-14)
    assert np.allclose(m.spot_from_chain(th), m.spot(th), atol=1e-12)


@SETTINGS
@given(t1=st.floats(-math.pi + 1e-6, math.pi), t2=st.floats(1e-4, math.radians(80)),
       o1=st.floats(-0.2, 0.2), o2=st.floats(-0.05, 0.05))
def test_ik_round_trip(t1, t2, o1, o2):
    m = ProjectorModel(H=2.9, d1=0.12, offsets=(o1, o2), tilt_limit=math.radians(85))
    th = np.array([t1, t2 - o2])
    back = m.ik(m.spot(th))
    d = back - th
    d[0] = (d[0] + math.pi) % (2 * math.pi) - math.pi  # pan compared modulo 2 pi
    assert np.abs(d).max() < 1e-12


def test_ik_round_trip_vectorised_batch_shapes(model):
    rng = np.random.default_rng(1)
    th = working_range(rng, 600).reshape(4, 150, 2)
    back = model.ik(model.spot(th))
    assert back.shape == (4, 150, 2)
    assert np.abs(back - th).max() < 1e-12
    # world frame round trip through eq. (1)
    mw = model.with_(R_0_W=matrix_from_angle("z", 0.04), t_0_W=np.array([2.4, -0.9, -2.9]))
    pw = mw.spot_world(th)
    assert np.abs(pw[..., 2]).max() < 1e-12
    assert np.abs(mw.ik_world(pw[..., :2]) - th).max() < 1e-12


def test_jacobian_eq9_matches_finite_differences_and_inverse(model):
    rng = np.random.default_rng(2)
    th = working_range(rng, 50)
    J = model.spot_jacobian(th)
    eps = 1e-6
    for j in range(2):
        d = np.zeros(2)
        d[j] = eps
        fd = (model.spot(th + d) - model.spot(th - d)) / (2 * eps)
        assert np.abs(fd - J[..., j]).max() < 1e-6
    v = rng.normal(size=(50, 2))
    rates = model.joint_rates(th, v)
    assert np.abs(np.einsum("nij,nj->ni", J[:, :2, :], rates) - v).max() < 1e-10
    # eq. (10): rate of the beam range
    td = rng.normal(size=(50, 2))
    fd = (model.beam_range(th + eps * td) - model.beam_range(th - eps * td)) / (2 * eps)
    assert np.abs(fd - model.beam_range_rate(th, td)).max() < 1e-6


def test_nadir_singularity_raises_or_warns_never_nan(model):
    with pytest.raises(SingularConfigurationError, match="nadir"):
        model.joint_rates([0.3, 0.0], [0.1, 0.0])
    with pytest.warns(NearSingularityWarning, match="nadir"):
        th = model.ik([[0.0, 0.0, -model.H], [0.5, 0.5, -model.H]], theta1_at_nadir=0.7)
    assert np.all(np.isfinite(th)) and th[0, 0] == pytest.approx(0.7) and th[0, 1] == 0.0
    with pytest.raises(SingularConfigurationError, match="nadir"):
        model.ik([0.0, 0.0], on_nadir="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.ik([0.0, 0.0], on_nadir="ignore")
    # the Jacobian itself exists at the nadir (rank 1, finite)
    J = model.spot_jacobian([0.2, 0.0])
    assert np.all(np.isfinite(J)) and np.linalg.matrix_rank(J) == 1


def test_horizon_singularity_raises(model):
    for fn in (model.spot, model.beam_range, model.spot_jacobian, model.spot_from_chain):
        with pytest.raises(SingularConfigurationError, match="horizon"):
            fn([[0.1, 0.2], [0.0, math.pi / 2]])
    with pytest.raises(SingularConfigurationError, match="index \\(1,\\)"):
        model.spot([[0.1, 0.2], [0.0, 2.0]])
    assert model.singularity_margin([0.0, 1.2]) == pytest.approx(math.pi / 2 - 1.2)


def test_reachable_floor_and_bad_points(model):
    r = model.floor_radius
    assert r == pytest.approx((model.H - model.d1) * math.tan(math.radians(80)))
    pts = np.array([[0.5 * r, 0.0], [0.0, 1.01 * r]])
    assert model.reachable(pts).tolist() == [True, False]
    with pytest.raises(UnreachablePointError, match=r"point\(s\) \[1\]"):
        model.ik(pts)
    assert model.ik(pts, check_reach=False).shape == (2, 2)
    with pytest.raises(InputError, match="floor is z_0"):
        model.ik([[0.1, 0.2, -290.0]])  # centimetres where metres were expected
    with pytest.raises(NonFiniteError):
        model.spot([np.nan, 0.1])
    with pytest.raises(InputError, match="shape"):
        model.spot([0.1, 0.2, 0.3])
    with pytest.raises(InputError, match="H - d1"):
        ProjectorModel(H=1.0, d1=1.5)
    with pytest.raises(InputError, match="tilt_limit"):
        ProjectorModel(H=1.0, tilt_limit=math.pi / 2)
