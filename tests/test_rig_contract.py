"""The rig contract, checked for every registered rig (a new rig gets these checks by registering).

For each :class:`robocal.workflow.Workflow` in the ``robocal.rigs`` entry-point
group: ``simulate -> calibrate -> report`` through the ``robocal`` program, the
rebuilt report equal to the first, ``robocal report RESULT.json`` dispatching
on the rig, the result in the shared vocabulary (``docs/results.md``), one-line
exit-2 errors on bad input, and a declaration that imports nothing heavy.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from robocal.cli._rig import discover_rigs, registered_rig_names
from robocal.cli.main import main
from robocal.io import READABLE_SCHEMAS, SCHEMA, load_result
from robocal.workflow import Workflow
from browser import check_page, chromium_executable

RIG_NAMES = registered_rig_names()
#: What a rig's declaration must not import (cf. tests/cli/test_rig_imports.py)
HEAVY = ("numba", "matplotlib", "cv2", "scipy.optimize", "scipy.spatial", "skimage")


def _workflow(name: str) -> Workflow:
    (wf,) = discover_rigs([name])
    return wf


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _strip_stamp(html: str) -> str:
    # the report's one line that may differ between two builds: when it was made
    return re.sub(r"<p class='meta'>.*?</p>", "", html)


@pytest.mark.parametrize("name", RIG_NAMES)
def test_registered_rig_is_a_declared_workflow(name):
    wf = _workflow(name)
    assert isinstance(wf, Workflow), f"{name}: registered as {type(wf).__name__}, not a robocal.workflow.Workflow"
    assert wf.name == name
    if wf.calibrate is not None:
        assert wf.build_report is not None, f"{name}: calibrate without build_report"
    if wf.simulate is not None and wf.calibrate is not None:
        assert len(wf.simulated_inputs) == len(wf.inputs), f"{name}: simulated_inputs must name calibrate's inputs"


@pytest.mark.parametrize("name", RIG_NAMES)
def test_declaration_imports_nothing_heavy(name):
    code = (f"import json, sys\nfrom robocal.cli._rig import discover_rigs\nwf, = discover_rigs([{name!r}])\n"
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []


def check_result_vocabulary(res) -> list[str]:
    """Breaks of the result vocabulary (docs/results.md) in a loaded result; [] when it follows it."""
    problems = []
    est, std, units = res.estimate, res.std, res.units
    for name in res.poses:
        for part in ("rotation", "rotvec", "translation"):
            if f"{name}.{part}" not in est:
                problems.append(f"pose {name}: estimate has no {name}.{part}")
        if f"{name}.rotation" in est and np.shape(est[f"{name}.rotation"]) != (3, 3):
            problems.append(f"pose {name}: {name}.rotation is not 3x3")
    for key, value in est.items():
        base, _, part = key.rpartition(".")
        if part in ("rotation", "rotvec", "translation") and base not in res.poses:
            problems.append(f"{key}: a pose part, but {base!r} is not listed in `poses`")
        if np.shape(value) in ((4, 4), (3, 3)) and not (part == "rotation" and base in res.poses) \
                and not units.get(key, "").startswith("matrix"):
            problems.append(f"{key}: a bare matrix; write poses with CalibrationResult.add_pose")
        if re.fullmatch(r"(R|q|rotvec|t|T)_[A-Za-z0-9]+_[A-Za-z0-9]+", key):
            problems.append(f"{key}: a pose part under its own name; write it with add_pose")
        if key not in units:
            problems.append(f"{key}: no unit in `units`")
    for key in std:
        if key not in est and not (key.endswith(".rotvec") and key[:-7] in res.poses):
            problems.append(f"std {key}: not an estimate key")
    return problems


@pytest.mark.parametrize("name", RIG_NAMES)
def test_simulate_calibrate_report_round_trip(name, tmp_path, capsys):
    wf = _workflow(name)
    if wf.simulate is None or wf.calibrate is None:
        pytest.skip(f"{name} declares no simulate -> calibrate round trip")
    sim, cal, rep, rep2 = tmp_path / "sim", tmp_path / "cal", tmp_path / "rep", tmp_path / "rep2"
    code, out, err = _run([name, "simulate", *wf.quick_simulate, "--seed", "1", "--out", sim], capsys)
    assert code == 0, err
    inputs = [sim / f for f in wf.simulated_inputs]
    assert all(p.is_file() for p in inputs), f"simulate did not write {wf.simulated_inputs}"

    code, out, err = _run([name, "calibrate", *inputs, "--out", cal, "--accept-implausible"], capsys)
    assert code == 0, err
    assert (cal / "result.json").is_file() and (cal / "report.html").is_file()
    raw = json.loads((cal / "result.json").read_text())
    assert raw["schema"] == SCHEMA and raw["rig"] == name
    res = load_result(cal / "result.json")
    assert check_result_vocabulary(res) == []

    # the rig's own report command and the rig-independent one rebuild the same page
    first = _strip_stamp((cal / "report.html").read_text())
    code, out, err = _run([name, "report", cal / "result.json", "--out", rep], capsys)
    assert code == 0, err
    assert _strip_stamp((rep / "report.html").read_text()) == first
    code, out, err = _run(["report", cal / "result.json", "--out", rep2], capsys)
    assert code == 0, err
    assert _strip_stamp((rep2 / "report.html").read_text()) == first

    # a person reads it: every image loads, nothing overflows a 1400 px window
    if chromium_executable() is None:
        pytest.skip("Chromium not installed (.ci/run installs Debian's chromium): report not checked in a browser")
    assert check_page(cal / "report.html", width=1400) == []


@pytest.mark.parametrize("name", RIG_NAMES)
def test_a_declared_fleet_step_writes_a_batch_manifest(name, tmp_path, capsys):
    """``simulate --fleet`` (a rig with a ``fleet`` step): robot folders holding the inputs, and their manifest."""
    wf = _workflow(name)
    if wf.fleet is None:
        pytest.skip(f"{name} declares no fleet step")
    from robocal.batch import load_manifest

    sim = tmp_path / "fleet"
    code, out, err = _run([name, "simulate", "--fleet", "1", *wf.quick_simulate, "--seed", "1", "--out", sim], capsys)
    assert code == 0, err
    (entry,) = load_manifest(sim / "fleet.yaml", rig=name)
    assert entry.id == "robot-000" and [p.name for p in entry.inputs] == list(wf.simulated_inputs)
    assert all(p.is_file() for p in entry.inputs)
    assert json.loads((sim / "fleet_truth.json").read_text())["rig"] == name


def _example_lines():
    """Every ``calibrate`` example of every rig's help whose input files ship in ``examples/``."""
    import shlex
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for name in RIG_NAMES:
        for line in _workflow(name).calibrate_examples:
            words = shlex.split(line.split("#")[0])
            files = [w for w in words[3:] if w.startswith("examples/")]
            if files and all((root / f).is_file() for f in files):
                yield pytest.param(name, [str(root / w) if w.startswith("examples/") else w for w in words[1:]],
                                   id=" ".join(words[1:]).replace("examples/", ""))


@pytest.mark.parametrize("name, argv", list(_example_lines()))
def test_help_examples_calibrate_in_the_shared_vocabulary(name, argv, tmp_path, capsys):
    # the examples a user copies from `robocal <rig> calibrate --help` work, and their results
    # follow the schema (every rig's example result, issue 20)
    if "--out" in argv:
        argv = argv[: argv.index("--out")] + argv[argv.index("--out") + 2:]
    code, out, err = _run([*argv, "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    assert res.rig == name and check_result_vocabulary(res) == []


@pytest.mark.parametrize("name", RIG_NAMES)
def test_bad_input_is_one_line_exit_2(name, tmp_path, capsys):
    wf = _workflow(name)
    if wf.calibrate is None:
        pytest.skip(f"{name} has no calibrate")
    bad = tmp_path / "bad.yaml"
    bad.write_text("this: [is not, a calibration input\n")
    missing = tmp_path / "missing.yaml"
    for inputs in ([bad] * len(wf.inputs), [missing] * len(wf.inputs)):
        code, out, err = _run([name, "calibrate", *inputs, "--out", tmp_path / "o"], capsys)
        assert code == 2, (inputs, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("robocal: error:"), err
        assert "Traceback" not in err
        assert inputs[0].name in err, err  # the message names the file


def test_robocal_report_names_a_result_of_an_unknown_rig(tmp_path, capsys):
    from robocal.io import CalibrationResult, write_result

    write_result(tmp_path / "result.json", CalibrationResult(rig="nosuchrig", method="m", estimate={}))
    code, out, err = _run(["report", tmp_path / "result.json", "--out", tmp_path / "r"], capsys)
    assert code == 2 and "nosuchrig" in err and len(err.strip().splitlines()) == 1


def test_result_vocabulary_check_can_fail():
    from robocal.io import CalibrationResult

    res = CalibrationResult(rig="x", method="m", estimate={"R_0_W": np.eye(3).tolist(), "h": 1.0}, units={"h": "m"})
    found = check_result_vocabulary(res)
    assert any("R_0_W" in p for p in found)
    res = CalibrationResult(rig="x", method="m", estimate={})
    res.add_pose("T_r_c", np.eye(4), std_rotation=[1e-3] * 3, std_translation=[1e-3] * 3)
    assert check_result_vocabulary(res) == []


def test_previous_schema_still_loads(tmp_path):
    assert "robocal.result/1" in READABLE_SCHEMAS
    T = np.eye(4)
    v1 = {"schema": "robocal.result/1", "rig": "lineprofiler", "method": "fpdp",
          "estimate": {"T_E_L.rotation": T[:3, :3].tolist(), "T_E_L.translation": [0.1, 0.0, 0.0]},
          "std": {"T_E_L.rotvec": [1e-3] * 3, "T_E_L.translation": [1e-4] * 3},
          "units": {"T_E_L.rotation": "1", "T_E_L.translation": "m"}}
    (tmp_path / "result.json").write_text(json.dumps(v1))
    res = load_result(tmp_path / "result.json")
    assert list(res.poses) == ["T_E_L"]
    pose = res.pose("T_E_L")
    np.testing.assert_array_equal(pose.T[:3, 3], [0.1, 0.0, 0.0])
    np.testing.assert_array_equal(pose.std_rotation, [1e-3] * 3)
