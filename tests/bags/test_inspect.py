"""``robocal bag inspect`` and the summary behind it: topics, rates, gaps, clocks, the tf tree."""

import numpy as np
import pytest

import robocal.bags as bags
from robocal.bags._simulate import _Writer
from robocal.cli.main import main


def test_summary_of_the_simulated_recording(recording):
    s = bags.inspect_recording(recording.path, show_progress=False)
    by = {t.name: t for t in s.topics}
    assert by["/joint_states"].count == len(recording.joint_stamps_ns)
    assert by["/joint_states"].rate == pytest.approx(100.0, rel=1e-6)
    assert by["/camera/image_raw"].msgtype == "sensor_msgs/msg/Image"
    assert by["/joint_states"].clock_offset == pytest.approx(1e-3, abs=1e-9)  # the simulated 1 ms latency
    assert by["/tf_static"].clock_offset is None or by["/tf_static"].clock_offset == 0
    assert not s.flagged_clocks and all(not t.gaps for t in s.topics)
    assert sorted(s.tf_edges)[0][:3] == ("base_link", "camera_link", "static")
    assert {(p, c, k) for p, c, k, *_ in s.tf_edges} == {
        ("odom", "base_link", "dynamic"), ("base_link", "tool0", "dynamic"),
        ("base_link", "camera_link", "static"), ("camera_link", "camera_optical", "static")}
    text = s.text()
    assert "    base_link  <- odom  (dynamic, 50.0 Hz, 101 samples)" in text
    assert "gaps (> 3x the topic's median period): none" in text
    assert by["/camera/image_rgb"].detail == "160x120 rgb8"
    assert by["/camera/image_raw/compressed"].detail == "compressed (png)"
    assert by["/camera/camera_info"].detail == "160x120, distortion_model plumb_bob"


def test_a_camera_on_another_clock_is_flagged(tmp_path):
    path = tmp_path / "offset.bag"
    bags.simulate_recording(path, duration=1.0, image_size=(32, 24), camera_clock_offset=5.0)  # header stamps 5 s after their receive
    s = bags.inspect_recording(path, show_progress=False)
    flagged = {t.name for t in s.flagged_clocks}
    assert flagged == {"/camera/image_raw", "/camera/camera_info"}
    assert "AHEAD" in s.flagged_clocks[0].clock_flag and "FLAG /camera/image_raw" in s.text()


def test_gaps_longer_than_three_median_periods(tmp_path):
    path = tmp_path / "gap.bag"
    t = 10**18 + np.round(np.r_[np.arange(20), np.arange(25, 40)] * 1e8).astype(np.int64)  # 10 Hz, 0.6 s pause
    with _Writer(path, "rosbag1") as w:
        for s in t:
            w.write("/v", "geometry_msgs/msg/Vector3Stamped", int(s), w.msg(
                "geometry_msgs/msg/Vector3Stamped", header=w.header(int(s), "base"), vector=w.vec([1, 2, 3])))
    (topic,) = bags.inspect_recording(path, show_progress=False).topics
    assert topic.rate == pytest.approx(10.0) and len(topic.gaps) == 1
    start, length = topic.gaps[0]
    assert start == pytest.approx(1.9) and length == pytest.approx(0.6)


def test_cli_inspect_prints_the_summary(recordings, capsys):
    assert main(["bag", "inspect", str(recordings["mcap"].path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "format: MCAP" in out and "/joint_states" in out and "camera_optical  <- camera_link  (static)" in out


def test_cli_bad_file_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "broken.bag"
    bad.write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    assert main(["bag", "inspect", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(bad) in err and "truncated or unindexed" in err


def test_long_reads_show_the_topic_and_the_fraction_read(recordings, monkeypatch):
    import robocal.bags._reader as r

    bars = []

    def fake_progress(it, *, desc="", total=None, enabled=True):
        bars.append((desc, total, enabled))
        return it

    monkeypatch.setattr(r, "progress", fake_progress)
    monkeypatch.setattr(r, "PROGRESS_MIN_MESSAGES", 100)
    bags.read_joint_states(recordings["rosbag1"].path)
    assert bars == [("/joint_states", len(recordings["rosbag1"].joint_stamps_ns), True)]
    bars.clear()
    bags.read_tf(recordings["rosbag1"].path, show_progress=False)
    assert bars[0][2] is False
