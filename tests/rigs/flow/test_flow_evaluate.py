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


def test_straight_line_alignment_is_least_squares():
    # a straight drive: collinear positions still define the planar least-squares alignment
    # (Sturm 2012); the estimate is the reference turned by 2 deg about its start and shifted
    ref = integrate_twists(np.tile([0.01, 0, 0], (100, 1)))
    c, s = np.cos(0.035), np.sin(0.035)
    est = ref.copy()
    est[:, :2] = ref[:, :2] @ np.array([[c, -s], [s, c]]).T + [0.1, -0.05]
    est[:, 0] += 0.002 * np.sin(np.arange(101) / 7.0)      # some noise along the line
    al, method = align_trajectory(est, ref)
    assert method == "umeyama"
    a = ate(est, ref)[0]
    # no other rigid motion does better (brute force over yaw; centroid matching is optimal for a yaw)
    best = np.inf
    for yaw in np.linspace(-0.1, 0.1, 2001):
        R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        xy = est[:, :2] @ R.T
        xy += ref[:, :2].mean(0) - xy.mean(0)
        best = min(best, np.sqrt(np.mean(np.sum((xy - ref[:, :2]) ** 2, 1))))
    assert a <= best + 1e-9 and a < 0.0016
    ev = evaluate_trajectory(est, ref)
    assert ev.final_error > 0.1
    # no motion at all: the rotation is free, the first poses are aligned and that is said
    still = np.zeros((10, 3))
    assert "first-pose" in align_trajectory(still, still)[1]


def test_plot_and_bad_shapes():
    ref = _ref(300)
    ax = plot_trajectories({"true": ref, "flow": ref + 0.01})
    assert len(ax.lines) == 4
    with pytest.raises(InputError):
        evaluate_trajectory(ref[:10], ref)


def test_rpe_statistics_and_honest_comparison():
    from robocal.rigs.flow.workflow import compare_text

    ref = _ref(2000)
    est = integrate_twists(np.stack([np.full(1999, 0.00202), np.zeros(1999), 0.003 * np.sin(np.arange(1999) / 300)], 1))
    r = rpe_per_distance(est, ref[:2000], lengths=(1.0,))[1.0]
    assert r["trans_per_m_mean"] <= r["trans_per_m"] and r["trans_per_m_median"] == pytest.approx(0.01, rel=0.1)
    good = evaluate_trajectory(est, ref[:2000])
    worse = evaluate_trajectory(integrate_twists(np.stack([np.full(1999, 0.002), np.zeros(1999),
                                                           0.003 * np.sin(np.arange(1999) / 300) + 2e-5], 1)), ref[:2000])
    text = compare_text(good, worse)
    assert "RPE@0.5m" in text and "WORSE" in text


def test_short_run_rpe_uses_fractions_of_the_path_and_says_so():
    from robocal.rigs.flow.evaluate import rpe_lengths

    # 2000 steps of 2 mm: 4 m of path, the fixed lengths all fit (at least two segments each)
    assert rpe_lengths(4.0) == ((0.25, 0.5, 1.0), 0.5, "")
    # 1.5 m: the 1 m segments would not fit twice, they are left out and the note says so
    keep, head, note = rpe_lengths(1.5)
    assert keep == (0.25, 0.5) and head == 0.5 and "1 m left out" in note
    ref = _ref(150)                                   # 0.3 m of path: not one 0.5 m segment
    est = ref.copy()
    est[:, :2] *= 1.02
    ev = evaluate_trajectory(est, ref)
    assert ev.distance == pytest.approx(0.3, abs=1e-3)
    assert sorted(ev.rpe) == pytest.approx([0.03, 0.075, 0.15], abs=1e-3) and ev.rpe_headline == pytest.approx(0.075, abs=1e-3)
    assert "short run" in ev.rpe_note and "% of the path" in ev.rpe_note
    for r in ev.rpe.values():                         # never an empty or NaN RPE
        assert r["n"] > 50 and r["trans_per_m_median"] == pytest.approx(0.02, rel=0.05)
    assert ev.rpe_label() == "RPE@0.075m" and ev.to_dict()["rpe_note"] == ev.rpe_note
    # a reference that never moves has no RPE per distance, and says so
    still = np.zeros((20, 3))
    ev0 = evaluate_trajectory(still, still)
    assert ev0.rpe == {} and ev0.rpe_headline is None and "does not move" in ev0.rpe_note
    assert np.isnan(ev0.headline_rpe()["trans_per_m"]) and ev0.headline_rpe()["n"] == 0
    # asked for directly, a length longer than the path gives n = 0 with a note, not a bare NaN
    r = rpe_per_distance(est, ref, lengths=(1.0,))[1.0]
    assert r["n"] == 0 and "0.300 m" in r["note"]
    with pytest.raises(InputError):
        evaluate_trajectory(est, ref, lengths=())


def test_rpe_closed_form_equals_the_homogeneous_matrix_definition():
    """E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j) with 3x3 SE(2) matrices (the definition, Sturm et al. 2012) against
    the closed form rpe_per_distance uses; on a noisy estimate whose headings are wrapped to +/-pi, so the
    rotation's wrap is exercised. Both are exact up to rounding of O(1) numbers: 1e-12 relative leaves 3 orders of
    headroom over the ~1e-15 of a few dozen products, and is 10 orders below any RPE that means something."""
    rng = np.random.default_rng(5)
    K = 3000
    ref = integrate_twists(np.stack([np.full(K, 0.002), np.zeros(K), np.full(K, 0.004)], 1))   # 1.9 turns
    est = ref + rng.normal(0, [0.003, 0.003, 0.02], ref.shape)
    est[:, 2] = np.angle(np.exp(1j * est[:, 2]))        # headings stored wrapped: differences jump by 2 pi

    def se2(p):
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        T = np.zeros((len(p), 3, 3))
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
        T[:, 0, 2], T[:, 1, 2], T[:, 2, 2] = p[:, 0], p[:, 1], 1.0
        return T

    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1))])
    out = rpe_per_distance(est, ref, lengths=(0.5, 1.0))
    for L in (0.5, 1.0):
        j = np.searchsorted(s, s + L)
        i = np.flatnonzero(j < len(s))
        j = j[i]
        E = np.linalg.inv(np.linalg.inv(se2(ref[i])) @ se2(ref[j])) @ (np.linalg.inv(se2(est[i])) @ se2(est[j]))
        te = np.linalg.norm(E[:, :2, 2], axis=1)
        re = np.abs(np.arctan2(E[:, 1, 0], E[:, 0, 0]))
        seg = s[j] - s[i]
        assert out[L]["n"] == i.size
        assert out[L]["trans_per_m"] == pytest.approx(np.sqrt(np.mean((te / seg) ** 2)), rel=1e-12)
        assert out[L]["rot_per_m"] == pytest.approx(np.sqrt(np.mean((re / seg) ** 2)), rel=1e-12)
        assert out[L]["rot_per_m_median"] == pytest.approx(np.median(re / seg), rel=1e-12)
        assert out[L]["trans_per_m_median"] == pytest.approx(np.median(te / seg), rel=1e-12)
