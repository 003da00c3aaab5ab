"""The committed example recording and the page that uses it (docs/bags.md) stay true."""

import re
from pathlib import Path

import numpy as np

import robocal.bags as bags
from robocal.bags._simulate import T0_NS, _base_tool, _odom_base
from robocal.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "bags" / "sim.bag"
DOC = ROOT / "docs" / "bags.md"


def test_example_is_small_and_matches_its_truth():
    assert EXAMPLE.stat().st_size < 300_000
    base = bags.poses(EXAMPLE, "odom", "base_link", show_progress=False)
    tool = bags.poses(EXAMPLE, "base_link", "tool0", show_progress=False)
    # the trajectories the simulator wrote, evaluated at the stamps read (1e-12: float64 rounding only)
    for ps, fn in ((base, _odom_base), (tool, _base_tool)):
        assert len(ps.stamps_ns) > 50
        assert np.max(np.abs(ps.T - fn((ps.stamps_ns - T0_NS) / 1e9))) < 1e-12


def test_docs_inspect_output_is_what_the_command_prints(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert main(["bag", "inspect", "examples/bags/sim.bag", "--no-progress"]) == 0
    out = capsys.readouterr().out.strip()
    shown = re.search(r"```\n(recording: examples/bags/sim.bag.*?)```", DOC.read_text(encoding="utf-8"), re.S).group(1)
    assert out == shown.strip()


def test_docs_python_example_runs(monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    code = re.search(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S).group(1)
    scope = {}
    exec(compile(code, str(DOC), "exec"), scope)
    assert scope["base"].gap.max() == 0.01 and scope["camera"].width == 128
    assert "/camera/image_raw@1700000000.500000000 (96, 128) uint8" in capsys.readouterr().out


def test_example_images_and_camera_info_give_the_board_poses():
    # the images through the bag, the camera from its CameraInfo, detection + PnP: the simulated board poses.
    # Measured: <= 1.0 mm and 0.55 deg on these 128x96 images (9 px squares, grey-level noise 2); limits 3x that.
    from scipy.spatial.transform import Rotation

    from robocal.bags._simulate import board_poses
    from robocal.camera import Checkerboard, detect_checkerboard, solve_pnp
    from robocal.geometry import invert_transform

    cam = bags.read_camera_info(EXAMPLE, "/camera/camera_info")
    board = Checkerboard(rows=5, cols=7, square=0.03)
    frames = list(bags.images(EXAMPLE, "/camera/image_raw", show_progress=False))
    for (_, img), T in zip(frames, board_poses(len(frames)), strict=True):
        uv = detect_checkerboard(img, board, expected_uv=cam.project_points(board.object_points(), T))
        D = invert_transform(T) @ solve_pnp(cam, board.object_points(), uv).T_cam_obj
        assert np.linalg.norm(D[:3, 3]) < 3e-3 and Rotation.from_matrix(D[:3, :3]).magnitude() < np.radians(1.5)
