"""LM calibration over the seed's parameter set: exactness, ties, identifiability, outliers."""

import json
import re

import numpy as np
import pytest

from robocal.errors import InputError, NotEnoughDataError
from robocal.io import write_result
from robocal.rigs.humanoid.calibrate import calibrate, resolve_parameters
from robocal.rigs.humanoid.model import HumanoidModel
from robocal.rigs.humanoid.simulate import draw_truth, simulate_dataset


def test_noise_free_data_give_the_truth_from_zero(model):
    rng = np.random.default_rng(21)
    data = simulate_dataset(model, rng, n_per_foot=6, noise_px=0.0, resolution=0.0)
    cal = calibrate(model, data, corner_sigma=0.3, joint_resolution=0.0)
    seed = model.seed_parameters()
    assert len(seed) == 21 and sorted(cal.free) == sorted(seed)
    idx = [model.parameter_labels().index(lab) for lab in seed]
    np.testing.assert_allclose(cal.params[idx], data.truth.params[idx], atol=1e-9)
    assert cal.rms_xy.max() < 1e-6
    assert cal.lsq.rank == 21 and cal.unidentifiable == []


def test_finite_difference_jacobian_gives_the_same_estimate(model, corner_data):
    a = calibrate(model, corner_data)
    b = calibrate(model, corner_data, jac="2-point")
    assert b.lsq.jac_method != a.lsq.jac_method
    np.testing.assert_allclose(a.params, b.params, atol=1e-7)


def test_estimate_within_three_sigma_and_result_record(model, corner_data, tmp_path):
    cal = calibrate(model, corner_data)
    rows = cal.parameter_rows(corner_data.truth.params)
    z = np.array([r["error/std"] for r in rows])
    assert np.all(np.abs(z) < 3.5), rows
    assert 0.5 < cal.lsq.residual_variance < 2.0  # noise model (0.3 px + 0.1 deg quantisation) fits
    assert 0.2 < cal.corner_sigma < 0.4
    res = cal.to_result()
    path = write_result(tmp_path / "result.json", res)
    d = json.loads(path.read_text())
    assert d["rig"] == "humanoid" and set(d["estimate"]) == set(model.seed_parameters())
    assert d["units"]["camera.pitch"] == "rad" and d["units"]["board.left.x"] == "m"
    assert len(d["diagnostics"]["views"]) == corner_data.n_views
    assert d["diagnostics"]["rms_x_px"] > 0 and d["diagnostics"]["rms_y_px"] > 0
    assert d["diagnostics"]["rank"] == 21 and d["diagnostics"]["condition_number"] > 1


def test_unidentifiable_parameters_get_no_value(model, corner_data, tmp_path):
    # with the head still, a HeadYaw offset is a camera rotation: the data cannot separate them
    cal = calibrate(model, corner_data, parameters="all")
    assert "HeadYaw" in cal.unidentifiable
    for lab in cal.unidentifiable:
        assert cal.value(lab) is None and cal.std(lab) is None
    d = json.loads(write_result(tmp_path / "r.json", cal.to_result()).read_text())
    assert d["estimate"]["HeadYaw"] is None and d["std"]["HeadYaw"] is None
    assert "rank_deficient" in [w["code"] for w in d["warnings"]]
    assert "not identifiable" in cal.summary()
    # everything else is still estimated, with a std
    ok = [lab for lab in cal.free if lab not in cal.unidentifiable]
    assert all(cal.std(lab) is not None for lab in ok)


def test_undetermined_parameters_do_not_bias_the_determined_ones(model, corner_data, tmp_path):
    # one null direction (HeadYaw ~ camera roll/yaw/y with the head still): one gauge parameter is
    # held, not all four; holding all four at 0 biased LHipRoll by +6.9 sigma on this data set
    cal = calibrate(model, corner_data, parameters="all")
    assert len(cal.held) == 1 and cal.held[0] in cal.unidentifiable
    assert set(cal.unidentifiable) == {"HeadYaw", "camera.roll", "camera.yaw", "camera.y"}
    rows = cal.parameter_rows(corner_data.truth.params)
    z = np.array([r["error/std"] for r in rows if r["error/std"] is not None])
    assert len(z) == len(cal.free) - 4 and np.all(np.abs(z) < 3.5), rows
    # the rank is the problem's, not "N of N": 24 of 25, and the same in result.json
    assert cal.jacobian_rank == (24, 25)
    assert "Jacobian rank 24 of 25 free parameters (4 not determined" in cal.summary()
    d = json.loads(write_result(tmp_path / "r.json", cal.to_result()).read_text())
    assert (d["diagnostics"]["rank"], d["diagnostics"]["n_free"]) == (24, 25)
    assert d["diagnostics"]["gauge_held"] == cal.held
    # the corrected tree keeps the fitted combination: it reproduces the calibrated projection
    n = len(model.joint_names)
    folded = HumanoidModel(cal.corrected_tree(), model.camera, model.board, model.mounts)
    d = corner_data
    board = np.zeros_like(cal.params)  # boards are not part of the robot description
    board[n + 5:] = cal.params[n + 5:]
    np.testing.assert_allclose(folded.project(d.theta, d.feet, board), model.project(d.theta, d.feet, cal.params),
                               atol=1e-7)


def test_one_view_of_a_board_holds_a_minimal_gauge(model, corner_data):
    # a single right-board view leaves 3 null directions over the 9 right-side parameters: 3 are
    # held, 9 get no value, and the 12 others stay unbiased (they were off by up to 5.5 sigma)
    keep = [i for i, f in enumerate(corner_data.feet) if f == "left"] + [corner_data.feet.index("right")]
    data = corner_data.subset(keep)
    cal = calibrate(model, data)
    assert cal.jacobian_rank == (18, 21) and len(cal.held) == 3 and len(cal.unidentifiable) == 9
    rows = cal.parameter_rows(data.truth.params)
    z = np.array([r["error/std"] for r in rows if r["error/std"] is not None])
    assert len(z) == 12 and np.all(np.abs(z) < 3.5), rows
    assert not cal.outlier_corners


def test_tied_hip_yaw_pitch(model, tied_model):
    rng = np.random.default_rng(8)
    data = simulate_dataset(tied_model, rng, n_per_foot=6)
    cal = calibrate(tied_model, data)
    assert len(cal.free) == 20 and "RHipYawPitch" not in cal.free
    # the corrected URDF shifts the mimic joint's limits by its leader's offset (one motor)
    from robocal.kinematics import KinematicTree

    c = cal.value("LHipYawPitch")
    assert cal.limit_shifts()["RHipYawPitch"] == pytest.approx(c) and abs(c) > 1e-5
    lo, hi = tied_model.tree.joint("RHipYawPitch").limits
    reloaded = KinematicTree.from_urdf(cal.urdf_text())
    assert reloaded.joint("RHipYawPitch").limits == pytest.approx((lo - c, hi - c))
    # parameter-level tie on the untied model: one value for both joints
    truth = draw_truth(model, rng)
    n = len(model.joint_names)
    truth.params[model.joint_names.index("RHipYawPitch")] = truth.params[model.joint_names.index("LHipYawPitch")]
    data2 = simulate_dataset(model, rng, n_per_foot=6, truth=truth)
    cal2 = calibrate(model, data2, tie=True)
    assert cal2.value("RHipYawPitch") == pytest.approx(cal2.value("LHipYawPitch"))
    assert abs(cal2.value("LHipYawPitch") - truth.params[model.joint_names.index("LHipYawPitch")]) < \
        4 * cal2.std("LHipYawPitch")
    assert n == len(model.joint_names)


def test_gross_corner_error_is_named(model, corner_data):
    data = corner_data.subset(np.arange(corner_data.n_views))
    data.corners = data.corners.copy()
    data.corners[3, 7] += [6.0, -4.0]
    cal = calibrate(model, data)
    assert (data.names[3], 7) in cal.outlier_corners
    w = [w for w in cal.warnings if w.code == "outliers"][0]
    assert data.names[3] in w.message


def test_views_without_a_full_board_are_dropped(model, corner_data):
    data = corner_data.subset(np.arange(corner_data.n_views))
    data.corners = data.corners.copy()
    data.corners[2] = np.nan
    cal = calibrate(model, data)
    assert cal.data.n_views == corner_data.n_views - 1
    assert any(w.code == "dropped" and data.names[2] in w.message for w in cal.warnings)


def test_missing_corners_count_nowhere(model, corner_data):
    # Corners removed at detection (NaN) are left out of their view's residual term: the degrees of
    # freedom, the residual variance and the measured corner noise count only the kept corners, so
    # removing half of every view's corners must not halve the variance (as zero rows would).
    clean = calibrate(model, corner_data)
    data = corner_data.subset(np.arange(corner_data.n_views))
    data.corners = data.corners.copy()
    rng = np.random.default_rng(0)
    for v in range(data.n_views):
        data.corners[v, rng.choice(24, 12, replace=False)] = np.nan
    cal = calibrate(model, data)
    kept = int(np.isfinite(data.corners[..., 0]).sum())
    assert cal.keep.sum() == kept == cal.used_residuals.shape[0] and len(cal.missing_corners) == 12 * data.n_views
    assert sum(t.n_obs * t.dim for t in cal.lsq.terms) == 2 * kept  # one term per view, kept corners only
    assert cal.lsq.dof == 2 * kept - cal.lsq.rank
    assert cal.lsq.residual_variance == pytest.approx(clean.lsq.residual_variance, rel=0.15)
    assert cal.corner_sigma == pytest.approx(clean.corner_sigma, rel=0.1)
    assert np.isfinite(cal.rms_xy).all() and np.isfinite(cal.view_rms).all()
    # the stds grow by about sqrt(2) with half the corners, not less (a diluted variance)
    ratio = [cal.std(lab) / clean.std(lab) for lab in clean.free]
    assert 1.1 < np.median(ratio) < 1.8
    # the views' corners that remain are still consistent with their joint records
    assert not [w for w in cal.warnings if w.code == "inconsistent_data"]


def test_too_little_data(model, corner_data):
    left = corner_data.subset([i for i, f in enumerate(corner_data.feet) if f == "left"])
    with pytest.raises(NotEnoughDataError, match="right board"):
        calibrate(model, left)
    cal = calibrate(model, left, parameters="camera_rotation,LHipYawPitch,LHipRoll,LHipPitch,LKneePitch,"
                                           "LAnklePitch,LAnkleRoll,board.left.yaw,board.left.x,board.left.y")
    assert len(cal.free) == 12
    one = corner_data.subset([0, corner_data.n_views - 1])
    with pytest.raises(NotEnoughDataError):
        calibrate(model, one)


def test_parameter_selection(model):
    assert resolve_parameters(model, "seed+camera_xy")[-2:] != ["camera.x", "camera.y"]  # kept in model order
    assert len(resolve_parameters(model, "seed+camera_xy")) == 23
    assert resolve_parameters(model, "LKneePitch, camera.roll") == ["LKneePitch", "camera.roll"]
    with pytest.raises(InputError, match="unknown calibration parameter"):
        resolve_parameters(model, "LElbow")


def test_reject_outliers_restores_the_clean_estimate(model, tmp_path):
    # 3 views per foot, 0.3 px corners: one corner 3 px off pulls the estimate by ~3 std. It is
    # injected into the corners, past detection (whose homography check would drop this whole view:
    # its threshold is 1.34 px here). View 0, corner 18: a board corner with high leverage, chosen
    # once by scanning every corner.
    data = simulate_dataset(model, np.random.default_rng(11), n_per_foot=3)
    clean = calibrate(model, data)
    assert not clean.outlier_corners
    bad = data.subset(np.arange(data.n_views))
    bad.corners = bad.corners.copy()
    bad.corners[0, 18] += [0.0, 3.0]

    def worst(cal):
        return max(abs(cal.value(lab) - clean.value(lab)) / clean.std(lab) for lab in clean.free)

    plain = calibrate(model, bad)
    assert plain.outlier_corners == [(data.names[0], 18)] and plain.rejected_corners == []
    w = [w for w in plain.warnings if w.code == "outliers"][0]
    assert f"{data.names[0]}: corners [18]" in w.message
    assert worst(plain) > 2.0  # measured 2.95 std

    cal = calibrate(model, bad, reject_outliers=True)
    assert cal.rejected_corners == [(data.names[0], 18)] and cal.rejected_views == []
    assert int((~cal.keep).sum()) == 1 and not cal.keep[0, 18]
    assert worst(cal) < 1.0  # measured 0.09 std
    # the noise model of the kept corners fits: residual variance as for the clean data
    assert cal.lsq.residual_variance == pytest.approx(clean.lsq.residual_variance, rel=0.15)
    assert any(w.code == "low_quality" and "corners [18]" in w.message for w in cal.warnings)
    assert "1 corner(s) removed" in cal.summary()
    d = json.loads(write_result(tmp_path / "r.json", cal.to_result()).read_text())["diagnostics"]
    assert d["rejected_corners"] == [[data.names[0], 18]] and d["rejected_views"] == []
    assert d["n_corners_used"] == d["n_corners"] - 1
    # nothing to reject: the same calibration
    same = calibrate(model, data, reject_outliers=True)
    assert same.keep.all() and same.rejected_corners == [] and np.array_equal(same.params, clean.params)


def test_reject_outliers_drops_a_view_with_many_bad_corners(model):
    data = simulate_dataset(model, np.random.default_rng(11), n_per_foot=3)
    bad = data.subset(np.arange(data.n_views))
    bad.corners = bad.corners.copy()
    # a third of the view's corners 4 px off in alternating directions (no board pose absorbs that).
    # (At 3 px, 6 of the 8 pass the Bonferroni threshold over the 144 corners, 3.98 sigma: 25 %, not
    # more, so the view stays and those corners go; the fixed 3 sigma of before flagged all 8.)
    bad.corners[1, [0, 3, 5, 10, 13, 18, 20, 23]] += np.array([[4.0, 0.0], [-4.0, 0.0]] * 4)
    cal = calibrate(model, bad, reject_outliers=True)
    assert data.names[1] in cal.rejected_views and not cal.keep[1].any()
    assert all(v != data.names[1] for v, _ in cal.rejected_corners)


def test_corrected_urdf_shifts_limits_and_carries_provenance(model, corner_data, tmp_path):
    import re

    from robocal import __version__
    from robocal.kinematics import KinematicTree

    cal = calibrate(model, corner_data)
    path = tmp_path / "nao_calibrated.urdf"
    text = cal.write_urdf(path, inputs={"data/run.yaml": "f" * 64})
    assert path.read_text() == text
    reloaded = KinematicTree.from_urdf(path)
    n = len(model.joint_names)
    # physical range unchanged: new limits + offset = the model's limits, for every calibrated joint
    for k, j in enumerate(model.joint_names):
        lo, hi = model.tree.joint(j).limits
        c = cal.params[k]
        assert reloaded.joint(j).limits == pytest.approx((lo - c, hi - c), abs=1e-12)
        if j in model.leg_joints:
            assert abs(c) > 1e-5  # really shifted
    # a raw reading at the physical limit is at the new limit
    theta = np.array([model.tree.joint(j).limits[1] for j in model.joint_names]) - cal.params[:n]
    assert reloaded.within_limits(theta) and not reloaded.within_limits(theta + 1e-6)
    # provenance: version, date, input and its hash, the offsets applied
    head = text.split("<robot", 1)[0]
    assert f"robocal {__version__}" in head and re.search(r"on \d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", head)
    assert "data/run.yaml sha256 " + "f" * 64 in head
    for r in cal.offsets_table():
        if not r["estimated"]:
            assert re.search(rf"\n\s+{r['joint']} \+0\.000000\n", head)
            continue
        m = re.search(rf"\n\s+{r['joint']} ([+-]\d+\.\d+) \(std (\d+\.\d+)\)", head)
        assert m and float(m.group(1)) == pytest.approx(r["offset [deg]"], abs=1e-6)
        assert float(m.group(2)) == pytest.approx(r["std [deg]"], abs=1e-6)
    assert "camera correction in CameraBottom_frame" in head 
    body = head.split("<!--", 1)[1].rsplit("-->", 1)[0]
    assert "--" not in body and not body.endswith("-")  # a well-formed XML comment


def test_rejected_corners_in_both_reports(model, tmp_path):
    from robocal.io import load_result
    from robocal.rigs.humanoid.report import build_report, write_outputs

    data = simulate_dataset(model, np.random.default_rng(11), n_per_foot=3)
    data.corners = data.corners.copy()
    data.corners[0, 18] += [0.0, 3.0]
    cal = calibrate(model, data, reject_outliers=True)
    paths = write_outputs(cal, tmp_path / "a")
    assert sorted(p.name for p in paths)[:3] == ["nao_h25_legs_head_calibrated.urdf", "offsets.yaml", "report.html"]
    rebuilt = build_report(load_result(tmp_path / "a" / "result.json"), base_dir=tmp_path / "a")
    rebuilt.write(tmp_path / "b.html")
    first = (tmp_path / "a" / "report.html").read_text()
    # the report is built from the result alone: the rebuilt page is the first (but for its time stamp)
    strip = lambda html: re.sub(r"<p class='meta'>.*?</p>", "", html)  # noqa: E731
    assert strip((tmp_path / "b.html").read_text()) == strip(first)
    assert "re-solved once without them" in first and f"{data.names[0]} corners [18]" in first
