import json
import os
import stat

import numpy as np
import pytest
import yaml

from robocal.diagnostics import Diagnostic
from robocal.errors import FileFormatError
from robocal.io import CalibrationResult, atomic_write_text, hash_inputs, load_result, write_result


def _result(tmp_path):
    inp = tmp_path / "in.yaml"
    inp.write_text("a: 1\n")
    return CalibrationResult(
        rig="projector",
        method="nonlinear",
        estimate={"R": np.eye(3), "t": np.array([1.0, 2.0, 3.0]), "H": 2.9},
        std={"R": None, "t": [0.001, 0.001, np.nan], "H": 0.002},
        units={"t": "m", "H": "m"},
        residual_rms=0.0012,
        residual_unit="m",
        warnings=[Diagnostic("outliers", "2 residuals > 3 sigma", indices=(3, 7))],
        inputs=hash_inputs([inp]),
        diagnostics={"iterations": np.int64(7)},
    )


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_result_round_trip(tmp_path, suffix):
    res = _result(tmp_path)
    path = write_result(tmp_path / f"result{suffix}", res)
    back = load_result(path)
    assert back.rig == "projector" and back.method == "nonlinear"
    np.testing.assert_allclose(back.estimate["R"], np.eye(3))
    assert back.std["t"][2] is None  # NaN is never written
    assert back.warnings[0].indices == (3, 7)
    assert back.diagnostics["iterations"] == 7
    assert len(next(iter(back.inputs.values()))) == 64
    assert back.robocal_version


def _strict_json(text):
    def refuse(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_non_finite_values_are_written_as_null(tmp_path, suffix):
    # docs/results.md: "Non-finite numbers are written as null: a consumer never reads a NaN."
    res = _result(tmp_path)
    res.estimate = {"H": np.inf, "t": np.array([1.0, -np.inf, np.nan]), "k": np.float32("nan"), "R": np.eye(3)}
    res.std = {"H": float("nan"), "t": [0.1, np.inf, np.float64("nan")], "k": None, "R": np.full((3, 3), np.nan)}
    res.residual_rms = np.nan
    res.diagnostics = {"iterations": np.int64(7), "condition_number": np.inf, "cost_history": [2.0, np.nan, 1.0],
                       "per_view": {"rms": np.array([0.5, np.inf])}}
    path = write_result(tmp_path / f"result{suffix}", res)
    text = path.read_text()
    if suffix == ".json":
        d = _strict_json(text)
    else:
        assert ".nan" not in text.lower() and ".inf" not in text.lower()
        d = yaml.safe_load(text)
    assert d["estimate"]["H"] is None and d["estimate"]["k"] is None
    assert d["estimate"]["t"] == [1.0, None, None]
    assert d["estimate"]["R"] == np.eye(3).tolist()
    assert d["std"]["H"] is None and d["std"]["t"] == [0.1, None, None] and d["std"]["k"] is None
    assert d["std"]["R"] == [[None] * 3] * 3
    assert d["residual_rms"] is None
    assert d["diagnostics"] == {"iterations": 7, "condition_number": None, "cost_history": [2.0, None, 1.0],
                                "per_view": {"rms": [0.5, None]}}
    back = load_result(path)
    assert back.estimate["t"] == [1.0, None, None] and back.diagnostics["condition_number"] is None


def test_load_result_rejects_other_files(tmp_path):
    p = tmp_path / "x.json"
    p.write_text('{"schema": "other"}')
    with pytest.raises(FileFormatError, match="not a robocal result"):
        load_result(p)


def test_atomic_write_keeps_old_file_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "result.json"
    atomic_write_text(target, "old")

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]  # no temp file left behind


@pytest.mark.skipif(not hasattr(os, "fchmod"), reason="POSIX permissions")
def test_atomic_write_gives_the_usual_permissions(tmp_path):
    # mkstemp's 0600 would make result files unreadable to the rest of a team
    old = os.umask(0o022)
    try:
        path = atomic_write_text(tmp_path / "r.json", "{}")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_atomic_write_steps_over_a_leftover_temporary_file(tmp_path, monkeypatch):
    # a crashed process with this pid left its temporary file: O_EXCL takes the next name, not that file
    import itertools
    import threading

    from robocal.io import _atomic

    monkeypatch.setattr(_atomic, "_serial", itertools.count())
    stale = tmp_path / f".r.json.{os.getpid()}.{threading.get_ident()}.0.tmp"
    stale.write_text("stale")
    path = atomic_write_text(tmp_path / "r.json", "{}")
    assert path.read_text() == "{}" and stale.read_text() == "stale"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([stale.name, "r.json"])
