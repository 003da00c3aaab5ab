"""The shipped NAO model, the forward model of seed 001 eq. 5 and its analytic Jacobian."""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.kinematics import KinematicTree
from robocal.rigs.humanoid.model import FEET, HumanoidModel, default_model_path, rpy_matrix
from robocal.rigs.humanoid.simulate import board_outline, draw_truth, sample_poses


def test_nao_geometry_matches_aldebaran_and_spec(model):
    tree = model.tree
    q0 = np.zeros(tree.n_joints)
    fk = tree.fk(q0)
    # Aldebaran H25 links (docs/rigs/humanoid.md): neck 126.5 mm, hips (0, +-50, -85) mm, thigh 100, tibia 102.9, foot 45.19
    np.testing.assert_allclose(fk["Neck"][:3, 3], [0, 0, 0.1265])
    np.testing.assert_allclose(fk["LPelvis"][:3, 3], [0, 0.05, -0.085])
    np.testing.assert_allclose(fk["RPelvis"][:3, 3], [0, -0.05, -0.085])
    np.testing.assert_allclose(fk["l_sole"][:3, 3], [0, 0.05, -0.085 - 0.1 - 0.1029 - 0.04519])
    np.testing.assert_allclose(fk["r_sole"][:3, 3], [0, -0.05, -0.085 - 0.1 - 0.1029 - 0.04519])
    cam = tree.transform(q0, "Head", "CameraBottom_frame")
    np.testing.assert_allclose(cam[:3, 3], [0.05071, 0, 0.01774])
    # pitched down 39.7 deg: the optical axis points forward and down
    axis = tree.transform(q0, "Head", "CameraBottom_optical_frame")[:3, 2]
    np.testing.assert_allclose(np.degrees(np.arctan2(-axis[2], axis[0])), 39.7, atol=0.01)
    # a few joint limits from Aldebaran's H25 joints page (degrees)
    np.testing.assert_allclose(np.degrees(tree.joint("LKneePitch").limits), [-5.29, 121.04], atol=0.01)
    np.testing.assert_allclose(np.degrees(tree.joint("RHipRoll").limits), [-45.29, 21.74], atol=0.01)
    assert model.camera.fx == 562.5 and (model.camera.cx, model.camera.cy) == (324.0, 189.0)
    assert model.board.n_corners == 24 and model.board.square == 0.025


def test_seed_parameter_set_is_21_and_tie_makes_20(model, tied_model):
    assert len(model.seed_parameters()) == 21
    assert len(tied_model.seed_parameters()) == 20
    assert "RHipYawPitch" not in tied_model.joint_names
    assert "LHipYawPitch" in tied_model.mounts["right"].leg_joints
    q = np.zeros((1, tied_model.tree.n_joints))
    q[0, tied_model.joint_names.index("LHipYawPitch")] = 0.3
    # one motor: both hip yaw-pitch joints turn together
    fk = tied_model.tree.fk(q)
    untied = model.tree.fk(np.where(np.isin(model.joint_names, ["LHipYawPitch", "RHipYawPitch"]), 0.3, 0.0))
    np.testing.assert_allclose(fk["r_sole"][0], untied["r_sole"], atol=1e-12)
    assert model.with_tie(True).tied and not tied_model.with_tie(False).tied


@pytest.mark.parametrize("tie", [False, True])
def test_analytic_jacobian_matches_finite_differences(tie):
    m = HumanoidModel.from_urdf(tie_hip_yaw_pitch=tie)
    rng = np.random.default_rng(2)
    truth = draw_truth(m, rng, camera_mm=2.0, head_deg=0.5)
    feet, q = sample_poses(m, 3, rng, truth=truth)
    x = truth.params
    _, J = m.project(q, feet, x, jacobian=True)
    h = 1e-6
    Jn = np.empty_like(J)
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = h
        Jn[..., k] = (m.project(q, feet, x + e) - m.project(q, feet, x - e)) / (2 * h)
    scale = np.abs(Jn).max(axis=(0, 1, 2)) + 1.0
    assert np.max(np.abs(J - Jn).max(axis=(0, 1, 2)) / scale) < 1e-5


def test_board_faces_the_camera_and_pose_matches_projection(model):
    rng = np.random.default_rng(4)
    truth = draw_truth(model, rng)
    feet, q = sample_poses(model, 4, rng, truth=truth)
    n = len(model.joint_names)
    uv = model.project(q - truth.params[:n], feet, truth.params)
    assert np.all(model.camera.in_image(uv, margin=14.9))
    for v, foot in enumerate(feet):
        fi = FEET.index(foot)
        T = model.T_opt_board(q[v][None], foot, truth.params[n:n + 5], truth.params[n + 5 + 3 * fi:n + 8 + 3 * fi])[0]
        np.testing.assert_allclose(model.camera.project_points(model.object_points, T), uv[v], atol=1e-9)
        assert T[:3, 2] @ T[:3, 3] / np.linalg.norm(T[:3, 3]) > 0.5  # printed face toward the camera
        assert np.all(model.tree.within_limits(q[v] - truth.params[:n]))


def test_sampled_poses_show_the_whole_board(model):
    # issue 4: "poses ... with the board fully visible": the outer squares too, not only the inner
    # corners (before, 56 % of sampled poses had outer squares cut by the image border)
    rng = np.random.default_rng(6)
    truth = draw_truth(model, rng)
    feet, q = sample_poses(model, 12, rng, truth=truth)
    n = len(model.joint_names)
    edge = board_outline(model.board)
    np.testing.assert_allclose(np.ptp(edge[:4, :2], axis=0), [7 * 0.025, 5 * 0.025])  # the 5 x 7 squares
    for v, foot in enumerate(feet):
        fi = FEET.index(foot)
        T = model.T_opt_board(q[v][None], foot, truth.params[n:n + 5], truth.params[n + 5 + 3 * fi:n + 8 + 3 * fi])[0]
        assert np.all(model.camera.in_image(model.camera.project_points(edge, T), margin=3.9)), v


def test_corrected_tree_reproduces_the_calibrated_projection(model, tmp_path):
    rng = np.random.default_rng(5)
    truth = draw_truth(model, rng, camera_mm=1.0)
    feet, q = sample_poses(model, 2, rng, truth=truth)
    n = len(model.joint_names)
    theta = q - truth.params[:n]
    x = truth.params.copy()
    x[n + 5:] = 0.0  # boards are not part of the robot description
    tree = model.corrected_tree(x).fold_offsets()
    path = tmp_path / "nao_corrected.urdf"
    tree.to_urdf(path)
    reloaded = KinematicTree.from_urdf(path)
    zero_board = HumanoidModel(reloaded, model.camera, model.board, model.mounts)
    np.testing.assert_allclose(zero_board.project(theta, feet, np.zeros_like(x)), model.project(theta, feet, x),
                               atol=1e-8)


def test_rpy_matrix_derivatives():
    r = np.array([0.1, -0.2, 0.3])
    R, dR = rpy_matrix(*r, derivatives=True)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-7
        np.testing.assert_allclose((rpy_matrix(*(r + e)) - rpy_matrix(*(r - e))) / 2e-7, dR[k], atol=1e-7)


def test_joint_records_are_checked(model):
    rec = {j: 0.0 for j in model.joint_names}
    assert model.q_from_records([rec]).shape == (1, len(model.joint_names))
    with pytest.raises(InputError, match="missing joint angles"):
        model.q_from_records([{k: v for k, v in rec.items() if k != "LKneePitch"}])
    with pytest.raises(InputError, match="unknown joints"):
        model.q_from_records([{**rec, "LElbowRoll": 0.0}])
    bad = model.q_from_records([rec, {**rec, "LKneePitch": np.radians(130)}])
    with pytest.raises(InputError, match=r"joints\[1\]: joint 'LKneePitch' = 130.00 deg is outside"):
        model.check_limits(bad)


def test_default_model_file_is_shipped():
    assert default_model_path().is_file()
    assert "Aldebaran" in default_model_path().read_text()
