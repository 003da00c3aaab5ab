"""The README's first command, run as a user runs it: a subprocess on the installed package.

(Every rig's calibrate / report / bad-input behaviour: tests/test_rig_contract.py.)
"""

import json
import subprocess
import sys

import numpy as np

from robocal.cli import discover_rigs


def _run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "robocal", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)


def test_robocal_demo_runs_every_installed_rig(tmp_path):
    rigs = [r.name for r in discover_rigs() if r.demo is not None]
    proc = _run("demo", "--out", str(tmp_path / "demo"), "--no-progress", cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # a rig's figures do not depend on which other rigs run (its stream is keyed by its name):
    # the projector alone (the cheapest demo) gives the estimates it gave among all five
    alone = _run("demo", "--rigs", "projector", "--out", str(tmp_path / "alone"), "--no-progress", cwd=tmp_path)
    assert alone.returncode == 0, alone.stdout + alone.stderr
    est = [json.loads((tmp_path / d / "projector" / "result.json").read_text())["estimate"] for d in ("demo", "alone")]
    assert est[0].keys() == est[1].keys()
    for k in est[0]:
        # same data, same solver, same machine: equal up to summation order (a different
        # stream would move them by the noise, ~1e-3 relative)
        np.testing.assert_allclose(np.asarray(est[1][k], float), np.asarray(est[0][k], float), rtol=1e-9, atol=1e-12,
                                   err_msg=k)
    assert "Traceback" not in proc.stderr
    html = (tmp_path / "demo" / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html>")
    # self-contained: plots are embedded, nothing is fetched from elsewhere
    assert 'src="http' not in html and "<link " not in html
    for name in rigs:
        assert name in proc.stdout
        result = tmp_path / "demo" / name / "result.json"
        if result.exists():
            assert json.loads(result.read_text())["schema"] == "robocal.result/2"


def test_every_rig_has_help_with_examples(tmp_path):
    for rig in discover_rigs():
        proc = _run(rig.name, "--help", cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert rig.name in proc.stdout and "examples:" in proc.stdout, f"{rig.name} --help has no examples"

