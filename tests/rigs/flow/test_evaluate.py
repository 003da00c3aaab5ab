"""ATE after Umeyama alignment and RPE per distance, from their definitions."""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.rigs.flow.evaluate import align_trajectory, ate, evaluate_trajectory, plot_trajectories, rpe_per_distance
from robocal.rigs.flow.model import integrate_twists


def _ref(K=2000):
    k = np.arange(K)
    return integrate_twists(np.stack([np.full(K, 0.002), 0 * k, 0.003 * np.sin(k / 300)], 1))


def test_ate_is_invariant_to_a_rigid_motion_of_the_estimate():
    ref = _ref()
    c, s = np.cos(0.4), np.sin(0.4)
    est = ref.copy()
    est[:, :2] = ref[:, :2] @ np.array([[c, -s], [s, c]]).T + [1.0, -2.0]
    est[:, 2] += 0.4
    a, al, err, method = ate(est, ref)
    assert method == "umeyama"
    assert a < 1e-9 and np.abs(al - ref).max() < 1e-9


def test_rpe_of_a_scale_error_is_the_scale_error():
    ref = _ref()
    est = ref.copy()
    est[:, :2] *= 1.02  # 2 % too long everywhere
    r = rpe_per_distance(est, ref, lengths=(1.0,))[1.0]
    # per metre of *path*: 2 % of each segment's chord (the path curves a little)
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1))])
    i = np.arange(len(s))
    j = np.searchsorted(s, s + 1.0)
    ok = j < len(s)
    chord = np.linalg.norm(ref[j[ok], :2] - ref[i[ok], :2], axis=1) / (s[j[ok]] - s[i[ok]])
    assert r["trans_per_m"] == pytest.approx(0.02 * np.sqrt(np.mean(chord**2)), rel=1e-6)
    assert r["rot_per_m"] < 1e-9
    # a constant heading-rate error shows up as rotation per metre
    est2 = integrate_twists(np.stack([np.full(1999, 0.002), np.zeros(1999), 0.003 * np.sin(np.arange(1999) / 300) + 1e-4], 1))
    r2 = rpe_per_distance(est2, ref[:2000], lengths=(1.0,))[1.0]
    assert r2["rot_per_m"] == pytest.approx(1e-4 / 0.002, rel=0.02)


def test_straight_line_alignment_falls_back_and_says_so():
    ref = integrate_twists(np.tile([0.01, 0, 0], (100, 1)))
    est = ref + [0.1, 0.0, 0.0]
    al, method = align_trajectory(est, ref)
    assert "collinear" in method
    ev = evaluate_trajectory(est, ref)
    assert ev.final_error == pytest.approx(0.1)


def test_plot_and_bad_shapes():
    ref = _ref(300)
    ax = plot_trajectories({"true": ref, "flow": ref + 0.01})
    assert len(ax.lines) == 4
    with pytest.raises(InputError):
        evaluate_trajectory(ref[:10], ref)
