"""Line-profiler slips (issue 18) named in one line, exit 2: the sphere radius, MCT units.

(The hand-eye pose-list slips are tested with the core package, tests/handeye.)
"""

from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


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
