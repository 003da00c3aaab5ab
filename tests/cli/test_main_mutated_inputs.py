"""The robocal program (``main``, in-process) on every example input mutated as users mutate files (fuzzing).

The contract checked for each mutated input (issue 18): exit status 0, or 2
with exactly one stderr line starting ``robocal: error:`` and no traceback;
never 1 for bad input (only ``projector path`` has a documented exit 1: an
infeasible path); a ``result.json`` never holds NaN or infinity.

Mutations: truncated, empty and binary files, flipped bytes, wrong types
(text, null, booleans, lists where numbers go), NaN/inf, negative, zero and
huge values, values x1000 or /1000, swapped columns, another unit in a CSV
header or a YAML unit field, missing and duplicate keys, dropped columns and
rows; every example is copied under a non-ASCII folder name, and the
``--out`` is sometimes a file, a path below a file, or a folder holding
someone else's file.

Derandomized (tests/conftest.py) and bounded: the default profile draws a few
examples per command (~60 s on a 2-core machine); ``HYPOTHESIS_PROFILE=explore``
draws ten times as many, fresh each run::

    HYPOTHESIS_PROFILE=explore python -m pytest tests/cli/test_main_mutated_inputs.py -q
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
import tempfile
import traceback
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from robocal.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
EXPLORE = os.environ.get("HYPOTHESIS_PROFILE") == "explore"

#: name -> (example folder, argv with {file} placeholders, files to mutate, examples drawn by default)
TARGETS = {
    "handeye-calibrate": ("lineprofiler", ["handeye", "calibrate", "{gripper_poses.csv}", "{target_poses.csv}"],
                          ["gripper_poses.csv", "target_poses.csv"], 14),
    "flow-convert-mavlink": ("flow/mavlink", ["flow", "convert-mavlink", "{flow.tlog}", "--array", "{array.yaml}",
                                              "--sensor-map", "0:s60,1:s120,2:s270"], ["flow.tlog", "array.yaml"], 12),
    "projector-calibrate": ("projector", ["projector", "calibrate", "{room_A_csv.yaml}"],
                            ["room_A_csv.yaml", "room_A_points.csv"], 4),
    "projector-path": ("projector", ["projector", "path", "{path_timed.yaml}"], ["path_timed.yaml", "path_timed.csv"], 3),
    "lineprofiler-calibrate": ("lineprofiler", ["lineprofiler", "calibrate", "{mct_input.yaml}"],
                               ["mct_input.yaml", "mct_line.csv", "mct_block.csv"], 3),
    "mirror-calibrate": ("mirror", ["mirror", "calibrate", "{own_camera.yaml}"], ["own_camera.yaml", "opencv_camera.yaml"], 3),
    "flow-odometry": ("flow/loop", ["flow", "odometry", "{run.yaml}"], ["run.yaml", "flow.csv", "wheel.csv"], 3),
    "humanoid-calibrate": ("humanoid", ["humanoid", "calibrate", "{run.yaml}"], ["run.yaml", "images/view000.png"], 3),
}

#: documented exit 1 (a verdict, not an error)
EXIT_1_ALLOWED = {"projector-path"}

#: failures inside a rig's own code found by this fuzz and not yet fixed, tolerated so the suite
#: stays green while they are: (target, substring of the escaping exception's last traceback line)
#: -> reason. Empty: the one found (humanoid: a --out refusal after the whole solve, with
#: progress-bar frames on stderr) is fixed.
KNOWN: dict[tuple[str, str], str] = {}

# -- mutations -------------------------------------------------------------------------------------------------

_BAD_VALUES = [None, "abc", "2.5", True, [], {}, [1, 2], float("nan"), float("inf"), float("-inf"), 1e300, -1e300, 0, -1]
_UNIT_SWAPS = {"mm": "m", "m": "mm", "deg": "rad", "rad": "deg", "cm": "m", "s": "ms", "ms": "s", "px": "mm"}


def _leaves(obj, path=()):
    """Paths to every scalar (and every list of numbers) in parsed YAML."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(obj, list):
        if obj and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in obj):
            yield path
        for i, v in enumerate(obj):
            yield from _leaves(v, (*path, i))
    else:
        yield path


def _containers(obj, path=()):
    """Paths to every mapping (for deleting a key) and every list of equal-length rows (for swapping columns)."""
    if isinstance(obj, dict):
        yield path, "map"
        for k, v in obj.items():
            yield from _containers(v, (*path, k))
    elif isinstance(obj, list):
        if len(obj) > 0 and all(isinstance(r, list) and len(r) == len(obj[0]) and len(r) >= 2 for r in obj):
            yield path, "rows"
        for i, v in enumerate(obj):
            yield from _containers(v, (*path, i))


def _get(obj, path):
    for p in path:
        obj = obj[p]
    return obj


def _set(obj, path, value):
    if not path:
        return value
    _get(obj, path[:-1])[path[-1]] = value
    return obj


def _mutate_yaml(data, text: str) -> tuple[str, str]:
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError:
        doc = None
    ops = ["duplicate"]
    if isinstance(doc, (dict, list)):
        ops += ["value", "value", "scale", "delete", "swap", "unit"]
    op = data.draw(st.sampled_from(ops), label="yaml op")
    if op == "duplicate":
        lines = [ln for ln in text.splitlines() if ln and not ln[0].isspace() and ":" in ln and not ln.startswith("#")]
        if not lines:
            return op, text + "\nx: 1\nx: 2\n"
        return op, text.rstrip("\n") + "\n" + data.draw(st.sampled_from(lines), label="duplicated line") + "\n"
    if op in ("value", "scale"):
        path = data.draw(st.sampled_from(list(_leaves(doc))), label="leaf")
        old = _get(doc, path)
        if op == "value":
            new = data.draw(st.sampled_from(_BAD_VALUES), label="value")
        else:
            f = data.draw(st.sampled_from([1000.0, 1e-3, -1.0, math.pi / 180, 180 / math.pi]), label="factor")
            num = lambda v: v * f if isinstance(v, (int, float)) and not isinstance(v, bool) else v  # noqa: E731
            new = [num(v) for v in old] if isinstance(old, list) else num(old)
        doc = _set(doc, path, new)
        return f"{op} {'.'.join(map(str, path))}={new!r:.40}", yaml.safe_dump(doc, sort_keys=False)
    conts = list(_containers(doc))
    if op == "delete":
        maps = [p for p, k in conts if k == "map" and _get(doc, p)]
        if not maps:
            return op, ""
        path = data.draw(st.sampled_from(maps), label="mapping")
        key = data.draw(st.sampled_from(sorted(_get(doc, path), key=str)), label="key")
        del _get(doc, path)[key]
        return f"delete {'.'.join(map(str, (*path, key)))}", yaml.safe_dump(doc, sort_keys=False)
    if op == "swap":
        rows = [p for p, k in conts if k == "rows"]
        if not rows:
            return op, text.replace("\n", "\n\n", 1)
        path = data.draw(st.sampled_from(rows), label="rows")
        for r in _get(doc, path):
            r[0], r[1] = r[1], r[0]
        return f"swap columns 0,1 of {'.'.join(map(str, path))}", yaml.safe_dump(doc, sort_keys=False)
    # unit: another unit of the same kind in a `unit:` / `units:` field
    units = [p for p in _leaves(doc) if p and isinstance(_get(doc, p), str) and _get(doc, p) in _UNIT_SWAPS
             and any(isinstance(k, str) and k.startswith("unit") for k in p)]
    if not units:
        return "unit (none)", text
    path = data.draw(st.sampled_from(units), label="unit field")
    doc = _set(doc, path, _UNIT_SWAPS[_get(doc, path)])
    return f"unit {'.'.join(map(str, path))}", yaml.safe_dump(doc, sort_keys=False)


def _mutate_csv(data, text: str) -> tuple[str, str]:
    lines = text.splitlines(keepends=True)
    n_comments = next((i for i, ln in enumerate(lines) if not ln.startswith("#")), len(lines))
    comments, text = "".join(lines[:n_comments]), "".join(lines[n_comments:])
    what, new = _mutate_table(data, text)
    return what, comments + new


def _mutate_table(data, text: str) -> tuple[str, str]:
    rows = list(csv.reader(io.StringIO(text)))
    if len(rows) < 2 or len(rows[0]) < 2:
        return "csv (too small)", text[: len(text) // 2]
    header, body = rows[0], [r for r in rows[1:] if r]
    op = data.draw(st.sampled_from(["swap", "unit", "cell", "drop column", "drop rows", "negate"]), label="csv op")
    i, j = data.draw(st.lists(st.integers(0, len(header) - 1), min_size=2, max_size=2, unique=True), label="columns")
    if op == "swap":
        for r in body:
            if len(r) > max(i, j):
                r[i], r[j] = r[j], r[i]
    elif op == "unit":
        cell = header[i]
        for a, b in _UNIT_SWAPS.items():
            if f"[{a}]" in cell:
                header[i] = cell.replace(f"[{a}]", f"[{b}]")
                break
        else:
            header[i] = cell + " [mm]"
    elif op == "cell":
        r = data.draw(st.integers(0, len(body) - 1), label="row")
        if len(body[r]) > i:
            body[r][i] = data.draw(st.sampled_from(["nan", "inf", "-inf", "1e300", "-1e300", "abc", "", "0", "-1"]), label="cell")
    elif op == "drop column":
        header.pop(i)
        for r in body:
            if len(r) > i:
                r.pop(i)
    elif op == "drop rows":
        body = body[: data.draw(st.integers(0, 3), label="rows kept")]
    else:
        for r in body:
            try:
                r[i] = repr(-float(r[i]))
            except (ValueError, IndexError):
                pass
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows([header, *body])
    return f"{op} {header[min(i, len(header) - 1)] if header else ''}", out.getvalue()


def _mutate(data, path: Path) -> str:
    raw = path.read_bytes()
    op = data.draw(st.sampled_from(["truncate", "empty", "binary", "flip", "structured", "structured", "structured"]),
                   label="op")
    if op == "truncate":
        cut = data.draw(st.integers(0, max(len(raw) - 1, 0)), label="cut")
        path.write_bytes(raw[:cut])
        return f"truncated at {cut} of {len(raw)} bytes"
    if op == "empty":
        path.write_bytes(b"")
        return "empty"
    if op == "binary":
        path.write_bytes(data.draw(st.sampled_from([b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe", b"\x00" * 64,
                                                    bytes(range(256))]), label="bytes"))
        return "binary"
    if op == "flip" or path.suffix not in (".yaml", ".yml", ".csv", ".json"):
        b = bytearray(raw)
        for pos in data.draw(st.lists(st.integers(0, max(len(b) - 1, 0)), min_size=1, max_size=8), label="flips"):
            if b:
                b[pos] ^= 0xFF
        path.write_bytes(bytes(b))
        return "flipped bytes"
    text = raw.decode("utf-8")
    what, new = (_mutate_csv if path.suffix == ".csv" else _mutate_yaml)(data, text)
    path.write_text(new, encoding="utf-8")
    return what


# -- the contract ----------------------------------------------------------------------------------------------

def _no_nan(text: str) -> None:
    def refuse(c):
        raise AssertionError(f"result.json holds {c}")

    json.loads(text, parse_constant=refuse)


def _check(name, argv, capsys, case):
    try:
        code = main(argv)
    except SystemExit as e:  # argparse usage errors exit through SystemExit
        code = e.code
    except BaseException as exc:  # noqa: BLE001 - an escaping exception is the finding
        last = traceback.format_exception_only(type(exc), exc)[-1].strip()
        for (target, sig), reason in KNOWN.items():
            if target == name and sig in last:
                pytest.xfail(f"{name}: {case}: {reason}")
        pytest.fail(f"{name}: {case}: exception escaped main: {last}\n{traceback.format_exc()}")
    out, err = capsys.readouterr()
    if os.environ.get("ROBOCAL_FUZZ_LOG"):  # one line per case, to see what the draws reached
        with open(os.environ["ROBOCAL_FUZZ_LOG"], "a", encoding="utf-8") as fh:
            fh.write(f"{code} {name}: {case} | {err.strip().splitlines()[-1][:160] if err.strip() else ''}\n")
    allowed = (0, 1, 2) if name in EXIT_1_ALLOWED else (0, 2)
    assert code in allowed, f"{name}: {case}: exit {code}\nstdout: {out[-500:]}\nstderr: {err[-1500:]}"
    assert "Traceback" not in err, f"{name}: {case}: traceback\n{err[-2000:]}"
    if code == 2:
        lines = err.splitlines()
        errors = [ln for ln in lines if ln.startswith("robocal: error:")]
        assert len(errors) == 1 and lines[-1] == errors[0], f"{name}: {case}: stderr is not one error line:\n{err[-2000:]}"
        # other lines may only be robocal's own warnings printed before the failure was found
        assert all(ln.startswith(("warning:", "robocal: warning:", "robocal: error:")) for ln in lines), \
            f"{name}: {case}: stray stderr lines:\n{err[-2000:]}"
    out_dir = Path(argv[argv.index("--out") + 1])
    result = out_dir / "result.json"
    if code == 0 and result.is_file():
        _no_nan(result.read_text(encoding="utf-8"))


def _prepare(data, root: Path, name: str):
    folder, template, files, _ = TARGETS[name]
    # a non-ASCII folder name: paths are text, never assumed ASCII
    work = root / "données ünï 数据"
    shutil.copytree(EXAMPLES / folder, work)
    target = data.draw(st.sampled_from(files), label="file")
    case = f"{folder}/{target}: {_mutate(data, work / target)}"
    argv = [a.replace("{" + a[1:-1] + "}", str(work / a[1:-1])) if a.startswith("{") else a for a in template]
    out_kind = data.draw(st.sampled_from(["new", "new", "new", "new", "file", "below a file", "foreign"]), label="--out")
    out = root / "out"
    if out_kind == "file":
        out.write_text("not a folder\n")
    elif out_kind == "below a file":
        (root / "plain").write_text("x\n")
        out = root / "plain" / "out"
    elif out_kind == "foreign":
        out.mkdir()
        (out / "notes.txt").write_text("mine\n")
    return [*argv, "--out", str(out)], f"{case}; --out {out_kind}"


def _fuzz(name):
    n = TARGETS[name][3] * (10 if EXPLORE else 1)

    @settings(max_examples=n, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                      HealthCheck.too_slow])
    @given(data=st.data())
    def run(capsys, data):
        with tempfile.TemporaryDirectory() as tmp:
            argv, case = _prepare(data, Path(tmp), name)
            capsys.readouterr()
            _check(name, argv, capsys, case)

    return run


for _name in TARGETS:
    globals()[f"test_fuzz_{_name.replace('-', '_')}"] = _fuzz(_name)


def test_every_example_input_runs_clean_first(tmp_path, capsys):
    """The unmutated examples pass the same contract (so a fuzz failure is the mutation's)."""
    for name, (folder, template, _, _) in TARGETS.items():
        if name not in ("handeye-calibrate", "flow-convert-mavlink"):
            continue  # the others cost seconds each; the rigs' own tests run their examples
        argv = [str(EXAMPLES / folder / a[1:-1]) if a.startswith("{") else a for a in template]
        argv += ["--out", str(tmp_path / name)]
        assert main(argv) == 0, capsys.readouterr()
        capsys.readouterr()
