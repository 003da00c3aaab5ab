"""Geometric fits: truth recovered within the noise, predicted standard deviations
checked by Monte Carlo, short-arc unbiasedness against an algebraic (Kasa) foil,
and degenerate input refused with a named error."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, RobocalError
from robocal.geometry import (
    fit_circle_2d,
    fit_circle_3d,
    fit_line,
    fit_plane,
    fit_sphere,
    matrix_from_rotvec,
)

R_TILT = matrix_from_rotvec([0.4, 0.9, -0.3])


def kasa_radius(p):
    """Kasa's algebraic circle fit: least squares on |p|^2 = 2 c.p + k (the foil)."""
    A = np.column_stack([2 * p, np.ones(len(p))])
    sol, *_ = np.linalg.lstsq(A, np.sum(p * p, axis=1), rcond=None)
    return np.sqrt(sol[-1] + sol[:-1] @ sol[:-1])


def arc_points(n, arc, radius, centre, start=np.pi / 3):
    th = start + np.linspace(-arc / 2, arc / 2, n)
    return centre + radius * np.column_stack([np.cos(th), np.sin(th)])


def bias_check(estimates, truth, limit=0.2):
    """(|bias| + 3 SE) / std: the 3-sigma upper limit of the bias in units of the spread."""
    std = estimates.std(ddof=1)
    bias = estimates.mean() - truth
    se = std / np.sqrt(len(estimates))
    return (abs(bias) + 3 * se) / std, (abs(bias) - 3 * se) / std


# ----------------------------------------------------------------------------- line, plane


def test_fit_line_recovers_direction_with_predicted_spread():
    rng = np.random.default_rng(10)
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    base = np.array([0.1, 0.2, -0.3]) + np.outer(np.linspace(-1, 1, 30), d)
    exact = fit_line(base)
    np.testing.assert_allclose(abs(exact.direction @ d), 1.0, atol=1e-14)
    np.testing.assert_allclose(exact.residuals, 0.0, atol=1e-14)
    sigma = 0.01
    fits = [fit_line(base + sigma * rng.normal(size=base.shape)) for _ in range(500)]
    dirs = np.array([f.direction * np.sign(f.direction @ d) for f in fits])
    pred = np.mean([f.direction_cov for f in fits], axis=0)
    np.testing.assert_allclose(np.trace(np.cov(dirs.T)) / np.trace(pred), 1.0, atol=0.15)
    pts = np.array([f.point for f in fits])
    across = pts - np.outer(pts @ d, d)
    pred_point = np.mean([f.point_cov for f in fits], axis=0)
    np.testing.assert_allclose(np.trace(np.cov(across.T)) / np.trace(pred_point), 1.0, atol=0.15)
    assert abs(np.mean([f.rms for f in fits]) / (sigma * np.sqrt(2)) - 1) < 0.05  # 2 orthogonal components
    line2d = fit_line(base[:, :2])
    assert line2d.direction.shape == (2,) and line2d.residuals.shape == (30,)


def test_fit_plane_recovers_plane_and_std():
    rng = np.random.default_rng(11)
    uv = rng.uniform(-1, 1, size=(40, 2))
    n_true = R_TILT[:, 2]
    pts = 2.0 * n_true + uv @ R_TILT[:, :2].T  # plane n.x = 2
    f = fit_plane(pts)
    np.testing.assert_allclose(f.normal * np.sign(f.normal @ n_true), n_true, atol=1e-14)
    assert f.d == pytest.approx(2.0, abs=1e-13) and f.d >= 0
    flipped = fit_plane(-pts)  # normal re-oriented so that d stays >= 0
    assert flipped.d == pytest.approx(2.0) and flipped.normal @ n_true < 0
    sigma = 0.01
    fits = [fit_plane(pts + sigma * rng.normal(size=pts.shape)) for _ in range(500)]
    ds = np.array([g.d for g in fits])
    assert abs(ds.std() / np.mean([g.d_std for g in fits]) - 1) < 0.15
    normals = np.array([g.normal for g in fits])
    assert abs(np.trace(np.cov(normals.T)) / np.trace(np.mean([g.normal_cov for g in fits], 0)) - 1) < 0.15
    assert abs(np.mean([g.rms for g in fits]) / sigma - 1) < 0.05


# ----------------------------------------------------------------------------- circles


def test_circle_2d_unbiased_on_short_arc_where_kasa_fails():
    """Issue 'Foundation' item 2: 30 deg arc, 100 points, sigma = 0.2 % of R.

    Criterion: the 3-sigma upper confidence limit of |radius bias| is below
    0.2 x the radius standard deviation. 2000 trials put the bias estimate's
    standard error at 0.022 std, so the criterion can be met or missed
    significantly. Kasa's algebraic fit, on the very same samples, has a bias
    whose 3-sigma *lower* limit is far above 0.2 std (it shrinks the circle).
    """
    rng = np.random.default_rng(12)
    R, centre = 0.25, np.array([0.1, -0.3])
    clean = arc_points(100, np.radians(30), R, centre)
    sigma = 0.002 * R
    geo, kasa, pred = [], [], []
    for _ in range(2000):
        p = clean + sigma * rng.normal(size=clean.shape)
        f = fit_circle_2d(p)
        geo.append(f.radius)
        pred.append(f.std[2])
        kasa.append(kasa_radius(p))
    geo, kasa = np.array(geo), np.array(kasa)
    upper_geo, _ = bias_check(geo, R)
    _, lower_kasa = bias_check(kasa, R)
    assert upper_geo < 0.2, f"geometric fit: |bias| upper limit {upper_geo:.3f} std"
    assert lower_kasa > 0.2, f"Kasa fit should fail: |bias| lower limit {lower_kasa:.3f} std"
    assert np.mean(kasa) < R  # the known direction of Kasa's bias
    # the reported std is right (SE of an std estimate with 2000 trials ~ 1.6 %)
    assert abs(np.mean(pred) / geo.std() - 1) < 0.08


@pytest.mark.filterwarnings("error")  # no RuntimeWarning from a negative variance either
def test_nearly_degenerate_fits_report_large_std_and_warn():
    # inverting J^T J here gave radius std 6e-6 on a radius the points barely constrain
    rng = np.random.default_rng(0)
    x = np.linspace(0, 1, 50)
    f = fit_circle_2d(np.c_[x, 1e-4 * rng.normal(size=50)])
    assert f.std[2] > 0.1 * f.radius and "weakly_determined" in [w.code for w in f.warnings]
    u = rng.uniform(-0.1, 0.1, (200, 2))
    g = fit_sphere(np.c_[u, 1e-5 * rng.normal(size=200)])
    assert g.radius_std > 0.1 * g.radius and "weakly_determined" in [w.code for w in g.warnings]


def test_circle_2d_std_matches_monte_carlo_on_a_short_arc():
    # 15 deg arc, noise 0.1 % of the radius: the linearised std must still match the spread
    rng = np.random.default_rng(4)
    clean = arc_points(60, np.radians(15), 1.0, np.zeros(2))
    fits = [fit_circle_2d(clean + 1e-3 * rng.normal(size=clean.shape)) for _ in range(300)]
    spread = np.std([f.radius for f in fits])
    predicted = np.sqrt(np.mean([f.std[2] ** 2 for f in fits]))
    assert abs(spread / predicted - 1) < 0.2  # 300 trials: std of the ratio ~4 %, bias of nonlinearity


def test_circle_2d_exact_and_three_points():
    centre, R = np.array([3.0, -1.0]), 2.0
    p = arc_points(7, np.radians(200), R, centre)
    f = fit_circle_2d(p)
    np.testing.assert_allclose(f.centre, centre, atol=1e-12)
    assert f.radius == pytest.approx(R, abs=1e-12)
    np.testing.assert_allclose(f.residuals, 0.0, atol=1e-12)
    three = fit_circle_2d(p[[0, 3, 6]])  # circumcircle, no redundancy -> NaN std
    np.testing.assert_allclose(three.centre, centre, atol=1e-10)
    assert np.all(np.isnan(three.std))
    assert f.warnings == ()


def test_circle_2d_warns_when_radius_weakly_determined():
    rng = np.random.default_rng(13)
    p = arc_points(20, np.radians(10), 1.0, np.zeros(2)) + 0.01 * rng.normal(size=(20, 2))
    f = fit_circle_2d(p)
    assert [w.code for w in f.warnings] == ["weakly_determined"]
    assert f.warnings[0].params == ("radius",)


def test_circle_3d_unbiased_short_arc_and_recovers_truth():
    rng = np.random.default_rng(14)
    R, centre = 0.3, np.array([0.5, -0.2, 1.0])
    uv = arc_points(100, np.radians(30), R, np.zeros(2))
    clean = centre + uv @ R_TILT[:, :2].T
    sigma = 0.002 * R
    fits = [fit_circle_3d(clean + sigma * rng.normal(size=clean.shape)) for _ in range(600)]
    radii = np.array([f.radius for f in fits])
    upper, _ = bias_check(radii, R)
    assert upper < 0.25, f"3D circle: |radius bias| upper limit {upper:.3f} std"
    assert abs(np.mean([f.radius_std for f in fits]) / radii.std() - 1) < 0.15
    cs = np.array([f.centre for f in fits])
    # centre errors whitened by each fit's own covariance: chi-square with 3 dof
    z2 = [e @ np.linalg.solve(f.centre_cov, e) for e, f in zip(cs - centre, fits)]
    assert abs(np.mean(z2) / 3 - 1) < 0.15
    axes = np.array([f.axis for f in fits])
    n_true = R_TILT[:, 2] * np.sign(R_TILT[np.argmax(np.abs(R_TILT[:, 2])), 2])
    np.testing.assert_allclose(axes.mean(0), n_true, atol=5 * axes.std(0).max())
    assert abs(np.trace(np.cov(axes.T)) / np.trace(np.mean([f.axis_cov for f in fits], 0)) - 1) < 0.15
    exact = fit_circle_3d(clean)
    np.testing.assert_allclose(exact.centre, centre, atol=1e-9)
    np.testing.assert_allclose(exact.residuals, 0.0, atol=1e-9)


# ----------------------------------------------------------------------------- sphere


def cap_points(rng, n, half_angle, radius, centre):
    z = rng.uniform(np.cos(half_angle), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z**2)
    return centre + radius * np.column_stack([s * np.cos(phi), s * np.sin(phi), z]) @ R_TILT.T


@pytest.mark.parametrize("known_radius", [False, True])
def test_sphere_recovers_truth_within_noise(known_radius):
    rng = np.random.default_rng(15 + known_radius)
    R, centre, sigma = 0.0125, np.array([0.4, 0.1, -0.2]), 2e-5  # 25 mm ball, 20 um noise
    clean = cap_points(rng, 80, np.radians(60), R, centre)
    fits = [
        fit_sphere(clean + sigma * rng.normal(size=clean.shape), radius=R if known_radius else None)
        for _ in range(400)
    ]
    cs = np.array([f.centre for f in fits])
    z2 = [e @ np.linalg.solve(f.cov[:3, :3], e) for e, f in zip(cs - centre, fits)]
    assert abs(np.mean(z2) / 3 - 1) < 0.15
    for k in range(3):
        upper, _ = bias_check(cs[:, k], centre[k])
        assert upper < 0.3
    if known_radius:
        assert all(f.radius == R and f.radius_std == 0.0 and f.cov.shape == (3, 3) for f in fits)
    else:
        radii = np.array([f.radius for f in fits])
        assert bias_check(radii, R)[0] < 0.3
        assert abs(np.mean([f.radius_std for f in fits]) / radii.std() - 1) < 0.15
    assert abs(np.mean([f.rms for f in fits]) / sigma - 1) < 0.05


def test_known_radius_helps_on_a_small_cap():
    rng = np.random.default_rng(17)
    R, centre, sigma = 0.0125, np.zeros(3), 2e-5
    clean = cap_points(rng, 60, np.radians(20), R, centre)
    free, fixed = [], []
    for _ in range(100):
        p = clean + sigma * rng.normal(size=clean.shape)
        free.append(fit_sphere(p).centre)
        fixed.append(fit_sphere(p, radius=R).centre)
    assert np.mean(np.sum(np.square(fixed), 1)) < 0.2 * np.mean(np.sum(np.square(free), 1))


# ----------------------------------------------------------------------------- degenerate input


def test_degenerate_inputs_raise_named_errors():
    line3 = np.outer(np.linspace(0, 1, 6), [1.0, 2.0, 3.0]) + 0.5
    with pytest.raises(NotEnoughDataError, match="at least 3 points, got 2"):
        fit_circle_2d([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(NotEnoughDataError, match="at least 3 points"):
        fit_circle_3d(line3[:2])
    with pytest.raises(DegenerateGeometryError, match=r"points are collinear \(second singular value .* circle"):
        fit_circle_2d(line3[:, :2])
    with pytest.raises(DegenerateGeometryError, match="collinear .* cannot fit a circle"):
        fit_circle_3d(line3)
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        fit_plane(line3)
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        fit_line(np.ones((4, 3)))
    with pytest.raises(NotEnoughDataError):
        fit_line(np.ones((1, 3)))
    flat = np.random.default_rng(18).normal(size=(10, 3)) @ np.diag([1.0, 1.0, 0.0]) @ R_TILT.T
    with pytest.raises(DegenerateGeometryError, match=r"points are coplanar \(third singular value .* sphere"):
        fit_sphere(flat)
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        fit_sphere(flat, radius=2.0)
    with pytest.raises(NotEnoughDataError, match="at least 4"):
        fit_sphere(np.eye(3))
    with pytest.raises(InputError, match="radius must be > 0"):
        fit_sphere(np.vstack([np.eye(3), np.ones(3)]), radius=-1.0)
    with pytest.raises(InputError, match=r"shape \(\.\.\., N, 2\) or \(\.\.\., N, 3\)"):
        fit_line(np.zeros((5, 4)))


def test_line_and_plane_fits_are_batched():
    # one call over 5 x 7 point sets equals 35 separate fits, field by field
    rng = np.random.default_rng(21)
    P = rng.normal(size=(5, 7, 20, 3)) * [1.0, 0.1, 0.01]
    L, Pl = fit_line(P), fit_plane(P)
    assert L.rms.shape == (5, 7) and Pl.normal_cov.shape == (5, 7, 3, 3)
    for i, j in ((0, 1), (3, 6), (4, 0)):
        one, pl = fit_line(P[i, j]), fit_plane(P[i, j])
        assert isinstance(one.rms, float) and isinstance(pl.d, float)
        for a, b in ((one.direction, L.direction[i, j]), (one.direction_cov, L.direction_cov[i, j]),
                     (one.residuals, L.residuals[i, j]), (pl.normal, Pl.normal[i, j]), (pl.d, Pl.d[i, j]),
                     (pl.normal_cov, Pl.normal_cov[i, j]), (pl.d_std, Pl.d_std[i, j])):
            assert np.allclose(a, b, rtol=1e-12, atol=1e-15)
    P[2, 4, :, 1:] = 0.0  # one collinear set among 35: the error names it
    with pytest.raises(DegenerateGeometryError, match=r"collinear \(point set \(2, 4\)\)"):
        fit_plane(P)


FITS = {
    "line": fit_line,
    "plane": fit_plane,
    "circle2d": fit_circle_2d,
    "circle3d": fit_circle_3d,
    "sphere": fit_sphere,
}


@settings(max_examples=40, deadline=None)
@given(
    st.sampled_from(sorted(FITS)),
    arrays(
        np.float64,
        array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=6),
        elements=st.one_of(st.floats(-100, 100), st.just(np.nan), st.just(-np.inf), st.just(1.0)),
    ),
)
def test_fuzzed_input_fits_or_raises_a_named_error(name, pts):
    """Any shape, NaN, infinity or repeated values: a finite fit or a RobocalError."""
    try:
        f = FITS[name](pts)
    except RobocalError:
        return
    # Batched input (..., N, D) gives batched fields.
    assert np.all(np.isfinite(f.rms))
    assert f.residuals.shape == pts.shape[:-1]
