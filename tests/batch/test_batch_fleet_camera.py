"""``robocal camera simulate --fleet``: what each camera plants is its true camera (:mod:`robocal.rigs.camera.fleet`).

The fleet report naming them is ``tests/batch/test_batch_rig_fleets.py``'s; here, fast, the camera each
robot's session is rendered with (``simulate_session`` replaced by a stub that keeps its arguments), one
session rendered for real, and the lens a fleet cannot simulate.
"""

import numpy as np
import pytest

from robocal.camera import load_camera
from robocal.errors import InputError
from robocal.rigs.camera import simulate
from robocal.rigs.camera.fleet import (CENTRE_FAULT_PX, CENTRE_PX, FOCAL_FAULT, FOCAL_SCATTER, WEAK_BLUR_FACTOR,
                                       WEAK_NOISE_FACTOR, fleet_member)

W, H = 480, 360


@pytest.fixture
def sessions(monkeypatch):
    """The arguments of every ``simulate_session`` call (nothing rendered)."""
    calls = []
    monkeypatch.setattr(simulate, "simulate_session", lambda out_dir, rng, **kw: calls.append(kw))
    return calls


def _camera(sessions, kind, seed):
    planted = fleet_member("unused", np.random.default_rng(seed), kind=kind, views=6, width=W, height=H)
    kw = sessions[-1]
    cam, base = kw["camera"], simulate.default_camera(W, H)
    return planted, kw, cam.fx / base.fx, np.array([cam.cx - base.cx, cam.cy - base.cy]), cam.fy / base.fy


@pytest.mark.parametrize("seed", range(6))
def test_a_camera_of_each_kind_carries_what_it_planted(sessions, seed):
    # the line's scatter is drawn once per camera, bounded here at 5 of its stds (~6e-7 a draw)
    s = W / 640
    planted, kw, f, dc, fy = _camera(sessions, None, seed)
    assert planted == {} and abs(f - 1) < 5 * FOCAL_SCATTER and np.all(np.abs(dc) < 5 * CENTRE_PX * s)
    assert fy == pytest.approx(f, rel=1e-12)  # the pixel pitch is the sensor's: one focal factor for fx and fy
    assert (kw["views"], kw["blur"], kw["noise"]) == (6, 0.7, 2.0)
    planted, kw, f, dc, fy = _camera(sessions, "fault", seed)
    if planted["parameter"] == "fx":  # refocused
        assert abs(abs(f - 1) - FOCAL_FAULT) < 5 * FOCAL_SCATTER and np.all(np.abs(dc) < 5 * CENTRE_PX * s)
        assert np.sign(f - 1) == np.sign(planted["shift"])
    else:  # decentred along one axis
        j = "xy".index(planted["parameter"][1])
        assert abs(abs(dc[j]) - CENTRE_FAULT_PX * s) < 5 * CENTRE_PX * s and abs(dc[1 - j]) < 5 * CENTRE_PX * s
        assert np.sign(dc[j]) == np.sign(planted["shift"]) and abs(f - 1) < 5 * FOCAL_SCATTER
    planted, kw, f, dc, fy = _camera(sessions, "weak", seed)
    assert kw["views"] == planted["views"] == 3
    assert (kw["blur"], kw["noise"]) == pytest.approx((WEAK_BLUR_FACTOR * 0.7, WEAK_NOISE_FACTOR * 2.0))


def test_both_lens_faults_occur(sessions):
    stories = {fleet_member("unused", np.random.default_rng(seed), kind="fault")["parameter"] for seed in range(12)}
    assert "fx" in stories and stories & {"cx", "cy"}


def test_the_session_is_rendered_with_the_planted_camera(tmp_path):
    planted = fleet_member(tmp_path, np.random.default_rng(1), kind="fault", views=3, width=320, height=240)
    truth = load_camera(tmp_path / "camera_truth.yaml")
    base = simulate.default_camera(320, 240)
    shift = {"fx": truth.fx - base.fx, "cx": truth.cx - base.cx, "cy": truth.cy - base.cy}[planted["parameter"]]
    # the planted shift plus the line's scatter (5 of its stds; focal: 1.05 x its 0.3 %)
    assert abs(shift - planted["shift"]) < 5 * max(1.05 * FOCAL_SCATTER * base.fx, CENTRE_PX * 320 / 640)
    assert len(list((tmp_path / "images").glob("*.png"))) == 3 and (tmp_path / "camera_input.yaml").is_file()


def test_a_fleet_is_of_pinhole_cameras(tmp_path):
    with pytest.raises(InputError, match="pinhole cameras .* only, got --lens fisheye"):
        fleet_member(tmp_path, np.random.default_rng(0), lens="fisheye")
