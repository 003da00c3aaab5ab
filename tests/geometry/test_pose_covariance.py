"""PoseWithCovariance: first-order inverse and composition against finite differences and sampling, the error
to a known perturbation, both rotation sides, and the round trip through a result file."""

import numpy as np
import pytest

from robocal.geometry import PoseWithCovariance, invert_transform, matrix_from_rotvec, transform_from
from robocal.io import CalibrationResult, load_result, write_result

T0 = transform_from(matrix_from_rotvec([0.4, -1.1, 0.7]), [0.05, -0.2, 0.3])
T1 = transform_from(matrix_from_rotvec([-0.9, 0.2, 0.5]), [0.4, 0.1, -0.25])


def _cov(rng, scale=1e-3):
    A = rng.normal(size=(6, 6)) * scale
    return A @ A.T


def _perturb(T, d, side):
    """``T`` moved by ``d = (rotation vector, translation)`` on ``side`` (the convention of the covariance)."""
    R = matrix_from_rotvec(d[:3]) @ T[:3, :3] if side == "left" else T[:3, :3] @ matrix_from_rotvec(d[:3])
    return transform_from(R, T[:3, 3] + d[3:])


def _jacobian(f, T, side, h=1e-7):
    """d error(f(T + d)) / d d by central differences, the error on the same side."""
    ref = PoseWithCovariance(f(T), side=side)
    cols = []
    for e in np.eye(6):
        plus = PoseWithCovariance(f(_perturb(T, h * e, side)), side=side).error_to(ref.T).vector
        minus = PoseWithCovariance(f(_perturb(T, -h * e, side)), side=side).error_to(ref.T).vector
        cols.append((plus - minus) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("side", ["left", "right"])
def test_inverse_covariance_matches_finite_differences(side):
    cov = _cov(np.random.default_rng(1))
    inv = PoseWithCovariance(T0, cov, side).inverse()
    assert inv.side == side
    np.testing.assert_allclose(inv.T @ T0, np.eye(4), atol=1e-12)
    G = _jacobian(invert_transform, T0, side)
    # central differences with h = 1e-7 on O(1) entries: truncation ~h^2, rounding ~1e-16/h ~ 1e-9 relative
    np.testing.assert_allclose(inv.cov, G @ cov @ G.T, rtol=1e-6, atol=1e-15)
    # and back: the inverse of the inverse is the pose with its covariance
    back = inv.inverse()
    np.testing.assert_allclose(back.T, T0, atol=1e-12)
    np.testing.assert_allclose(back.cov, cov, rtol=1e-9, atol=1e-18)


def test_inverse_covariance_matches_sampling():
    # 4000 samples of 1 mrad / 1 mm errors: the sample covariance's entries scatter by ~sqrt(2/4000) = 2.2 %
    # of their scale, the second-order bias of the linearisation is ~1e-3 relative; 10 % is > 4 sigma
    rng = np.random.default_rng(7)
    cov = _cov(rng)
    inv = PoseWithCovariance(T0, cov).inverse()
    d = rng.multivariate_normal(np.zeros(6), cov, size=4000)
    samples = transform_from(matrix_from_rotvec(d[:, :3]) @ T0[:3, :3], T0[:3, 3] + d[:, 3:])   # left side
    e = PoseWithCovariance(invert_transform(samples)).error_to(inv.T).vector    # batched, one truth broadcast
    S = np.cov(e.T)
    scale = np.sqrt(np.outer(np.diag(inv.cov), np.diag(inv.cov)))
    assert np.max(np.abs(S - inv.cov) / scale) < 0.10
    # a wrong propagation (the covariance carried over unchanged) fails the same comparison
    assert np.max(np.abs(S - cov) / scale) > 0.5


@pytest.mark.parametrize("side", ["left", "right"])
def test_compose_covariance_matches_finite_differences(side):
    rng = np.random.default_rng(3)
    C0, C1 = _cov(rng), _cov(rng)
    out = PoseWithCovariance(T0, C0, side).compose(PoseWithCovariance(T1, C1, side))
    np.testing.assert_allclose(out.T, T0 @ T1, atol=1e-15)
    G0 = _jacobian(lambda T: T @ T1, T0, side)
    G1 = _jacobian(lambda T: T0 @ T, T1, side)
    np.testing.assert_allclose(out.cov, G0 @ C0 @ G0.T + G1 @ C1 @ G1.T, rtol=1e-6, atol=1e-15)
    # @ is compose; an exact pose adds nothing
    np.testing.assert_allclose((PoseWithCovariance(T0, C0, side) @ PoseWithCovariance(T1)).cov,
                               G0 @ C0 @ G0.T, rtol=1e-6, atol=1e-15)


def test_sides_describe_the_same_uncertainty():
    cov = _cov(np.random.default_rng(5))
    left = PoseWithCovariance(T0, cov, "left")
    right = left.to_side("right")
    np.testing.assert_allclose(right.to_side("left").cov, cov, rtol=1e-12, atol=1e-20)
    # the translation block is side-free; the rotation block's trace (total variance) is rotation-invariant
    np.testing.assert_allclose(right.cov[3:, 3:], cov[3:, 3:], rtol=1e-12)
    assert np.trace(right.cov[:3, :3]) == pytest.approx(np.trace(cov[:3, :3]), rel=1e-12)
    assert not np.allclose(right.cov[:3, :3], cov[:3, :3])


@pytest.mark.parametrize("side", ["left", "right"])
def test_error_to_recovers_a_known_perturbation(side):
    d = np.array([2e-3, -1e-3, 0.5e-3, 1e-3, 2e-3, -3e-3])
    err = PoseWithCovariance(_perturb(T0, d, side), side=side).error_to(T0)
    np.testing.assert_allclose(err.vector, d, atol=1e-15)   # exact by construction: Log(Exp(d)) = d
    assert err.rotation == pytest.approx(np.linalg.norm(d[:3]), rel=1e-12)
    assert err.translation == pytest.approx(np.linalg.norm(d[3:]), rel=1e-12)
    # a pose on the other side sees another rotation vector (rotated by R), with the same angle
    other = PoseWithCovariance(_perturb(T0, d, side), side="right" if side == "left" else "left").error_to(T0)
    assert not np.allclose(other.vector[:3], d[:3], atol=1e-6)
    assert other.rotation == pytest.approx(err.rotation, rel=1e-12)


def test_vectorised_over_leading_dimensions():
    rng = np.random.default_rng(9)
    Ts = np.stack([T0, T1, T0 @ T1])
    covs = np.stack([_cov(rng) for _ in range(3)])
    batch = PoseWithCovariance(Ts, covs)
    inv, err = batch.inverse(), batch.error_to(np.stack([T1, T0, T0]))
    assert inv.cov.shape == (3, 6, 6) and err.vector.shape == (3, 6) and err.rotation.shape == (3,)
    for k in range(3):
        one = PoseWithCovariance(Ts[k], covs[k])
        np.testing.assert_allclose(inv.cov[k], one.inverse().cov, rtol=1e-12, atol=1e-20)
        np.testing.assert_allclose(err.vector[k], one.error_to(np.stack([T1, T0, T0])[k]).vector, atol=1e-15)
    assert batch.std.shape == (3, 6) and batch.std_rotation.shape == (3, 3)


def test_round_trip_through_a_result(tmp_path):
    cov = _cov(np.random.default_rng(11))
    cov[4, :] = cov[:, 4] = 0.0
    cov[4, 4] = np.nan                          # a component the data did not determine
    pose = PoseWithCovariance(T0, cov, "right")
    res = CalibrationResult(rig="test", method="m", estimate={}, std={}, units={})
    pose.add_to(res, "T_a_b", parent="a", child="b")
    assert res.std["T_a_b.translation"][1] is None
    write_result(tmp_path / "result.json", res)
    back = PoseWithCovariance.from_result(load_result(tmp_path / "result.json"), "T_a_b")
    np.testing.assert_allclose(back.T, T0, atol=1e-12)
    assert back.side == "right"
    np.testing.assert_allclose(back.std[[0, 1, 2, 3, 5]], pose.std[[0, 1, 2, 3, 5]], rtol=1e-12)
    assert np.isnan(back.std[4]) and np.isnan(pose.std[4])
    # no covariance in, none out
    PoseWithCovariance(T1).add_to(res, "T_c_d")
    assert PoseWithCovariance.from_result(res, "T_c_d").cov is None


def test_bad_input():
    with pytest.raises(ValueError, match="side"):
        PoseWithCovariance(T0, side="middle")
    with pytest.raises(ValueError, match="one 6x6"):
        PoseWithCovariance(np.stack([T0, T1]), np.eye(6))
    with pytest.raises(Exception, match="rotation"):
        PoseWithCovariance(np.diag([2.0, 1.0, 1.0, 1.0]))
