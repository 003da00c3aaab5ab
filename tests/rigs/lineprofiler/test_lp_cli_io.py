"""CLI on the example files, file formats and their errors, pose interpolation, the demo."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import FileFormatError, InputError, ShapeError
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.rigs.lineprofiler.calibrate import calibrate_file
from robocal.rigs.lineprofiler.cli import HANDEYE, RIG
from robocal.workflow import DemoContext
from robocal.io import load_result
from robocal.rigs.lineprofiler.io import (
    interpolate_poses,
    load_block_faces_csv,
    load_poses,
    load_profiles_csv,
    write_poses_csv,
)

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"


def test_calibrate_example_names_undetermined_component(tmp_path, capsys):
    assert main(["lineprofiler", "calibrate", str(EX / "fpdp_input.yaml"), "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["estimate"]["T_E_L.translation"][1] is None  # never a silent 0
    assert "X.ty" in res["diagnostics"]["undetermined"]
    assert any(w["code"] == "rank_deficient" for w in res["warnings"])
    assert abs(res["estimate"]["T_E_L.translation"][0] - 0.035) < 2e-4
    assert (tmp_path / "report.html").stat().st_size > 10000
    assert main(["lineprofiler", "report", str(tmp_path / "result.json"), "--out", str(tmp_path / "r")]) == 0


def test_calibrate_with_joint_sigma(tmp_path):
    for f in ("fpdp_input.yaml", "fpdp_profiles.csv"):
        (tmp_path / f).write_bytes((EX / f).read_bytes())
    y = tmp_path / "fpdp_input.yaml"
    y.write_text(y.read_text() + "joint_sigma: [0.02, 0.00035, 0.02]  # mm, rad (no angle unit given), mm\n")
    assert main(["lineprofiler", "calibrate", str(y), "--out", str(tmp_path / "o")]) == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    d = res["diagnostics"]
    assert d["joint_noise_modelled"] and len(d["joint_corrections"]) == d["n_profiles_used"]
    assert res["estimate"]["T_E_L.translation"][1] is None and res["std"]["T_E_L.translation"][1] is None
    assert abs(res["estimate"]["T_E_L.translation"][0] - 0.035) < 4 * res["std"]["T_E_L.translation"][0]
    y.write_text(y.read_text().replace("joint_sigma: [0.02, 0.00035, 0.02]", "joint_sigma: [0.02, -0.1, 0.02]"))
    with pytest.raises(FileFormatError, match="joint_sigma"):
        calibrate_file(y)
    y.write_text(y.read_text().replace("joint_sigma: [0.02, -0.1, 0.02]", "joint_sigma: [0.02, 0.1]"))
    with pytest.raises(ShapeError, match="joint_sigma"):
        calibrate_file(y)


def test_handeye_example(tmp_path):
    assert main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--method", "park", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert np.allclose(res["estimate"]["T_gripper_cam.translation"], [0.035, 0.06, 0.12], atol=2e-3)


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "p.csv"
    bad.write_text("t [s], x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 0.5, 0.5\n")
    assert main(["handeye", "calibrate", str(bad), str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unit quaternion" in capsys.readouterr().err


def test_pose_files_errors(tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, nan, 0, 0, 0, 1\n")
    with pytest.raises(FileFormatError, match="nan"):
        load_poses(f)
    y = tmp_path / "p.yaml"
    y.write_text("units: {length: mm}\nposes:\n  - {p: [1, 2, 3], R: [[1, 0, 0], [0, 1, 0], [0, 0.1, 1]]}\n")
    with pytest.raises(FileFormatError, match="rotation matrix"):
        load_poses(y)
    y.write_text("units: {length: mm, time: s}\nposes:\n  - {p: [1, 2, 3], q: [0, 0, 0, 1], t: 0.5}\n")
    T, t = load_poses(y)
    assert np.allclose(T[0, :3, 3], [1e-3, 2e-3, 3e-3]) and t[0] == 0.5


def test_profiles_csv_round_trip_and_errors(tmp_path):
    profiles, q, t = load_profiles_csv(EX / "fpdp_profiles.csv", dof=3)
    assert len(profiles) == len(q) == 16 and t is None
    assert 0.15 < profiles[0][:, 1].mean() < 0.4  # z in metres
    f = tmp_path / "x.csv"
    f.write_text("profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n0, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match="differ between its rows"):
        load_profiles_csv(f)
    f.write_text("profile, x [mm], z [mm], q1\n0, 1, 2, 3\n")
    with pytest.raises(FileFormatError, match="needs a unit"):
        load_profiles_csv(f)


def test_csv_errors_name_the_file_line(tmp_path):
    """Comments and blank lines before the data: messages name the file line, not the data row."""
    head = "# exported by the tracker\n\n"
    f = tmp_path / "faces.csv"
    f.write_text(head + "face, x [mm], y [mm], z [mm]\n0, 1, 2, 3\n# probe re-seated\n4, 1, 2, 3\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 6\): column 'face' must be 0, 1 or 2"):
        load_block_faces_csv(f)
    f = tmp_path / "poses.csv"
    f.write_text(head + "x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 1\n0, 0, 0, 0, 0, 0.5, 0.5\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 5\): quaternion"):
        load_poses(f)
    f = tmp_path / "prof.csv"
    f.write_text(head + "profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n\n0, 1, 2, 4\n-1, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match=r"row 3 \(line 7\): column 'profile'"):
        load_profiles_csv(f)
    f.write_text(head + "profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n\n0, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 6\) against its first, row 1 \(line 4\)"):
        load_profiles_csv(f)


def test_slerp_interpolation_between_streams(tmp_path):
    t = np.array([0.0, 1.0, 2.0])
    T = transform_from(matrix_from_rotvec([[0, 0, 0], [0, 0, 0.4], [0, 0, 0.8]]), [[0, 0, 0], [1, 0, 0], [2, 0, 0]])
    write_poses_csv(tmp_path / "s.csv", T, t)
    T2, t2 = load_poses(tmp_path / "s.csv")
    Ti = interpolate_poses(t2, T2, [0.5, 1.75])
    assert np.allclose(Ti[0], transform_from(matrix_from_rotvec([0, 0, 0.2]), [0.5, 0, 0]), atol=1e-9)
    assert np.allclose(Ti[1, :3, 3], [1.75, 0, 0])
    with pytest.raises(InputError, match="no extrapolation"):
        interpolate_poses(t, T, [2.5])
    with pytest.raises(InputError, match="counts must match"):
        interpolate_poses(t[:2], T, [0.5])


def test_rigs_registered_and_demo(tmp_path):
    assert RIG.name == "lineprofiler" and HANDEYE.name == "handeye"
    out = RIG.step("demo")(DemoContext(tmp_path, np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    assert "undetermined" in out.summary


def test_calibrate_mct_example(tmp_path, capsys):
    assert main(["lineprofiler", "calibrate", str(EX / "mct_input.yaml"), "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["method"] == "mct" and not res["diagnostics"]["undetermined"]
    t = np.array(res["estimate"]["T_E_L.translation"])
    st = np.array(res["std"]["T_E_L.translation"])
    assert np.all((st > 5e-6) & (st < 3e-4))
    assert np.all(np.abs(t - [0.035, 0.06, 0.12]) < 4 * st)  # simulated truth in the file's comment
    assert "+/-" in capsys.readouterr().out
    d = res["diagnostics"]
    assert d["encoder_sigma_m"] == 5e-6  # the documented default
    assert set(d["covariance"]["std_by_source"]) == {"tracker", "heights", "block scan", "P3 encoder"}
    assert main(["lineprofiler", "report", str(tmp_path / "result.json"), "--out", str(tmp_path / "r")]) == 0
    assert "P3 encoder sigma per scan profile 5.0 um" in (tmp_path / "r" / "report.html").read_text()


def _mct_copy(tmp_path):
    for f in EX.glob("mct_*"):
        (tmp_path / f.name).write_bytes(f.read_bytes())
    return tmp_path / "mct_input.yaml"


@pytest.mark.parametrize("file, edit, message", [
    ("mct_block.csv", lambda s: s.replace("\n2, ", "\n3, ", 1), "must be 0, 1 or 2"),
    ("mct_block.csv", lambda s: "\n".join(ln for ln in s.splitlines() if not ln.startswith("1, ") or
                                          ln.endswith("0")) + "\n", "face 1 has"),
    ("mct_arc.csv", lambda s: s.replace("q1 [mm], q2 [deg], q3 [mm]", "a [mm], b [deg], c [mm]"), "joint columns"),
    ("mct_input.yaml", lambda s: s.replace("sigma: 0.02", "sigma: -0.02"), "heights.sigma"),
    ("mct_input.yaml", lambda s: s.replace("block_size: [60.000", "block_size: [0"), "block_size"),
    ("mct_input.yaml", lambda s: s.replace("method: mct", "method: tracker"), "method"),
    ("mct_input.yaml", lambda s: s.replace("# arm_sigma: {length: 0.3", "arm_sigma: {length: -0.3"), "arm_sigma"),
    ("mct_input.yaml", lambda s: s.replace("# encoder_sigma: 0.005", "encoder_sigma: -0.005"), "encoder_sigma"),
    ("mct_scan.csv", lambda s: s.replace("\n0, ", "\n0.5, ", 1), "line 2"),
    ("mct_scan.csv", lambda s: s.replace("q3 [mm]", "q3 [deg]"), "joint 3 is prismatic"),
    ("mct_arc.csv", lambda s: "\n".join(s.splitlines()[:3]) + "\n", "mct_arc.csv: 2 tracker reading(s)"),
])
def test_mct_input_errors_are_one_line(tmp_path, capsys, file, edit, message):
    yaml_path = _mct_copy(tmp_path)
    f = tmp_path / file
    f.write_text(edit(f.read_text()))
    assert main(["lineprofiler", "calibrate", str(yaml_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_handeye_robot_world_example(tmp_path, capsys):
    # the same two pose lists give AX = ZB: T_gripper_cam and T_base_target together
    assert main(["handeye", "robot-world", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["method"] == "robot-world shah+refine"
    result = load_result(tmp_path / "result.json")
    T = result.pose("T_gripper_cam").T
    assert np.allclose(T[:3, 3], [0.035, 0.06, 0.12], atol=2e-3)  # 0.2 mm / 1 mrad pose noise, 16 poses
    assert all(v is not None and 0 < v < 3e-3 for v in res["std"]["T_cam_gripper.translation"])
    assert np.allclose(result.pose("T_base_target").T @ result.pose("T_target_base").T, np.eye(4), atol=1e-12)
    # the inverses carry their std too (first order through the inverse), and the CLI prints it
    st = np.array(res["std"]["T_gripper_cam.translation"])
    assert np.all((st > 0) & (st < 3e-3)) and len(res["std"]["T_gripper_cam.rotvec"]) == 3
    assert np.all(np.abs(T[:3, 3] - [0.035, 0.06, 0.12]) < 4 * st)
    assert "+/-" in capsys.readouterr().out


def test_mct_arm_sigma_enters_the_covariance(tmp_path):
    yaml_path = _mct_copy(tmp_path)
    yaml_path.write_text(yaml_path.read_text().replace("# arm_sigma: {length: 0.3", "arm_sigma: {length: 0.3"))
    assert main(["lineprofiler", "calibrate", str(yaml_path), "--out", str(tmp_path / "o")]) == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["diagnostics"]["arm_dh_sigma"] == pytest.approx({"length_m": 3e-4, "angle_rad": np.deg2rad(0.1)})
    # 0.3 mm of arm error dominates the 0.03-0.08 mm the tracker and the scan leave
    assert all(v > 2.5e-4 for v in np.array(res["std"]["T_E_L.translation"])[[0, 2]])
