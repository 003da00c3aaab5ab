"""Checks of a rig's result and report shared by the rigs' CLI tests (on the test path: tests/support)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from robocal.cli.main import main


def page(path: Path) -> str:
    """A report page without the one line that differs between two builds of it: when it was made."""
    return re.sub(r"<p class='meta'>.*?</p>", "", Path(path).read_text())


def rebuilt_equal(cal: Path, out: Path, rig: str, capsys) -> str:
    """``robocal <rig> report`` and ``robocal report`` rebuild the page ``calibrate`` wrote; returns it."""
    first = page(cal / "report.html")
    assert main([rig, "report", str(cal / "result.json"), "--out", str(out / "rig")]) == 0
    assert main(["report", str(cal / "result.json"), "--out", str(out / "any")]) == 0
    capsys.readouterr()
    assert page(out / "rig" / "report.html") == first
    assert page(out / "any" / "report.html") == first
    return first


def bare_matrices(result) -> list[str]:
    """Estimate keys holding a 3x3 / 4x4 matrix that is not a pose's rotation (the vocabulary forbids them)."""
    return [k for k, v in result.estimate.items() if np.shape(v) in ((3, 3), (4, 4))
            and not (k.endswith(".rotation") and k[: -len(".rotation")] in result.poses)]
