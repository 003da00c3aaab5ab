"""Hand-eye slips (issue 18) named in one line, exit 2; hand-eye errors name the files.

The example pose lists (examples/lineprofiler/gripper_poses.csv, target_poses.csv) give a closure
rotation residual of 0.72 mrad and a translation residual of 0.2-0.3 mm, consistent with each other
(ratio ~1, see robocal.rigs.lineprofiler.handeye.TRANS_ROT_RATIO_MAX); each slip below breaks that
by orders of magnitude, so the figures asserted are far from the bounds.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import ImplausibleInputError
from robocal.geometry import invert_transform
from robocal.rigs.lineprofiler.handeye import calibrate_hand_eye, calibrate_robot_world, judge_poses
from robocal.rigs.lineprofiler.io import load_poses, write_poses_csv

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def poses():
    Tg, tg = load_poses(EX / "gripper_poses.csv")
    Tc, _ = load_poses(EX / "target_poses.csv")
    return Tg, Tc, tg


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
    # target times outside the robot stream: the interpolation names both files
    late = write_poses_csv(tmp_path / "late.csv", Tc, t + 100.0)
    code = main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(late), "--out", str(tmp_path / "c")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "gripper_poses.csv resampled at the times of" in line and "late.csv" in line
    # rotations about one axis only: degenerate, named with the files
    from robocal.geometry import matrix_from_rotvec, transform_from

    ang = np.linspace(0, 1, 6)
    R = matrix_from_rotvec(np.outer(ang, [0, 0, 1.0]))
    deg = write_poses_csv(tmp_path / "planar.csv", transform_from(R, np.outer(ang, [0.1, 0, 0])))
    code = main(["handeye", "calibrate", str(deg), str(deg), "--out", str(tmp_path / "d")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "planar.csv" in line and "parallel axes" in line


@pytest.mark.parametrize("radius, slip, fix", [
    ("0.0254", "radius_m_as_mm", "with x1000"),      # metres under `units: {length: mm}`
    ("50.8", "radius_is_diameter", "with /2"),       # the sphere's diameter
])
def test_sphere_radius_slips_are_named(tmp_path, capsys, radius, slip, fix):
    # were: T_E_L 230 mm / 1.7 m off with exit 0 and only solver warnings
    (tmp_path / "fpdp_profiles.csv").write_bytes((EX / "fpdp_profiles.csv").read_bytes())
    text = (EX / "fpdp_input.yaml").read_text().replace("sphere_radius: 25.4000", f"sphere_radius: {radius}")
    (tmp_path / "in.yaml").write_text(text)
    code = main(["lineprofiler", "calibrate", str(tmp_path / "in.yaml"), "--out", str(tmp_path / "o")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "in.yaml" in line and "`sphere_radius`" in line and f"{fix} the FPDP residual drops" in line
    # the example's own FPDP residual (0.16 mm, arm and joint noise) once undone
    assert float(line.split(" to ")[1].split(" mm")[0]) < 0.5


def test_sphere_radius_slip_can_be_accepted(tmp_path, capsys):
    from robocal.rigs.lineprofiler.calibrate import judge_sphere
    from robocal.rigs.lineprofiler.fpdp import fpdp_calibrate
    from robocal.rigs.lineprofiler.io import load_profiles_csv
    from robocal.rigs.lineprofiler.model import p1r2p3_chain

    ch = p1r2p3_chain()
    prof, q, _ = load_profiles_csv(EX / "fpdp_profiles.csv", dof=ch.dof, joint_types=ch.joint_types)
    f = fpdp_calibrate(q, prof, ch, 0.0254)
    assert judge_sphere(q, prof, ch, 0.0254, f) is None
    # profile points in m under an [mm] header: every circle 1000 x too small against the sphere
    small = [p * 1e-3 for p in prof]
    g = fpdp_calibrate(q, small, ch, 0.0254)
    d = judge_sphere(q, small, ch, 0.0254, g, accept=True)
    assert d.code == "implausible_input" and d.params == ("profiles_m_as_mm",)


def _mct_copy(tmp_path):
    for f in ("mct_input.yaml", "mct_arc.csv", "mct_line.csv", "mct_block.csv", "mct_scan.csv"):
        (tmp_path / f).write_bytes((EX / f).read_bytes())


def _edit_columns(path, fn):
    lines = path.read_text().splitlines()
    rows = [", ".join(fn(i, v) for i, v in enumerate(ln.split(", "))) for ln in lines[1:]]
    path.write_text("\n".join([lines[0]] + rows) + "\n")


def test_mct_tracker_in_metres_is_named(tmp_path, capsys):
    # the line's tracker coordinates written in m under 'x [mm]': the ball would move 1000 x less than P3
    _mct_copy(tmp_path)
    _edit_columns(tmp_path / "mct_line.csv", lambda i, v: v if i < 3 else f"{float(v) / 1000:.8f}")
    code = main(["lineprofiler", "calibrate", str(tmp_path / "mct_input.yaml"), "--out", str(tmp_path / "o")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "x, y, z of mct_line.csv look like m, not mm" in line and "with x1000" in line


def test_mct_joint_angles_in_radians_are_named(tmp_path, capsys):
    _mct_copy(tmp_path)
    _edit_columns(tmp_path / "mct_arc.csv", lambda i, v: f"{np.radians(float(v)):.8f}" if i == 1 else v)
    code = main(["lineprofiler", "calibrate", str(tmp_path / "mct_input.yaml"), "--out", str(tmp_path / "o")])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "the R2 readings of mct_arc.csv look like rad, not deg: with rad -> deg" in line
    # the example's own ratios are 1 within 0.03 % (tracker noise ~10 um over a 100 mm stroke)
    assert float(line.split(" to ")[1].split(" %")[0]) < 1.0
