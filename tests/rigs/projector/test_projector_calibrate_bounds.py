"""Issue 19, physical bounds; issue 18, sizes: estimates kept physical, memory O(N)."""

import json
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "projector"


def test_narrow_tilt_example_holds_h_at_nominal_and_says_why(tmp_path, capsys):
    code = main(["projector", "calibrate", str(EXAMPLES / "room_A_narrow_tilt.yaml"), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert code == 0, err
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    held = [w for w in res["warnings"] if w["code"] == "parameter_held"]
    assert held and "above H" in held[0]["message"]
    assert "the points span 44.8-49.4 deg of tilt" in held[0]["message"]
    assert "cannot be told apart; add points nearer and farther from the nadir" in held[0]["message"]
    est, std = res["estimate"], res["std"]
    assert est["h"] <= est["H"] and std["h"] is None  # held at nominal: no std
    # the truth errors of every estimated parameter are in the result
    assert set(res["diagnostics"]["truth"]["errors"]) >= {"yaw", "t_x", "t_y", "h", "tilt_offset"}


def test_strict_refuses_an_estimate_outside_its_bounds(tmp_path, capsys):
    code = main(["projector", "calibrate", str(EXAMPLES / "room_A_narrow_tilt.yaml"), "--strict",
                 "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "cannot be told apart" in err, err


def _room_with_tilt_offset(offset_deg: float, seed: int = 4):
    from robocal.rigs.projector.simulate import default_nominal, default_truth, simulate_calibration

    truth = default_truth().with_(offsets=(0.0, math.radians(offset_deg)))
    return simulate_calibration(np.random.default_rng(seed), truth=truth, nominal=default_nominal(truth),
                                n_points=10, sigma=0.005)


def test_tilt_offset_limit_is_configurable():
    """A true 3 deg tilt offset is estimated under the default 5 deg limit and held under a 2 deg one."""
    from robocal.rigs.projector.calibrate import calibrate

    sc = _room_with_tilt_offset(3.0)
    kw = dict(theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=sc.sigma,
              methods=("closed_form", "nonlinear"))
    free = calibrate(sc.points_W, **kw).best
    assert "held" not in free.extra
    # 10 points, 5 mm: std(tilt offset) ~ 0.02 deg; 0.2 deg is > 8 sigma
    assert math.degrees(free.extra["offsets"][1]) == pytest.approx(3.0, abs=0.2)
    run = calibrate(sc.points_W, tilt_offset_limit=math.radians(2.0), **kw)
    assert "tilt_offset" in run.best.extra["held"] and run.best.std["tilt_offset"] is None
    assert run.best.extra["offsets"][1] == 0.0  # the nominal value
    # with the tilt offset held 3 deg off, h compensates past H and is held too: the warning names both
    assert [w for w in run.warnings if w.code == "parameter_held"][0].params[0] == "tilt_offset"


def test_tilt_offset_limit_from_the_input_file(tmp_path, capsys):
    import yaml

    from robocal.rigs.projector.workflow import scenario_document

    doc = scenario_document(_room_with_tilt_offset(3.0))
    doc["tilt_offset_limit"] = {"value": 2, "unit": "deg"}
    f = tmp_path / "in.yaml"
    f.write_text(yaml.safe_dump(doc))
    assert main(["projector", "calibrate", str(f), "--out", str(tmp_path / "cal")]) == 0
    err = capsys.readouterr().err
    assert "parameter_held" in err and "beyond +-2 deg (tilt_offset_limit)" in err, err


def test_consistency_check_memory_is_linear_in_n():
    """20 000 points: the old N x N x 3 difference array alone was 9.6 GB; now the peak stays < 200 MB
    (measured ~60 MB: chunks of N pairs per anchor, the bad pairs capped)."""
    from robocal.rigs.projector.calibrate import distance_consistency

    rng = np.random.default_rng(0)
    pw = np.column_stack([rng.uniform(-5, 5, (20_000, 2)), np.zeros(20_000)])
    p0 = pw + [1.0, 2.0, -2.9]
    p0[:, :2] += rng.normal(0, 0.005, (20_000, 2))
    p0[123, :2] += 0.3  # one gross point
    tracemalloc.start()
    rep = distance_consistency(pw, p0, sigma=0.005)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 200e6, peak
    assert rep.suspects[0] == 123 and rep.n_pairs > 20_000 * 60


def test_calibrate_refuses_in_one_line_when_memory_is_short(tmp_path, capsys, monkeypatch):
    import robocal.resources

    monkeypatch.setattr(robocal.resources, "available_memory", lambda: 10_000)  # 10 kB free
    code = main(["projector", "calibrate", str(EXAMPLES / "room_A.yaml"), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "memory" in err and "8 points" in err, err
    assert not (tmp_path / "cal" / "result.json").exists()
