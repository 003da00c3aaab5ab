"""The README's first command, run as a user runs it: a subprocess on the installed package.

Each rig's own demo checks (its figures, its truth check) are in its own tests
(tests/rigs/<rig>/..., e.g. test_flow_demo.py); here: the whole command runs,
every installed rig takes part and passes, and the index page holds them.
(Every rig's calibrate / report / bad-input behaviour: tests/test_rig_contract.py.)
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from robocal.cli import discover_rigs
from robocal.cli._rig import demo_of
from robocal.cli.main import build_parser, demo_seed, main
from robocal.io import write_result
from robocal.workflow import DemoContext


def _run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "robocal", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)


def test_robocal_demo_runs_every_installed_rig(tmp_path):
    rigs = [r.name for r in discover_rigs() if r.demo is not None]
    proc = _run("demo", "--out", str(tmp_path / "demo"), "--no-progress", cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
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
    # a rig's figures do not depend on which other rigs ran before it in the same process (its stream is
    # keyed by its name): the projector's demo step on its own, in this process with the command's
    # default seed, gives the estimates it gave among all the others
    (projector,) = discover_rigs(["projector"])
    seed = build_parser(discover_rigs(["projector"])).parse_args(["demo"]).seed
    ctx = DemoContext(out_dir=tmp_path / "alone" / "projector", rng=np.random.default_rng(demo_seed(seed, "projector")),
                      progress=False)
    ctx.out_dir.mkdir(parents=True)
    alone = demo_of(projector)(ctx)
    assert alone.passed, alone.summary
    write_result(ctx.out_dir / "result.json", alone.result)  # the same JSON round trip as the command's file
    est = [json.loads((tmp_path / d / "projector" / "result.json").read_text())["estimate"]
           for d in ("demo", "alone")]
    assert est[0].keys() == est[1].keys()
    for k in est[0]:
        # same data, same solver, same machine: equal up to summation order (a different
        # stream would move them by the noise, ~1e-3 relative)
        np.testing.assert_allclose(np.asarray(est[1][k], float), np.asarray(est[0][k], float), rtol=1e-9, atol=1e-12,
                                   err_msg=k)


def test_every_rig_has_help_with_examples(capsys):
    # in this process: the help text is the parser's, the same as a subprocess prints (that `--help`
    # imports no heavy module is tests/cli/test_rig_imports.py's subprocess check)
    for rig in discover_rigs():
        with pytest.raises(SystemExit) as e:
            main([rig.name, "--help"])
        assert e.value.code == 0, rig.name
        out = capsys.readouterr().out
        assert rig.name in out and "examples:" in out, f"{rig.name} --help has no examples"
