"""The core's simulated pose lists calibrate to their truth within the reported covariance; the old
``robocal.rigs.lineprofiler`` paths still import (deprecated, one release)."""

import importlib
import sys

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.geometry import PoseWithCovariance
from robocal.handeye import calibrate_hand_eye, judge_poses, simulate_eye_in_hand


def test_simulated_views_give_consistent_covariance():
    # 40 independent scenes of 16 views: the mean NEES of X (6 dof) is chi2(6)/1 with std sqrt(12/40) = 0.55;
    # [4.2, 7.8] is +/- 3.3 sigma (measured: 6.0)
    nees, small = [], []
    for seed in range(40):
        sim = simulate_eye_in_hand(np.random.default_rng(seed), 16)
        assert judge_poses(sim.T_base_gripper, sim.T_cam_target) == []
        res = calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target)
        e = PoseWithCovariance(res.X, res.cov).error_to(sim.X).vector
        nees.append(e @ np.linalg.solve(res.cov, e))
        small.append(e @ np.linalg.solve(res.cov / 4, e))
    assert 4.2 < np.mean(nees) < 7.8, np.mean(nees)
    assert np.mean(small) > 7.8          # a std half the size is caught


def test_results_give_their_poses_with_covariance():
    from robocal.geometry import invert_transform
    from robocal.handeye import calibrate_robot_world, invert_with_covariance, transform_error

    sim = simulate_eye_in_hand(np.random.default_rng(1), 12)
    res = calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target)
    assert res.X_pose.cov is res.cov and np.array_equal(res.X_pose.T, res.X)
    err = res.X_pose.error_to(sim.X)
    assert (err.rotation, err.translation) == transform_error(res.X, sim.X)
    assert calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target, refine=False).X_pose.std is None
    rw = calibrate_robot_world(sim.T_cam_target, invert_transform(sim.T_base_gripper))
    Ti, Ci = invert_with_covariance(rw.Z, np.asarray(rw.cov)[6:, 6:])
    np.testing.assert_array_equal(rw.Z_pose.inverse().cov, Ci)      # the same arithmetic, bit for bit
    # Z = T_cam_gripper: its inverse is the truth X = T_gripper_cam, within the propagated covariance
    e = rw.Z_pose.inverse().error_to(sim.X).vector
    assert e @ np.linalg.solve(Ci, e) < 22.5                         # chi2(6) 0.999 quantile
    assert rw.X_pose.cov.shape == (6, 6)


def test_noise_free_simulation_is_exact_and_bad_arguments_are_named():
    sim = simulate_eye_in_hand(np.random.default_rng(0), 5, noise=False)
    assert sim.sigma_rotation == 0.0
    np.testing.assert_allclose(sim.T_base_gripper @ sim.X @ sim.T_cam_target, np.broadcast_to(sim.Y, (5, 4, 4)),
                               atol=1e-12)
    with pytest.raises(InputError, match="at least 3"):
        simulate_eye_in_hand(np.random.default_rng(0), 2)
    with pytest.raises(InputError, match="Generator"):
        simulate_eye_in_hand(0, 5)


def test_old_import_paths_warn_and_alias_the_core():
    import robocal.handeye as core
    import robocal.handeye.motions as core_motions
    import robocal.handeye.workflow as core_workflow

    for name in ("robocal.rigs.lineprofiler.handeye", "robocal.rigs.lineprofiler.handeye_workflow"):
        sys.modules.pop(name, None)
    with pytest.warns(DeprecationWarning, match="use robocal.handeye instead"):
        old = importlib.import_module("robocal.rigs.lineprofiler.handeye")
    assert old.calibrate_hand_eye is core.calibrate_hand_eye
    from robocal.rigs.lineprofiler.handeye.motions import _pose_residual
    assert _pose_residual is core_motions._pose_residual
    with pytest.warns(DeprecationWarning, match="use robocal.handeye.workflow instead"):
        old_wf = importlib.import_module("robocal.rigs.lineprofiler.handeye_workflow")
    assert old_wf.calibrate is core_workflow.calibrate
    import robocal.rigs.lineprofiler.cli as lp_cli
    from robocal.handeye.cli import HANDEYE

    with pytest.warns(DeprecationWarning, match="robocal.handeye.cli.HANDEYE"):
        assert lp_cli.HANDEYE is HANDEYE
