"""What a user gets wrong, and damaged files: each is one line naming the file (a RobocalError, never a traceback)."""

import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import robocal.bags as bags
from robocal.errors import FileFormatError, InputError, RobocalError


def _read_everything(path):
    bags.read_tf(path, show_progress=False).lookup("odom", "camera_optical")
    bags.read_joint_states(path, show_progress=False)
    bags.read_camera_info(path, "/camera/camera_info")
    bags.read_arrays(path, "/odom", show_progress=False)
    for _ in bags.images(path, "/camera/image_raw", show_progress=False):
        pass


def _one_line_naming(exc, path):
    text = str(exc.value) if hasattr(exc, "value") else str(exc)
    assert "\n" not in text and str(path) in text, text
    return text


def test_missing_topic_offers_the_closest(recording):
    with pytest.raises(bags.MissingTopicError) as exc:
        bags.read_joint_states(recording.path, "/joint_state")
    assert "(closest: /joint_states" in _one_line_naming(exc, recording.path)


def test_topic_of_another_type(recording):
    with pytest.raises(InputError, match="holds sensor_msgs/msg/Image, expected sensor_msgs/msg/JointState") as exc:
        bags.read_joint_states(recording.path, "/camera/image_raw")
    _one_line_naming(exc, recording.path)


def test_frame_typo_offers_the_closest(recording):
    with pytest.raises(bags.UnknownFrameError) as exc:
        bags.poses(recording.path, "odom", "base_lnik")
    assert "no tf frame 'base_lnik' (closest: base_link" in _one_line_naming(exc, recording.path)


def test_frames_of_two_unconnected_trees(tmp_path):
    from robocal.bags._simulate import _Writer

    path = tmp_path / "two_trees.bag"
    with _Writer(path, "rosbag1") as w:
        w.write("/tf_static", "tf2_msgs/msg/TFMessage", 10**18, w.tf([
            w.transform(10**18, "a", "b", np.eye(4)), w.transform(10**18, "c", "d", np.eye(4))]))
    with pytest.raises(bags.UnknownFrameError, match="'a'.*'d'.*not connected") as exc:
        bags.poses(path, "a", "d")
    _one_line_naming(exc, path)


def test_missing_file_and_wrong_suffix(tmp_path):
    with pytest.raises(InputError, match="no such recording"):
        bags.read_tf(tmp_path / "nothere.bag")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(FileFormatError, match="not a recording"):
        bags.read_tf(tmp_path / "notes.txt")
    (tmp_path / "folder").mkdir()
    with pytest.raises(FileFormatError, match="without metadata.yaml"):
        bags.read_tf(tmp_path / "folder")


def _main_file(truth, tmp_path):
    """A copy of the recording's data file: the .bag, or the .db3 / .mcap without its metadata.yaml."""
    src = truth.path if truth.path.is_file() else next(p for p in truth.path.iterdir() if p.suffix in (".db3", ".mcap"))
    dst = tmp_path / src.name
    shutil.copyfile(src, dst)
    return dst


@pytest.mark.parametrize("keep", [0.5, 0.98])
def test_truncated_recording(recording, tmp_path, keep):
    path = _main_file(recording, tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[:int(keep * len(data))])
    with pytest.raises(FileFormatError, match="truncated or unindexed") as exc:
        _read_everything(path)
    _one_line_naming(exc, path)


def test_unindexed_ros1_bag(recordings, tmp_path):
    # a recorder killed before closing leaves index_pos = 0 in the bag header (ROS 1 bag format 2.0)
    path = _main_file(recordings["rosbag1"], tmp_path)
    data = bytearray(path.read_bytes())
    at = data.index(b"index_pos=") + len(b"index_pos=")
    data[at:at + 8] = bytes(8)
    path.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match="not indexed.*rosbag reindex") as exc:
        bags.read_tf(path)
    _one_line_naming(exc, path)


@pytest.fixture(scope="module")
def small_bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    return {f: bags.simulate_recording(root / ("s.bag" if f == "rosbag1" else f"s_{f}"), format=f, duration=0.3,
                                       tf_rate=20, joint_rate=20, image_rate=5, image_size=(32, 24))
            for f in bags.RECORDING_FORMATS}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fmt=st.sampled_from(bags.RECORDING_FORMATS),
       edits=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=8),
       cut=st.one_of(st.none(), st.floats(0, 1)))
def test_fuzz_corrupted_recording_is_one_line_error(small_bags, tmp_path_factory, fmt, edits, cut):
    path = _main_file(small_bags[fmt], tmp_path_factory.mktemp("c"))
    data = bytearray(path.read_bytes())
    for where, value in edits:
        data[int(where * len(data))] = value
    if cut is not None:
        data = data[:int(cut * len(data))]
    path.write_bytes(bytes(data))
    try:
        _read_everything(path)  # a byte in image pixels or padding changes nothing that is checked
    except RobocalError as exc:
        _one_line_naming(exc, path)
