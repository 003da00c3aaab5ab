"""The lineprofiler commands on the example files, their errors, the demo."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import FileFormatError, ShapeError
from robocal.io import load_result
from robocal.rigs.lineprofiler.calibrate import calibrate_file
from robocal.rigs.lineprofiler.cli import RIG
from robocal.workflow import DemoContext
from report_pages import bare_matrices, rebuilt_equal

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"


def test_calibrate_example_names_undetermined_component(tmp_path, capsys):
    cal = tmp_path / "cal"
    assert main(["lineprofiler", "calibrate", str(EX / "fpdp_input.yaml"), "--out", str(cal)]) == 0
    assert "T_E_L translation [mm] (fpdp+geometric): 34.982 +/- 0.033, undetermined, 119.996 +/- 0.056" \
        in capsys.readouterr().out
    res = json.loads((cal / "result.json").read_text())
    assert res["estimate"]["T_E_L.translation"][1] is None  # never a silent 0
    assert res["std"]["T_E_L.translation"][1] is None and res["estimate"]["fpdp.T_E_L.translation"][1] is None
    assert "X.ty" in res["diagnostics"]["undetermined"]
    assert any(w["code"] == "rank_deficient" for w in res["warnings"])
    assert abs(res["estimate"]["T_E_L.translation"][0] - 0.035) < 2e-4
    result = load_result(cal / "result.json")
    assert list(result.poses) == ["T_E_L", "fpdp.T_E_L"] and bare_matrices(result) == []
    assert result.poses["T_E_L"] == {"rotation_std": "left", "parent": "end effector E", "child": "laser L"}
    # the rebuilt report keeps the sections drawn from the fit (they were lost on 'report' before)
    page = rebuilt_equal(cal, tmp_path / "rep", "lineprofiler", capsys)
    for title in ("Residuals", "FPDP circle cuts (seed Table 1)", "Solver (geometric refinement)",
                  "T_E_L rotation vector x"):
        assert title in page, title


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


def test_rigs_registered_and_demo(tmp_path):
    assert RIG.name == "lineprofiler"
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
    result = load_result(tmp_path / "result.json")
    # the intermediate frames are poses too, derived: no std of their own
    assert list(result.poses) == ["T_E_L", "T_T_L", "T_T_E", "T_T_B", "T_L_B"] and bare_matrices(result) == []
    assert result.pose("T_T_L").std_rotation is None
    np.testing.assert_allclose(result.pose("T_T_E").T @ result.pose("T_E_L").T, result.pose("T_T_L").T,
                               atol=1e-12)  # eq. 5, X = T_T_E^-1 T_T_L: rounding only
    page = rebuilt_equal(tmp_path, tmp_path / "rep", "lineprofiler", capsys)
    assert "P3 encoder sigma per scan profile 5.0 um" in page and "block-scan fit residuals" in page


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


def test_mct_arm_sigma_enters_the_covariance(tmp_path):
    yaml_path = _mct_copy(tmp_path)
    yaml_path.write_text(yaml_path.read_text().replace("# arm_sigma: {length: 0.3", "arm_sigma: {length: 0.3"))
    assert main(["lineprofiler", "calibrate", str(yaml_path), "--out", str(tmp_path / "o")]) == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["diagnostics"]["arm_dh_sigma"] == pytest.approx({"length_m": 3e-4, "angle_rad": np.deg2rad(0.1)})
    # 0.3 mm of arm error dominates the 0.03-0.08 mm the tracker and the scan leave
    assert all(v > 2.5e-4 for v in np.array(res["std"]["T_E_L.translation"])[[0, 2]])
