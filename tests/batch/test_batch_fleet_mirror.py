"""``robocal mirror simulate --fleet``: what each robot plants is in its truth (:mod:`robocal.rigs.mirror.fleet`).

The fleet report naming them is ``tests/batch/test_batch_rig_fleets.py``'s; here, fast, the truth of
one robot of each kind against the published robot, and the forms a fleet cannot simulate.
"""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.geometry import rotation_angle
from robocal.rigs.mirror.files import load_input
from robocal.rigs.mirror.fleet import FAULT_DEG, MOUNT_DEG, MOUNT_MM, WEAK_NOISE_FACTOR, fleet_member
from robocal.rigs.mirror.scene import published_scene


def _robot(tmp_path, kind, seed):
    out = tmp_path / f"{kind}-{seed}"
    out.mkdir()
    planted = fleet_member(out, np.random.default_rng(seed), kind=kind, placements=4, sigma_px=0.5)
    inp = load_input(out / "mirror_input.yaml")
    T0 = np.linalg.inv(published_scene().T_c_r)
    dR = T0[:3, :3].T @ inp.truth[:3, :3]  # the turn in the camera's own axes
    return planted, inp, float(np.degrees(rotation_angle(dR))), (inp.truth[:3, 3] - T0[:3, 3]) * 1e3


@pytest.mark.parametrize("seed", range(3))
def test_a_robot_of_each_kind_carries_what_it_planted(tmp_path, seed):
    # the mount's scatter: 0.2 deg per axis, so the angle (chi with 3 dof x 0.2 deg) is < 1 deg but with
    # probability ~2e-5, the translation per axis < 5 x 2 mm; a knock adds FAULT_DEG about the camera's x or y
    bound_deg, bound_mm = 5 * MOUNT_DEG, 5 * MOUNT_MM
    planted, inp, angle, dt = _robot(tmp_path, None, seed)
    assert planted == {} and angle < bound_deg and np.all(np.abs(dt) < bound_mm)
    assert len(inp.observations) == 4 and inp.sigma_px == 0.5
    planted, inp, angle, dt = _robot(tmp_path, "fault", seed)
    assert planted["parameter"] == "T_r_c.rotvec" and abs(planted["shift"]) == FAULT_DEG
    assert abs(angle - FAULT_DEG) < bound_deg and np.all(np.abs(dt) < bound_mm)  # turned about its centre
    planted, inp, angle, dt = _robot(tmp_path, "weak", seed)
    assert angle < bound_deg and len(inp.observations) == planted["placements"] == 2
    assert inp.sigma_px == planted["sigma_px"] == WEAK_NOISE_FACTOR * 0.5


@pytest.mark.parametrize("form", ["images", "markerless"])
def test_a_fleet_is_of_the_point_form(tmp_path, form):
    with pytest.raises(InputError, match="point form only"):
        fleet_member(tmp_path, np.random.default_rng(0), **{form: True})
