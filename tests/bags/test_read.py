"""Reading the simulated recordings back: every stream against the truth it was written from."""

import numpy as np
import pytest

import robocal.bags as bags
from robocal.errors import InputError
from robocal.bags._simulate import LATENCY_NS, expected_image
from robocal.geometry import invert_transform
from robocal.io import interpolate_poses

# Poses go through a quaternion (float64) and 4x4 products: ~1e-16 relative; 1e-12 m / rad is far above
# that rounding and far below any real error (a wrong frame or an inverted transform is ~0.1).
TOL = 1e-12


def _rot_err(Ra, Rb):
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.swapaxes(Ra, -1, -2) @ Rb).magnitude()


def assert_poses(Ta, Tb, tol=TOL):
    assert np.max(np.abs(Ta[:, :3, 3] - Tb[:, :3, 3])) < tol
    assert np.max(_rot_err(Ta[:, :3, :3], Tb[:, :3, :3])) < tol


def test_a_bare_db3_or_mcap_file_reads_like_its_folder(recording):
    files = [p for p in recording.path.iterdir() if p.suffix in (".db3", ".mcap")] if recording.path.is_dir() else []
    for path in [recording.path, *files]:
        with bags.open_recording(path) as rec:
            assert rec.topics["/joint_states"].count == len(recording.joint_stamps_ns)


def test_dynamic_tf_at_its_samples_is_exact(recording):
    ps = bags.poses(recording.path, "odom", "base_link")
    assert np.array_equal(ps.stamps_ns, recording.tf_stamps_ns)
    assert_poses(ps.T, recording.T_odom_base)
    assert np.all(ps.gap == 0) and ps.edges == (("odom", "base_link", "dynamic"),)


def test_static_chain_and_inverse_direction(recording):
    T_bo = recording.T_base_camera_link @ recording.T_camera_link_optical
    ps = bags.poses(recording.path, "base_link", "camera_optical")
    assert [e[2] for e in ps.edges] == ["static", "static"]
    assert_poses(ps.T, T_bo[None])
    inv = bags.poses(recording.path, "/camera_optical", "/base_link")  # ROS 1 spelling with a leading slash
    assert_poses(inv.T, invert_transform(T_bo)[None])


def test_chain_across_two_dynamic_edges_interpolates_and_reports_the_gap(recording):
    # tool0 at 100 Hz, base_link at 50 Hz: every other tool0 stamp falls half-way between two base samples
    q = recording.tool_stamps_ns[(recording.tool_stamps_ns <= recording.tf_stamps_ns[-1])]
    ps = bags.poses(recording.path, "camera_optical", "tool0", q)
    t = (recording.tf_stamps_ns - q[0]) / 1e9
    T_ob = interpolate_poses(t, recording.T_odom_base, (q - q[0]) / 1e9)
    T_co = recording.T_base_camera_link @ recording.T_camera_link_optical
    assert_poses(ps.T, invert_transform(T_co) @ recording.T_base_tool[:len(q)])
    # through odom: odom -> tool0 needs base_link interpolated
    ps2 = bags.poses(recording.path, "odom", "tool0", q)
    assert_poses(ps2.T, T_ob @ recording.T_base_tool[:len(q)])
    # the gap: 0 on base_link's samples, half its 20 ms period in between (stamps are exact integer ns)
    assert np.array_equal(ps2.gap, np.where(np.arange(len(q)) % 2 == 1, 0.01, 0.0))


def test_float_second_stamps_are_accepted(recording):
    s = recording.tf_stamps_ns[3:6]
    ps = bags.poses(recording.path, "odom", "base_link", s / 1e9)
    # epoch seconds in float64 resolve 0.24 us: at <= 1 m/s and 1 rad/s that is < 1e-6 m / rad
    assert_poses(ps.T, recording.T_odom_base[3:6], tol=1e-6)
    assert ps.gap.max() < 1e-6


def test_no_extrapolation_beyond_a_dynamic_edge(recording):
    late = recording.tf_stamps_ns[-1] + 10**9
    with pytest.raises(InputError, match="no extrapolation"):
        bags.poses(recording.path, "odom", "base_link", np.array([late]))


def test_joint_states_by_name_and_both_clocks(recording):
    js = bags.read_joint_states(recording.path)
    assert js.names == recording.joint_names
    assert np.array_equal(js.position, recording.joint_positions)  # float64 written and read: bit for bit
    assert np.array_equal(js.velocity, recording.joint_velocities)
    assert np.array_equal(js["joint_3"], recording.joint_positions[:, 2])
    assert np.array_equal(js.stamps_ns, recording.joint_stamps_ns)
    # receive time = header + the simulated transport latency (1 ms), to float64 rounding of epoch seconds
    assert np.all(js.receive_ns - js.stamps_ns == LATENCY_NS["joints"])
    assert js.clock_offset == LATENCY_NS["joints"] / 1e9
    assert np.allclose(js.receive_stamps - js.stamps, LATENCY_NS["joints"] / 1e9, atol=1e-6)


@pytest.mark.parametrize("encoding", ["mono8", "bgr8", "rgb8", "mono16", "png"])
def test_images_bit_exact(recording, encoding):
    topic = recording.image_topics[encoding]
    got = list(bags.images(recording.path, topic))
    assert [n for n, _ in got] == [bags.image_name(topic, int(s)) for s in recording.image_stamps_ns]
    for (_, img), truth in zip(got, recording.images):
        want = expected_image(truth, encoding)
        assert img.dtype == want.dtype and img.shape == want.shape
        assert np.array_equal(img, want)


def test_only_the_frames_asked_for_are_decoded(recording, monkeypatch):
    import robocal.bags._messages as m

    calls = []
    real = m.image_from_message
    monkeypatch.setattr(m, "image_from_message", lambda *a, **k: calls.append(1) or real(*a, **k))
    pick = recording.image_stamps_ns[[1, 3]]
    got = list(bags.images(recording.path, "/camera/image_raw", pick))
    assert len(got) == 2 and len(calls) == 2
    assert np.array_equal(got[1][1], recording.images[3])
    with pytest.raises(InputError, match="nearest frame"):
        list(bags.images(recording.path, "/camera/image_raw", np.array([pick[0] + 10**8])))


def test_camera_info_gives_the_camera(recording):
    assert bags.read_camera_info(recording.path, "/camera/camera_info") == recording.camera


def test_odometry_as_arrays(recording):
    odom = bags.read_arrays(recording.path, "/odom")
    assert odom.frame_id == "odom" and odom.msgtype == "nav_msgs/msg/Odometry"
    assert_poses(odom["T"], recording.T_odom_base)
    assert np.allclose(odom["quaternion"][:, 3] ** 2 + np.sum(odom["quaternion"][:, :3] ** 2, 1), 1.0)
    assert np.array_equal(odom["linear"], np.tile([0.1, 0.2, 0.3], (len(odom.stamps), 1)))


@pytest.mark.parametrize("fmt", ["rosbag1", "mcap"])
@pytest.mark.parametrize("model, d", [("plumb_bob", [-0.1, 0.02, 1e-3, -2e-3, 0.004]),
                                      ("rational_polynomial", [-0.1, 0.02, 1e-3, -2e-3, 0.004, 0.1, -0.01, 0.002]),
                                      ("equidistant", [0.05, -0.01, 0.002, -1e-4]),
                                      ("", [])])  # an uncalibrated driver: no model, no coefficients
def test_camera_info_models(tmp_path, fmt, model, d):
    from robocal.bags._simulate import _Writer
    from robocal.camera import CameraModel, FisheyeCamera

    path = tmp_path / ("c.bag" if fmt == "rosbag1" else "c")
    K = [500.0, 0.0, 320.5, 0.0, 505.0, 240.25, 0.0, 0.0, 1.0]
    with _Writer(path, fmt) as w:
        names = ("D", "K", "R", "P") if fmt == "rosbag1" else ("d", "k", "r", "p")
        roi = w.msg("sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        msg = w.msg("sensor_msgs/msg/CameraInfo", header=w.header(10**18, "cam"), height=480, width=640,
                    distortion_model=model, binning_x=0, binning_y=0, roi=roi,
                    **dict(zip(names, (np.array(d, float), np.array(K), np.eye(3).ravel(), np.zeros(12)))))
        w.write("/cam/camera_info", "sensor_msgs/msg/CameraInfo", 10**18, msg)
    cam = bags.read_camera_info(path, "/cam/camera_info")
    if model == "equidistant":
        assert cam == FisheyeCamera(500.0, 505.0, 320.5, 240.25, np.array(d), 640, 480)
    else:
        assert cam == CameraModel(500.0, 505.0, 320.5, 240.25, np.array(d or [0.0] * 5), 640, 480)


def test_raw_image_rows_padding_and_byte_order():
    from types import SimpleNamespace

    from robocal.bags import image_from_message
    from robocal.errors import FileFormatError

    img = np.arange(12, dtype=np.uint16).reshape(3, 4) * 4099
    big = np.zeros((3, 10), np.uint8)  # 8 bytes of pixels + 2 bytes of padding per row (step 10)
    big[:, :8] = img.astype(">u2").view(np.uint8)
    msg = SimpleNamespace(data=big.ravel(), encoding="mono16", height=3, width=4, step=10, is_bigendian=1)
    out = image_from_message(msg, "sensor_msgs/msg/Image")
    assert out.dtype == np.uint16 and np.array_equal(out, img)
    short = SimpleNamespace(**{**vars(msg), "data": big.ravel()[:25]})
    with pytest.raises(FileFormatError, match="4x3 mono16 image needs 3 rows of >= 8 bytes"):
        image_from_message(short, "sensor_msgs/msg/Image", source="x.bag")
    with pytest.raises(InputError, match="encoding 'yuv422' is not supported"):
        image_from_message(SimpleNamespace(**{**vars(msg), "encoding": "yuv422"}), "sensor_msgs/msg/Image")


@pytest.mark.parametrize("fmt", ["rosbag1", "rosbag2", "mcap"])
def test_compressed_recordings(tmp_path, fmt):
    truth = bags.simulate_recording(tmp_path / ("z.bag" if fmt == "rosbag1" else "z"), format=fmt, duration=0.5,
                                    image_size=(48, 32), encodings=("mono8",), compress=True)
    with bags.open_recording(truth.path) as rec:
        assert_poses(bags.poses(rec, "odom", "base_link").T, truth.T_odom_base)
        assert np.array_equal(bags.read_joint_states(rec).position, truth.joint_positions)
        assert all(np.array_equal(img, want) for (_, img), want in zip(bags.images(rec, "/camera/image_raw"), truth.images))


def test_joint_states_from_two_drivers_on_one_topic(tmp_path):
    from robocal.bags._simulate import _Writer

    path = tmp_path / "two.bag"
    with _Writer(path, "rosbag1") as w:
        for k, (names, pos, vel) in enumerate([(["a", "b"], [1.0, 2.0], [0.1, 0.2]), (["c"], [3.0], []),
                                               (["b", "a"], [5.0, 4.0], [0.5, 0.4])]):
            w.write("/joint_states", "sensor_msgs/msg/JointState", 10**18 + k, w.msg(
                "sensor_msgs/msg/JointState", header=w.header(10**18 + k, ""), name=names,
                position=np.array(pos), velocity=np.array(vel), effort=np.zeros(0)))
    js = bags.read_joint_states(path)
    assert js.names == ("a", "b", "c")
    nan = np.nan
    assert np.array_equal(js.position, [[1, 2, nan], [nan, nan, 3], [4, 5, nan]], equal_nan=True)
    assert np.array_equal(js.velocity, [[0.1, 0.2, nan], [nan, nan, nan], [0.4, 0.5, nan]], equal_nan=True)
    assert np.all(np.isnan(js.effort))
