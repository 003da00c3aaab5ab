"""CLI: every example runs; simulate -> odometry/calibrate/evaluate; bad inputs give one-line errors."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"


def _run(argv, capsys):
    code = main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_examples_run(tmp_path, capsys):
    code, out, _ = _run(["flow", "odometry", str(EX / "loop" / "run.yaml"), "--out", str(tmp_path / "odo"), "--no-progress"], capsys)
    assert code == 0 and "ATE" in out
    res = json.loads((tmp_path / "odo" / "result.json").read_text())
    assert res["rig"] == "flow" and res["estimate"]["ate_rmse"] < 0.02
    assert (tmp_path / "odo" / "report.html").stat().st_size > 10_000
    code, out, _ = _run(["flow", "calibrate", str(EX / "calibration" / "run.yaml"), "--out", str(tmp_path / "cal"), "--no-progress"], capsys)
    assert code == 0
    cal = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert cal["units"]["s60.R"] == "m" and cal["std"]["s60.R"] > 0
    assert abs(cal["estimate"]["s60.R"] - 0.356) < 0.01
    # statistical and systematic parts, and a residual figure in the report
    assert cal["diagnostics"]["std_systematic_kernel"]["s60.R"] > 0 and cal["diagnostics"]["std_total"]["s60.R"] > cal["std"]["s60.R"]
    # a flow log has no frames: the systematic comes from its flow phases through the kernel's bias measured
    # on gravel frames; s270 (flow along one axis at two speeds) gets far more than s60 (the example's
    # s270.R is ~12 mm short of the mounting)
    d = cal["diagnostics"]
    assert d["std_systematic_kernel_source"] == "model" and "derived from this run's flow phases" in out
    assert d["std_systematic_kernel"]["s270.R"] > 0.006 > d["std_systematic_kernel"]["s60.R"]
    assert abs(d["estimate_kernel_debiased"]["s270.R"] - 0.353) < 0.5 * abs(cal["estimate"]["s270.R"] - 0.353)
    code, out, _ = _run(["flow", "calibrate", str(EX / "calibration" / "run.yaml"), "--out", str(tmp_path / "cald"),
                         "--debias", "--no-progress"], capsys)
    assert code == 0 and "--debias removed that bias" in out
    cald = json.loads((tmp_path / "cald" / "result.json").read_text())
    assert abs(cald["estimate"]["s270.R"] - 0.353) < 0.005
    assert "<img" in (tmp_path / "cal" / "report.html").read_text()
    assert "psi: 271." in (tmp_path / "cal" / "array_calibrated.yaml").read_text()   # near the nominal 270, not -89
    code, out, _ = _run(["flow", "evaluate", str(EX / "loop" / "run.yaml"), "--array", str(tmp_path / "cal" / "array_calibrated.yaml"),
                         "--out", str(tmp_path / "ev"), "--no-progress"], capsys)
    assert code == 0
    ev = json.loads((tmp_path / "ev" / "result.json").read_text())["estimate"]
    assert ev["flow odometry (calibrated) ATE"] < ev["flow odometry ATE"]


def test_raw_frames_example_runs(tmp_path, capsys):
    # the shipped raw-frames example (frames + gyro + height, no flow log): the kernel computes the flow
    ex = EX / "frames"
    assert sum(f.stat().st_size for f in ex.iterdir()) < 2_000_000
    assert "flow_log" not in (ex / "run.yaml").read_text()
    code, out, _ = _run(["flow", "odometry", str(ex / "run.yaml"), "--out", str(tmp_path / "odo"), "--no-progress"], capsys)
    assert code == 0 and "ATE" in out
    res = json.loads((tmp_path / "odo" / "result.json").read_text())
    assert res["estimate"]["ate_rmse"] < 0.003 and abs(res["estimate"]["distance"] - 0.119) < 0.005
    s = res["diagnostics"]["summary"]
    assert s["bridged_steps"] == 0
    # a 0.12 m drive: the RPE segments are fractions of its path, and stdout says so
    assert "short run" in out and "RPE@0.03m" in out
    ev = res["diagnostics"]["evaluation"]["flow odometry"]
    assert ev["rpe_headline_m"] == pytest.approx(0.03) and ev["rpe"]["0.03"]["n"] > 50


def test_simulate_frames_then_odometry(tmp_path, capsys):
    out = tmp_path / "sim"
    code, text, _ = _run(["flow", "simulate", "--duration", "0.6", "--supersample", "1", "--texture", "grass",
                          "--out", str(out), "--no-progress"], capsys)
    assert code == 0 and "scikit-image photograph 'grass'" in text
    with np.load(out / "frames.npz") as z:
        assert z["frames"].shape == (3, 241, 64, 64) and z["frames"].dtype == np.uint8
    # written uncompressed, so the reader memory-maps the frames instead of inflating them
    from robocal.rigs.flow.log import read_frames_npz

    assert isinstance(read_frames_npz(out / "frames.npz")["frames"], np.memmap)
    code, text, _ = _run(["flow", "odometry", str(out / "run.yaml"), "--refine", "lk", "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 0
    # --no-report: the trajectory and the result now, the report drawn from the result later
    code, text, _ = _run(["flow", "odometry", str(out / "run.yaml"), "--no-report", "--out", str(tmp_path / "n"),
                          "--no-progress"], capsys)
    assert code == 0 and "ATE" in text and "report.html" not in text
    assert (tmp_path / "n" / "trajectory.csv").is_file() and not (tmp_path / "n" / "report.html").exists()
    code, _, _ = _run(["flow", "report", str(tmp_path / "n" / "result.json"), "--out", str(tmp_path / "r")], capsys)
    assert code == 0 and (tmp_path / "r" / "report.html").stat().st_size > 10_000


def _copy_loop(tmp_path):
    d = tmp_path / "run"
    shutil.copytree(EX / "loop", d)
    return d


def _edit_csv(path, fn):
    lines = path.read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln.startswith("t [s]")][0]
    body = [ln.split(",") for ln in lines[head + 1:]]
    body = fn(body)
    path.write_text("\n".join(lines[:head + 1] + [",".join(r) for r in body]) + "\n")


@pytest.mark.parametrize("case, edit, message", [
    ("non-monotonic", lambda b: b[:30] + b[33:36] + b[30:33] + b[36:], "must not decrease"),
    ("missing sensor", lambda b: b[:10] + b[11:], "sensor 1 has no record at t = 0.010000"),
    ("zero height", lambda b: b[:5] + [b[5][:8] + ["0.0"] + b[5][9:]] + b[6:], "height must be > 0"),
    ("negative height", lambda b: b[:7] + [b[7][:8] + ["-0.1"] + b[7][9:]] + b[8:], "height must be > 0"),
    ("bad sensor index", lambda b: b[:4] + [b[4][:2] + ["7"] + b[4][3:]] + b[5:], "sensor index 7"),
    ("quality above 255", lambda b: b[:6] + [b[6][:9] + ["999"]] + b[7:], "quality must be in 0..255, got 999"),
    ("negative quality", lambda b: b[:6] + [b[6][:9] + ["-3"]] + b[7:], "quality must be in 0..255, got -3"),
    ("dt of one row", lambda b: b[:6] + [b[6][:1] + ["0.0100"] + b[6][2:]] + b[7:], "disagrees with dt = 0.0025"),
    ("dt overlaps", lambda b: b[:6] + [r[:1] + ["0.0050"] + r[2:] for r in b[6:9]] + b[9:], "reaches back to"),
    ("dropped intervals", lambda b: b[:300] + b[600:], "0.250000 s of records are missing"),
])
def test_bad_flow_logs(tmp_path, capsys, case, edit, message):
    d = _copy_loop(tmp_path)
    _edit_csv(d / "flow.csv", edit)
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2
    assert message in err and err.count("\n") == 1 and "flow.csv" in err


def test_missing_records_can_be_allowed(tmp_path, capsys):
    d = _copy_loop(tmp_path)
    _edit_csv(d / "flow.csv", lambda b: b[:10] + b[11:])
    code, _, _ = _run(["flow", "odometry", str(d / "run.yaml"), "--allow-missing", "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 0


def test_single_sensor_is_a_clear_error(tmp_path, capsys):
    d = _copy_loop(tmp_path)
    text = (d / "run.yaml").read_text()
    cut = text.index("- name: s120")
    end = text.index("flow_log:")
    (d / "run.yaml").write_text(text[:cut] + text[end:])
    # keep only sensor 0's rows: the array has one sensor
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2 and "at least 2" in err and "3 unknowns" in err


def test_wrong_frame_size(tmp_path, capsys):
    d = _copy_loop(tmp_path)
    rng = np.random.default_rng(0)
    np.savez(d / "frames.npz", frames=rng.integers(0, 255, (3, 5, 32, 32), dtype=np.uint8), t=np.arange(5) / 400.0,
             gyro=np.zeros((3, 4, 3)), height=np.full((3, 4), 0.1))
    text = (d / "run.yaml").read_text().replace("flow_log: flow.csv", "frames: frames.npz")
    (d / "run.yaml").write_text(text)
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2 and "64x64" in err and "32x32" in err


def test_non_monotonic_frame_times(tmp_path, capsys):
    d = _copy_loop(tmp_path)
    rng = np.random.default_rng(0)
    t = np.arange(6) / 400.0
    t[3] = t[1]
    np.savez(d / "frames.npz", frames=rng.integers(0, 255, (3, 6, 64, 64), dtype=np.uint8), t=t,
             gyro=np.zeros((3, 5, 3)), height=np.full((3, 5), 0.1))
    (d / "run.yaml").write_text((d / "run.yaml").read_text().replace("flow_log: flow.csv", "frames: frames.npz"))
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2 and "increase strictly" in err


def test_help_lists_examples(capsys):
    with pytest.raises(SystemExit):
        main(["flow", "odometry", "--help"])
    out = capsys.readouterr().out
    assert "examples/flow/loop/run.yaml" in out


def test_dropped_intervals_are_bridged_over_their_length(tmp_path, capsys):
    # 100 whole intervals (0.25 s) cut out of the log: with --allow-missing they are bridged at
    # the last velocity over their real length (before: silently skipped, distance 0.694 -> 0.637 m)
    d = _copy_loop(tmp_path)
    _edit_csv(d / "flow.csv", lambda b: b[:300] + b[600:])
    code, out, err = _run(["flow", "odometry", str(d / "run.yaml"), "--allow-missing", "--out", str(tmp_path / "o"),
                           "--no-progress"], capsys)
    assert code == 0 and "[dropped]" in err and "0.2500 s" in err
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["diagnostics"]["summary"]["bridged_steps"] == 1
    assert res["diagnostics"]["summary"]["invalid_by_reason"]["s60"] == {"dropped interval": 1}
    assert abs(res["estimate"]["distance"] - 0.694) < 0.02


def test_excluded_frames_are_reported_per_sensor(tmp_path, capsys):
    # 60 of 1200 s270 frames (5 %) with quality 0: reported in stdout, warnings and result.json
    d = _copy_loop(tmp_path)

    def zero(b):
        rows = [r for r in b if r[2] == "2"][100:160]
        for r in rows:
            r[9] = "0"
        return b

    _edit_csv(d / "flow.csv", zero)
    code, out, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 0 and "sensor s270: 60 frames without flow (quality 0 in the log 60)" in out
    assert "[low_quality] sensor s270: 60 of 1200 frames (5.0 %)" in err
    summ = json.loads((tmp_path / "o" / "result.json").read_text())["diagnostics"]["summary"]
    assert summ["invalid_frames"] == {"s60": 0, "s120": 0, "s270": 60}
    assert summ["invalid_by_reason"]["s270"] == {"quality 0 in the log": 60}


def test_kernel_options_on_a_flow_log_are_an_error(tmp_path, capsys):
    # --subpixel/--refine/--search act on raw frames; on a flow log they were silently ignored
    for opt in (["--subpixel", "half"], ["--refine", "lk"], ["--search", "6"]):
        code, _, err = _run(["flow", "odometry", str(EX / "loop" / "run.yaml"), *opt, "--out", str(tmp_path / "o"),
                             "--no-progress"], capsys)
        assert code == 2 and f"{opt[0]} acts on raw frames" in err and "flow.csv" in err


def test_flow_sigma_comes_from_run_yaml_and_is_checked(tmp_path, capsys):
    from robocal.rigs.flow.log import load_run, load_steps

    d = _copy_loop(tmp_path)
    st6, _ = load_steps(load_run(d / "run.yaml"))
    # a log whose stated flow noise is 6x too small: the chi-square check says so
    (d / "run.yaml").write_text((d / "run.yaml").read_text().replace("sigma_px: 0.06", "sigma_px: 0.01"))
    st1, _ = load_steps(load_run(d / "run.yaml"))
    assert np.allclose(st1.sigma, st6.sigma / 6)
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 0 and "[inconsistent_data]" in err and "sigma_px" in err
    # another kernel's log (its stated flow error differs): its sub-pixel bias is unknown, --debias is refused
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o3"), "--debias", "--no-progress"], capsys)
    assert code == 2 and "another flow kernel" in err
    code, _, err = _run(["flow", "odometry", str(EX / "loop" / "run.yaml"), "--out", str(tmp_path / "o2"), "--no-progress"], capsys)
    assert code == 0 and "[inconsistent_data]" not in err


def test_calibrate_window_must_be_positive(tmp_path, capsys):
    for w in ("0", "-1"):
        code, _, err = _run(["flow", "calibrate", str(EX / "calibration" / "run.yaml"), "--window", w,
                             "--out", str(tmp_path / "c"), "--no-progress"], capsys)
        assert code == 2 and "--window must be > 0 s" in err


def test_straight_drive_calibration_keeps_undetermined_values_nominal(tmp_path, capsys):
    # a straight drive cannot give R or psi: they stay nominal in stdout, result.json and the YAML
    # (before: R = 0.0 was written, and the array gave NaN trajectories)
    sim = tmp_path / "straight"
    code, _, _ = _run(["flow", "simulate", "--trajectory", "straight", "--duration", "1.5", "--no-frames",
                       "--supersample", "1", "--out", str(sim), "--no-progress"], capsys)
    assert code == 0
    code, out, err = _run(["flow", "calibrate", str(sim / "run.yaml"), "--out", str(tmp_path / "c"), "--no-progress"], capsys)
    assert code == 0 and "not determined by this drive (kept nominal)" in out
    res = json.loads((tmp_path / "c" / "result.json").read_text())
    assert res["estimate"]["s60.R"] == pytest.approx(0.35) and res["std"]["s60.R"] is None
    assert "s60.R" in res["diagnostics"]["undetermined_kept_nominal"]
    text = (tmp_path / "c" / "array_calibrated.yaml").read_text()
    assert "R: 0.0" not in text and "R: 350.0" in text
    code, out, _ = _run(["flow", "evaluate", str(sim / "run.yaml"), "--array", str(tmp_path / "c" / "array_calibrated.yaml"),
                         "--out", str(tmp_path / "e"), "--no-progress"], capsys)
    assert code == 0 and "nan" not in out.lower()


def test_degenerate_array_file_is_a_clear_error(tmp_path, capsys):
    d = _copy_loop(tmp_path)
    text = (d / "run.yaml").read_text()
    (d / "run.yaml").write_text(text.replace("R: 350.0", "R: 0.0"))
    code, _, err = _run(["flow", "odometry", str(d / "run.yaml"), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2 and "run.yaml" in err and "rank < 3" in err and err.count("\n") == 1


def test_simulate_rate_and_short_reference(tmp_path, capsys):
    code, out, err = _run(["flow", "simulate", "--rate", "0", "--out", str(tmp_path / "s"), "--no-progress"], capsys)
    assert code == 2 and "--rate must be > 0 Hz" in err and "ceiling" not in out
    d = _copy_loop(tmp_path)
    lines = (d / "truth.csv").read_text().splitlines()
    (d / "truth.csv").write_text("\n".join(lines[:200]) + "\n")
    code, _, err = _run(["flow", "evaluate", str(d / "run.yaml"), "--out", str(tmp_path / "e"), "--no-progress"], capsys)
    assert code == 2 and "truth.csv" in err and "reference covers" in err


def _frames_run(tmp_path, edit):
    """A copy of the raw-frames example whose frames.npz is rewritten by ``edit(dict) -> dict | bytes``."""
    d = tmp_path / "fr"
    shutil.copytree(EX / "frames", d)
    with np.load(d / "frames.npz") as z:
        data = {k: z[k] for k in z.files}
    new = edit(data)
    if isinstance(new, bytes):
        (d / "frames.npz").write_bytes(new)
    elif isinstance(new, np.ndarray):
        with open(d / "frames.npz", "wb") as fh:
            np.save(fh, new)
    else:
        np.savez(d / "frames.npz", **new)
    return d / "run.yaml"


@pytest.mark.parametrize("edit, message", [
    (lambda d: (EX / "frames" / "frames.npz").read_bytes()[:50_000], "cannot read as .npz"),
    (lambda d: d["frames"], "single .npy array"),
    (lambda d: {k: v for k, v in d.items() if k != "height"}, "missing array(s) height (have: frames, t, gyro)"),
    (lambda d: {**d, "gyro": d["gyro"][:, :-1]}, "gyro must have shape (3, 120, 3)"),
    (lambda d: {**d, "gyro": np.where(np.arange(3)[None, None] == 0, np.nan, d["gyro"])}, "gyro has 360 NaN"),
    (lambda d: {**d, "height": -d["height"]}, "height must be > 0 m: sensor 0, interval 0"),
    (lambda d: {**d, "frames": d["frames"][:, :1], "t": d["t"][:1], "gyro": d["gyro"][:, :0], "height": d["height"][:, :0]},
     "at least 2 frames"),
])
def test_bad_frames_files_name_the_file(tmp_path, capsys, edit, message):
    run = _frames_run(tmp_path, edit)
    code, _, err = _run(["flow", "odometry", str(run), "--out", str(tmp_path / "o"), "--no-progress"], capsys)
    assert code == 2 and message in err and err.startswith(f"robocal: error: {run.parent / 'frames.npz'}")
    assert err.count("\n") == 1 and err.count("frames.npz") == 1


@pytest.mark.parametrize("args, message", [
    (["--supersample", "0"], "--supersample must be >= 1"),
    (["--speed", "-0.2"], "--speed must be >= 0 m/s"),
    (["--duration", "1e6"], "GB of memory to render"),
])
def test_simulate_refuses_bad_arguments(tmp_path, capsys, args, message):
    code, _, err = _run(["flow", "simulate", *args, "--out", str(tmp_path / "s"), "--no-progress"], capsys)
    assert code == 2 and message in err and err.count("\n") == 1


def test_cli_textures_equal_the_simulator_ones():
    """cli repeats them (the ``--texture`` choices) so that building the parser does not import the simulator."""
    from robocal.rigs.flow import cli, simulate

    assert cli.TEXTURES == simulate.TEXTURES
