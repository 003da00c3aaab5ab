"""Issue 18, slips: each input quantity with a physical scale that is off by a likely slip is named in one line
(exit 2), through the CLI; ``--accept-implausible`` goes on with an ``implausible_input`` warning."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "projector"


def _room() -> dict:
    return yaml.safe_load((EXAMPLES / "room_A.yaml").read_text())  # units: mm, deg


def _world_mm_as_m(d):
    d["points"]["world"] = {"value": d["points"]["world"], "unit": "m"}


def _world_m_as_mm(d):
    d["points"]["world"] = {"value": (np.array(d["points"]["world"]) / 1000).tolist(), "unit": "mm"}


def _world_cm_as_mm(d):
    d["points"]["world"] = {"value": (np.array(d["points"]["world"]) / 10).tolist(), "unit": "mm"}


def _H_mm_as_m(d):
    for k in ("H", "d1", "d2"):
        d["projector"][k]["unit"] = "m"


def _angles_rad_as_deg(d):
    d["points"]["joint_angles"] = {"value": np.radians(d["points"]["joint_angles"]).tolist(), "unit": "deg"}


def _world_xy_swapped(d):
    d["points"]["world"] = np.array(d["points"]["world"])[:, ::-1].tolist()


def _angles_swapped(d):
    d["points"]["joint_angles"] = np.array(d["points"]["joint_angles"])[:, ::-1].tolist()


def _angles_deg_as_rad(d):
    d["points"]["joint_angles"] = {"value": d["points"]["joint_angles"], "unit": "rad"}


# (edit of room_A.yaml, the start of the expected one-line message)
SLIPS = {
    "world_mm_as_m": (_world_mm_as_m, "`points.world` looks like mm declared as m (1000x too large): with /1000 "
                                      "the median residual drops from"),
    "world_m_as_mm": (_world_m_as_mm, "`points.world` looks like m declared as mm (1000x too small): with x1000"),
    "world_cm_as_mm": (_world_cm_as_mm, "`points.world` looks like cm declared as mm (10x too small): with x10"),
    "H_mm_as_m": (_H_mm_as_m, "`projector.H` (and d1) look like mm declared as m (1000x too large): with /1000"),
    "angles_rad_as_deg": (_angles_rad_as_deg, "`points.joint_angles` look like rad declared as deg: read as rad"),
    "world_xy_swapped": (_world_xy_swapped, "`points.world` x and y look swapped (a mirror image: no rotation fits): "
                                            "with x and y swapped back the median residual drops from"),
    "angles_swapped": (_angles_swapped, "`points.joint_angles` columns look swapped"),
    # degrees read as rad put most tilts beyond the horizon: the loader's check names the unit first
    "angles_deg_as_rad": (_angles_deg_as_rad, "degrees declared as rad?"),
}


def _write(tmp_path, edit) -> Path:
    d = _room()
    edit(d)
    f = tmp_path / "slip.yaml"
    f.write_text(yaml.safe_dump(d, sort_keys=False))
    return f


@pytest.mark.parametrize("name", sorted(SLIPS))
def test_each_slip_is_named_in_one_line_with_exit_2(tmp_path, capsys, name):
    edit, needle = SLIPS[name]
    f = _write(tmp_path, edit)
    code = main(["projector", "calibrate", str(f), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("robocal: error:") and err.count("\n") == 1 and needle in err, err
    assert "Traceback" not in err


def test_accept_implausible_goes_on_with_a_warning(tmp_path, capsys):
    f = _write(tmp_path, _world_xy_swapped)
    code = main(["projector", "calibrate", str(f), "--accept-implausible", "--out", str(tmp_path / "cal")])
    assert code == 0, capsys.readouterr().err
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    w = [w for w in res["warnings"] if w["code"] == "implausible_input"]
    assert w and "x and y look swapped" in w[0]["message"]


def test_the_unchanged_example_is_plausible(tmp_path, capsys):
    """The checks cost nothing on good data and raise nothing (room_A: 8 points, 5 mm noise)."""
    code = main(["projector", "calibrate", str(EXAMPLES / "room_A.yaml"), "--out", str(tmp_path / "cal")])
    assert code == 0
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert not [w for w in res["warnings"] if w["code"] == "implausible_input"]
    assert math.isfinite(res["residual_rms"])
