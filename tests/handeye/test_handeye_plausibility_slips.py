"""Hand-eye slips (issue 18) named in one line, exit 2; hand-eye errors name the files.

The example pose lists (examples/lineprofiler/gripper_poses.csv, target_poses.csv) give a closure
rotation residual of 0.72 mrad and a translation residual of 0.2-0.3 mm, consistent with each other
(ratio ~1, see robocal.handeye.TRANS_ROT_RATIO_MAX); each slip below breaks that
by orders of magnitude, so the figures asserted are far from the bounds.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import ImplausibleInputError
from robocal.geometry import invert_transform
from robocal.handeye import calibrate_hand_eye, calibrate_robot_world, judge_poses
from robocal.io import load_poses
from robocal.io import write_poses as write_poses_csv

EX = Path(__file__).resolve().parents[2] / "examples" / "lineprofiler"


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def poses():
    g = load_poses(EX / "gripper_poses.csv")
    return g.T, load_poses(EX / "target_poses.csv").T, g.t


def _target_in_mm(tmp_path, poses):
    Tg, Tc, t = poses
    T = Tc.copy()
    T[:, :3, 3] *= 1000.0                       # written under the file's 'x [m]' header
    return write_poses_csv(tmp_path / "target_mm.csv", T, t)


@pytest.mark.parametrize("command", ["calibrate", "robot-world"])
def test_target_translations_in_mm_are_named(tmp_path, capsys, poses, command):
    # was: a camera 110 m from the gripper, no warning
    bad = _target_in_mm(tmp_path, poses)
    code = main(["handeye", command, str(EX / "gripper_poses.csv"), str(bad), "--out", str(tmp_path / "o")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and not (tmp_path / "o" / "result.json").exists()
    assert "x, y, z of target_mm.csv look like mm, not m: with /1000 the translation residual drops from" in line
    after = float(line.split(" to ")[1].split(" mm")[0])
    assert after < 1.0                           # the example's own residual (0.3 mm), not metres


def test_accepted_slip_is_written_with_a_warning(tmp_path, capsys, poses):
    bad = _target_in_mm(tmp_path, poses)
    code = main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(bad), "--out", str(tmp_path / "o"),
                 "--accept-implausible"])
    assert code == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    w = [w for w in res["warnings"] if w["code"] == "implausible_input"]
    assert len(w) == 1 and "target_mm.csv look like mm" in w[0]["message"]


def test_slips_of_the_library(poses):
    Tg, Tc, _ = poses
    assert judge_poses(Tg, Tc) == []             # the example is plausible
    Tm = Tg.copy()
    Tm[:, :3, 3] *= 1000.0
    with pytest.raises(ImplausibleInputError) as e:
        calibrate_hand_eye(Tm, Tc)
    assert e.value.slip == "gripper_mm_as_m"
    Tx = Tc.copy()
    Tx[:, :3, 3] /= 1000.0                       # metres declared mm
    with pytest.raises(ImplausibleInputError) as e:
        calibrate_hand_eye(Tg, Tx)
    assert e.value.slip == "target_m_as_mm"
    # T_target_cam given as T_cam_target: the rotation residual grows 100 x; this set (wrist rolls about
    # one axis plus vertical turns) cannot tell a target inversion from a gripper one, so both are named
    with pytest.raises(ImplausibleInputError) as e:
        calibrate_robot_world(invert_transform(Tc), invert_transform(Tg))
    assert e.value.slip == "target_poses_inverted" and "gripper_poses_inverted" in str(e.value)


def test_handeye_errors_name_the_files(tmp_path, capsys, poses):
    Tg, Tc, t = poses
    short = write_poses_csv(tmp_path / "target_short.csv", Tc[:2], t[:2])
    code = main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(short), "--out", str(tmp_path / "a")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "gripper_poses.csv" in line and "target_short.csv" in line and "at least 3 poses" in line
    # no timestamps, different counts
    a = write_poses_csv(tmp_path / "g.csv", Tg)
    b = write_poses_csv(tmp_path / "c.csv", Tc[:10])
    code = main(["handeye", "robot-world", str(a), str(b), "--out", str(tmp_path / "b")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "g.csv has 16 poses but" in line and "c.csv has 10" in line
    # target times outside the robot stream: no overlap to crop to, the pairing names both files and the spans
    late = write_poses_csv(tmp_path / "late.csv", Tc, t + 100.0)
    code = main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(late), "--out", str(tmp_path / "c")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "gripper_poses.csv paired by time with" in line and "late.csv" in line
    assert "overlap in 0 camera sample(s)" in line and "--clock-offset" in line
    # rotations about one axis only: degenerate, named with the files
    from robocal.geometry import matrix_from_rotvec, transform_from

    ang = np.linspace(0, 1, 6)
    R = matrix_from_rotvec(np.outer(ang, [0, 0, 1.0]))
    deg = write_poses_csv(tmp_path / "planar.csv", transform_from(R, np.outer(ang, [0.1, 0, 0])))
    code = main(["handeye", "calibrate", str(deg), str(deg), "--out", str(tmp_path / "d")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "planar.csv" in line and "parallel axes" in line
