"""The flow rig from a robot recording (issue 15): ROS 1, ROS 2 and MCAP bags of a simulated drive.

One simulated calibration drive (1.5 s at 400 Hz, 3 sensors, flow log only: ``robocal flow simulate
--no-frames``) is written in each format by :func:`simulate_flow_recording`: one
``mavros_msgs/OpticalFlowRad`` topic per sensor (600 records each) and the true poses as
``nav_msgs/Odometry``. OpticalFlowRad stores floats as float32, so a record read back equals the
flow.csv one to float32 rounding (relative 6e-8), not to the bit.
"""

import json
from functools import lru_cache

import numpy as np
import pytest

from robocal.bags import MissingTopicError
from robocal.cli.main import main
from robocal.errors import FileFormatError, InputError
from robocal.rigs.flow.bag import load_bag_run
from robocal.rigs.flow.log import load_run, read_flow_csv, read_poses_csv
from robocal.rigs.flow.simulate_bag import REFERENCE_TOPIC, flow_topic, simulate_flow_recording
from robocal.rigs.flow.workflow import calibrate_input, calibration_result, load_input

FORMATS = ("rosbag1", "rosbag2", "mcap")


@pytest.fixture(scope="module")
def run_yaml(tmp_path_factory):
    from robocal.rigs.flow.commands import simulate_files

    out = tmp_path_factory.mktemp("flow_sim")
    simulate_files(out, np.random.default_rng(5), progress=False, trajectory="calibration", duration=1.5,
                   supersample=1, no_frames=True)
    return out / "run.yaml"


@pytest.fixture(scope="module")
def recording(tmp_path_factory, run_yaml):
    """``recording(fmt, **options)``: the drive written as ``fmt`` (each asked-for variant written once)."""
    folder = tmp_path_factory.mktemp("flow_bags")

    @lru_cache(maxsize=None)
    def make(fmt, **options):
        name = "-".join([fmt, *(f"{k}{len(v)}" for k, v in sorted(options.items()))])
        path = folder / (f"{name}.bag" if fmt == "rosbag1" else name)
        return simulate_flow_recording(path, run_yaml, format=fmt, **{k: dict(v) for k, v in options.items()})
    return make


@pytest.mark.parametrize("fmt", FORMATS)
def test_records_read_back(recording, run_yaml, fmt):
    # the lowest-pins stage's bag path (fast): the recording gives flow.csv's records and truth.csv's poses
    truth = recording(fmt)
    spec = load_bag_run(truth.path, truth.map)
    file = load_run(run_yaml)
    want = read_flow_csv(file.flow_log, file.array.n)
    got = spec.records
    # grid: whole-microsecond stamps of intervals on a 2.5 ms grid -> exact to double rounding of t
    np.testing.assert_allclose(got.t, want.t, rtol=0, atol=1e-12)
    # float32 fields: flow ~1 px -> 1e-7 px; gyro (rad/s, integrated over 2.5 ms) and height ~1e-8
    np.testing.assert_allclose(got.flow, want.flow, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.gyro, want.gyro, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.height, want.height, rtol=1e-6, atol=0)
    np.testing.assert_array_equal(got.quality, want.quality)
    assert got.present.all()
    t_ref, p_ref = read_poses_csv(file.reference)
    np.testing.assert_allclose(spec.reference_data[0], t_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(spec.reference_data[1], p_ref, rtol=0, atol=1e-9)
    assert spec.warnings == [] and "header times" in spec.notes[0]
    assert spec.array.names == file.array.names and spec.focal_px == pytest.approx(file.focal_px)


def test_calibrates_like_the_file(recording, run_yaml, tmp_path, capsys):
    # the same drive through the file path and through the recording (CLI): the same array, to a tiny
    # fraction of its std (float32 storage moves each estimate by ~1e-6 std on this run)
    truth = recording("mcap")
    want = calibration_result(calibrate_input(load_input(run_yaml)), load_input(run_yaml))
    out = tmp_path / "cal"
    assert main(["flow", "calibrate", "--bag", str(truth.path), "--map", str(truth.map), "--out", str(out)]) == 0
    got = json.loads((out / "result.json").read_text())
    assert set(got["estimate"]) == set(want.estimate) and len(want.estimate) == 12
    for k, v in want.estimate.items():
        assert abs(got["estimate"][k] - v) < 1e-3 * want.std[k], k
    assert any(k.endswith(".mcap") for k in got["inputs"]) and any(k.endswith(".topics.yaml") for k in got["inputs"])
    assert got["diagnostics"]["messages"][0].startswith("recording ")
    assert "note: recording " in capsys.readouterr().out and "messages" not in want.diagnostics


def test_one_line_errors(recording, tmp_path, capsys):
    truth = recording("rosbag1")
    # the map names a topic the recording lacks: the closest names offered
    typo = recording("rosbag1", rename=(("s60", flow_topic("s60")[:-1]),))
    assert main(["flow", "calibrate", "--bag", str(typo.path), "--map", str(typo.map),
                 "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"no topic '{flow_topic('s60')[:-1]}' (closest: {flow_topic('s60')}" in err
    # a bad map file: no topics, a sensor the array lacks, a sensor without topic
    bad = tmp_path / "bad.yaml"
    text = truth.map.read_text()
    bad.write_text(text.split("topics:")[0])
    assert main(["flow", "calibrate", "--bag", str(truth.path), "--map", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "needs 'topics: {flow:" in err and "bad.yaml" in err
    bad.write_text(text.replace("s120: ", "s12: "))
    with pytest.raises(FileFormatError, match=r"'s12' is not a sensor of the array \(closest: s120"):
        load_bag_run(truth.path, bad)
    # no --map; a run.yaml and --bag both; the reference topic of another type
    assert main(["flow", "calibrate", "--bag", str(truth.path), "--out", str(tmp_path / "c")]) == 2
    assert "--bag needs --map topics.yaml" in capsys.readouterr().err
    with pytest.raises(InputError, match="not both"):
        load_input(truth.run, bag=truth.path, map=truth.map)
    bad.write_text(text.replace(REFERENCE_TOPIC, flow_topic("s60")))
    with pytest.raises(InputError, match="OpticalFlowRad"):
        load_bag_run(truth.path, bad)
    bad.write_text(text.replace(REFERENCE_TOPIC, "/ground_truth/odm"))
    with pytest.raises(MissingTopicError, match=f"closest: {REFERENCE_TOPIC}"):
        load_bag_run(truth.path, bad)


def test_clock_mismatch_named(recording):
    # the reference stamped on another clock (1000 s ahead): named, and every stream placed at receive times
    truth = recording("rosbag1", clock_offset=(("reference", 1000.0),))
    spec = load_bag_run(truth.path, truth.map)
    (w,) = spec.warnings
    # 1000 s less the difference of the recorder's latencies (5 ms odometry, 1 ms flow)
    assert w.code == "clock_mismatch" and f"{REFERENCE_TOPIC} (-999.996 s)" in w.message
    assert "receive times" in spec.notes[0]
    # on receive times the reference still covers the flow (the recorder's latencies differ by 4 ms)
    t_ref = spec.reference_data[0]
    assert t_ref[0] <= spec.records.t[0] + 0.01 and t_ref[-1] >= spec.records.t[-1] - 0.01


def test_odometry_like_the_file(recording, run_yaml, tmp_path, capsys):
    # `robocal flow odometry --bag`: the file path's trajectory, to float32 rounding of the records
    # (flow ~1e-7 px per step, summed over 600 steps at ~0.6 mm/px: far below 1e-6 m)
    truth = recording("rosbag2")
    a, b = tmp_path / "file", tmp_path / "bag"
    assert main(["flow", "odometry", str(run_yaml), "--no-report", "--out", str(a)]) == 0
    assert main(["flow", "odometry", "--bag", str(truth.path), "--map", str(truth.map), "--no-report",
                 "--out", str(b)]) == 0
    t_a, p_a = read_poses_csv(a / "trajectory.csv")
    t_b, p_b = read_poses_csv(b / "trajectory.csv")
    np.testing.assert_allclose(t_b, t_a, rtol=0, atol=1e-9)
    np.testing.assert_allclose(p_b, p_a, rtol=0, atol=1e-6)
    ra, rb = (json.loads((d / "result.json").read_text()) for d in (a, b))
    assert rb["estimate"]["ate_rmse"] == pytest.approx(ra["estimate"]["ate_rmse"], abs=1e-6)
    assert main(["flow", "odometry", "--out", str(tmp_path / "none")]) == 2
    assert "give a run.yaml, or a recording with --bag FILE --map topics.yaml" in capsys.readouterr().err


def test_sensor_on_another_clock(recording, run_yaml):
    # one sensor stamping 1000 s ahead: on header stamps it would never overlap the others; named, and on
    # receive times (every flow topic 1 ms after its stamp) the records are flow.csv's again
    truth = recording("mcap", clock_offset=(("s120", 1000.0),))
    spec = load_bag_run(truth.path, truth.map)
    (w,) = spec.warnings
    assert w.code == "clock_mismatch" and f"{flow_topic('s120')} (-1000.000 s)" in w.message
    file = load_run(run_yaml)
    want = read_flow_csv(file.flow_log, file.array.n)
    np.testing.assert_allclose(spec.records.t, want.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(spec.records.flow, want.flow, rtol=0, atol=1e-6)


def test_ros2_bag_without_definitions(recording, tmp_path):
    # a Humble rosbag2 stores no message definitions: OpticalFlowRad (not in ROS 2's own store) still decodes
    import shutil
    import sqlite3

    truth = recording("rosbag2")
    bare = tmp_path / "humble"
    shutil.copytree(truth.path, bare)
    (db3,) = bare.glob("*.db3")
    with sqlite3.connect(db3) as c:
        c.execute("delete from message_definitions")
    np.testing.assert_array_equal(load_bag_run(bare, truth.map).records.flow,
                                  load_bag_run(truth.path, truth.map).records.flow)
