"""The fleet report names the planted faulty robot (mechanical) and the weak recording, and no one else."""

import json
import re

import numpy as np
from batch_toy import write_fleet

from robocal.batch import fleet_summary, load_manifest, run_batch
from robocal.batch._fleet import MIN_FLEET, STANDOUT
from robocal.io import CalibrationResult


def test_planted_fault_and_weak_recording_are_named(tmp_path, toy):
    # 12 robots: true a scattered by 2e-4 rad, per-robot std ~1.8e-4 rad (30 samples of 1e-3); r07 has a
    # 0.05 rad (2.9 deg) offset, r03 was recorded with 10x the noise
    manifest = write_fleet(tmp_path / "in", 12, seed=4, planted={"r07": 0.05}, weak={"r03"}, fail={"r10"})
    out = tmp_path / "out"
    outcome = run_batch(toy, load_manifest(manifest), out)
    fleet = json.loads((out / "fleet.json").read_text())
    assert fleet["n_robots"] == 11 and fleet["failed"] == [{"id": "r10", "error": outcome.failed[0]["error"]}]
    mech = [(s["id"], s["parameter"]) for s in fleet["standouts"] if s["cause"] == "mechanical"]
    assert mech == [("r07", "a")]
    s = fleet["standouts"][0]
    assert s["id"] == "r07" and s["robust_sigmas"] > 50 and s["own_stds"] > 100
    # 0.01 + 0.05 rad = 3.4 deg, 0.05 rad = 2.9 deg less this robot's own scatter from the median
    assert re.match(r"r07: a \+3\.4 deg, \+2\.[89] deg from the fleet median, \d+ x the fleet's spread", s["text"])
    assert s["text"].endswith("a mechanical cause, not noise")
    # the weak recording: its std ~10x the fleet's; if it also strays it is called noise, never mechanical
    assert [w["id"] for w in fleet["weak"]] == ["r03"] and 5 < fleet["weak"][0]["std_ratio"] < 20
    assert all(x["cause"] == "noise" for x in fleet["standouts"] if x["id"] == "r03")
    assert {x["id"] for x in fleet["standouts"]} <= {"r07", "r03"}
    a = fleet["parameters"]["a"]
    assert a["unit"] == "deg" and abs(a["median"] - np.degrees(0.01)) < 0.1  # r07 does not move the median
    html = (out / "fleet.html").read_text()
    assert "r07: a +3.4 deg" in html and "a weak recording" in html and "r10" in html and "data:image/png" in html


def test_a_small_fleet_names_no_one():
    res = {f"x{i}": CalibrationResult(rig="toy", method="m", estimate={"a": 0.01 * i}, std={"a": 1e-6},
                                      units={"a": "rad"}) for i in range(MIN_FLEET - 1)}
    summary = fleet_summary(res)
    assert summary["standouts"] == [] and summary["weak"] == []


def test_vectors_are_compared_per_element_and_identical_robots_are_not_named_for_noise():
    rng = np.random.default_rng(1)
    # 8 identical arms: their estimates differ by noise alone (std 1e-3 m); the MAD of 8 is itself
    # noisy, so the fleet is judged by max(robust sigma, median std) and no one stands out at 4
    res = {f"arm{i}": CalibrationResult(rig="handeye", method="m",
                                        estimate={"X.translation": (np.array([0.1, 0.2, 0.3]) + 1e-3 * rng.standard_normal(3)).tolist()},
                                        std={"X.translation": [1e-3] * 3}, units={"X.translation": "m"})
           for i in range(8)}
    summary = fleet_summary(res)
    assert list(summary["parameters"]) == ["X.translation.x", "X.translation.y", "X.translation.z"]
    assert summary["parameters"]["X.translation.y"]["unit"] == "mm"
    assert summary["standouts"] == [] and STANDOUT == 4.0
