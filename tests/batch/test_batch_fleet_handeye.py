"""``robocal handeye simulate --fleet``'s robots: what each plants is in its truth (:mod:`robocal.handeye.fleet`).

The fleet report naming them is ``tests/batch/test_batch_rig_fleets.py``'s; here, fast, the truth of
one cell of each kind against the drawing, and the set-up a fleet cannot simulate.
"""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.geometry import invert_transform, rotation_angle
from robocal.handeye.fleet import FAULT_DEG, MOUNT_DEG, MOUNT_MM, fleet_member
from robocal.handeye.simulate import default_hand_eye
from truth_files import truth_pose


def _cell(tmp_path, kind, seed=0, **options):
    out = tmp_path / str(kind)
    out.mkdir()
    planted = fleet_member(out, np.random.default_rng(seed), kind=kind, **options)
    dX = invert_transform(default_hand_eye()) @ truth_pose(out / "truth.yaml", "T_gripper_cam")
    rows = (out / "gripper_poses.csv").read_text().count("\n") - 1
    return planted, float(np.degrees(rotation_angle(dX[:3, :3]))), dX[:3, 3] * 1e3, rows


@pytest.mark.parametrize("seed", range(3))
def test_a_cell_of_each_kind_carries_what_it_planted(tmp_path, seed):
    # the bracket's scatter: 0.1 deg per axis, so the angle (a chi with 3 dof x 0.1 deg) is < 0.5 deg but
    # with probability ~2e-5, the translation per axis < 5 x 0.5 mm; a knock adds FAULT_DEG about one axis
    bound_deg, bound_mm = 5 * MOUNT_DEG, 5 * MOUNT_MM
    planted, angle, dt, rows = _cell(tmp_path, None, seed)
    assert planted == {} and angle < bound_deg and np.all(np.abs(dt) < bound_mm) and rows == 16
    planted, angle, dt, rows = _cell(tmp_path, "fault", seed)
    assert planted["parameter"] == "T_gripper_cam.rotvec" and abs(planted["shift"]) == FAULT_DEG
    assert abs(angle - FAULT_DEG) < bound_deg and np.all(np.abs(dt) < bound_mm)  # turned about its centre
    planted, angle, dt, rows = _cell(tmp_path, "weak", seed)
    assert angle < bound_deg and rows == planted["poses"] == 5 and "5x the pose noise" in planted["text"]


def test_a_fleet_is_eye_in_hand_only(tmp_path):
    # the fleet's manifest carries no options: 'robocal batch handeye' calibrates with the default set-up
    with pytest.raises(InputError, match="eye-in-hand cells only.*eye-to-hand"):
        fleet_member(tmp_path, np.random.default_rng(0), setup="eye-to-hand")
