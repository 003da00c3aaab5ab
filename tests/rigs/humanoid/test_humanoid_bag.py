"""The humanoid rig from a robot recording (issue 15): ROS 1, ROS 2 and MCAP bags of a simulated NAO run.

One rendered run (3 views per foot, a half-size 320 x 240 camera: 4x faster to render and detect) is
written in each format by :func:`simulate_humanoid_recording`: 26 NAO joints at 50 Hz holding each view's
readings for 0.5 s and moving 0.5 s between views, the camera at 4 Hz throughout (so frames taken while
moving, and several frames of each held pose, are in the recording).
"""

import json
from functools import lru_cache

import numpy as np
import pytest

from robocal.bags import MissingTopicError
from robocal.camera import CameraModel
from robocal.cli.main import main
from robocal.errors import InputError, NotEnoughDataError
from robocal.rigs.humanoid.bag import load_bag_input
from robocal.rigs.humanoid.model import HumanoidModel
from robocal.rigs.humanoid.simulate import simulate_dataset
from robocal.rigs.humanoid.simulate_bag import IMAGE_TOPIC, simulate_humanoid_recording
from robocal.rigs.humanoid.workflow import calibrate_input, load_input

FORMATS = ("rosbag1", "rosbag2", "mcap")


@pytest.fixture(scope="module")
def small_model():
    return HumanoidModel.from_urdf(camera=CameraModel(281.25, 281.25, 162.0, 94.5, width=320, height=240))


@pytest.fixture(scope="module")
def recording(tmp_path_factory, small_model):
    """``recording(fmt, **options)``: the run written as ``fmt`` (each asked-for variant written once)."""
    run = simulate_dataset(small_model, np.random.default_rng(3), n_per_foot=3, render=True)
    folder = tmp_path_factory.mktemp("nao_bags")

    @lru_cache(maxsize=None)
    def make(fmt, **options):
        name = "-".join([fmt, *(f"{k}{v}" for k, v in sorted(options.items()))]).replace("/", "")
        path = folder / (f"{name}.bag" if fmt == "rosbag1" else name)
        return simulate_humanoid_recording(path, format=fmt, model=small_model, data=run,
                                           **{k: (dict(v) if k == "rename" else v) for k, v in options.items()})
    return make


def test_views_from_recording(recording):
    # the lowest-pins stage's bag path (fast): per held pose one view, at its readings, its foot found
    truth = recording("rosbag1")
    inp = load_input(bag=truth.path, images=IMAGE_TOPIC)
    data, run = inp.data, truth.data
    assert data.feet == run.feet
    # the held readings (0.1 deg grid) come back through the interpolation: (1 - w) a + w a is a to ~1 ulp
    np.testing.assert_allclose(data.theta, run.theta, rtol=0, atol=1e-12)
    stamps = np.array([int(n.split("@")[1].replace(".", "")) for n in data.names])
    assert np.all((truth.hold_ns[:, 0] <= stamps) & (stamps <= truth.hold_ns[:, 1]))  # each from its own hold
    notes = "\n".join(data.messages)
    n_moving = int(np.sum(~truth.still & (truth.image_stamps_ns > truth.hold_ns[0, 0] - 500_000_000)))
    assert f"{n_moving} frame(s) taken while a joint moved, refused" in notes
    assert "repeat a still pose" in notes and "camera from" in notes and "camera_info" in notes
    # the joint samples are 20 ms apart and the frames fall between them: gaps up to half a period
    assert max(inp.info["bag"]["gap_s"]) <= 0.010 + 1e-9
    assert [p.name for p in inp.info["inputs"]] == [truth.path.name]
    # the images decoded are the rendered ones
    for got, want in zip(data.images, run.images):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("fmt", FORMATS)
def test_calibrates_to_truth(recording, fmt):
    truth = recording(fmt)
    inp = load_input(bag=truth.path, images=IMAGE_TOPIC)
    res = calibrate_input(inp).to_result()
    labels = truth.model.parameter_labels()
    z = {k: (res.estimate[k] - truth.params[labels.index(k)]) / res.std[k] for k in res.estimate}
    # the seed's 21 parameters, each within 3 sigma of the truth (this fixed run: max |z| 2.3)
    assert len(z) == 21 and max(abs(v) for v in z.values()) < 3.0, z


def test_cli_from_recording(recording, tmp_path, capsys):
    truth = recording("mcap")
    out = tmp_path / "cal"
    assert main(["humanoid", "calibrate", "--bag", str(truth.path), "--joints", "/joint_states",
                 "--images", IMAGE_TOPIC, "--out", str(out)]) == 0
    d = json.loads((out / "result.json").read_text())
    assert d["rig"] == "humanoid" and len(d["estimate"]) == 21
    assert any("interpolated at the header stamps" in m for m in d["diagnostics"]["messages"])
    assert any(k.endswith(".mcap") for k in d["inputs"])  # the folder's files are hashed
    assert "note: recording " in capsys.readouterr().out


def test_one_line_errors(recording, tmp_path, capsys):
    truth = recording("rosbag1")
    # a missing topic: the closest names offered
    assert main(["humanoid", "calibrate", "--bag", str(truth.path), "--images", IMAGE_TOPIC[:-1],
                 "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"no topic '{IMAGE_TOPIC[:-1]}' (closest: {IMAGE_TOPIC}" in err
    with pytest.raises(MissingTopicError, match="closest: /joint_states"):
        load_bag_input(truth.path, joints="/joint_state", images=IMAGE_TOPIC)
    # a joint name typo, in the recording or in --joint-map: the closest names offered
    typo = recording("rosbag1", rename=(("LKneePitch", "LKneePich"),))
    with pytest.raises(InputError, match=r"no joint 'LKneePitch' \(closest: LKneePich"):
        load_bag_input(typo.path, images=IMAGE_TOPIC)
    assert load_bag_input(typo.path, images=IMAGE_TOPIC, joint_map=["LKneePitch=LKneePich"]).data.n_views == 6
    with pytest.raises(InputError, match=r"model has no joint 'LKneePich' \(closest: LKneePitch"):
        load_bag_input(truth.path, images=IMAGE_TOPIC, joint_map=["LKneePich=LKneePitch"])
    # no usable image: every frame too far from a joint sample (the gaps are 5 ms, the limit 0.2 ms)
    with pytest.raises(NotEnoughDataError, match=r"no usable image on .*: 26 frame\(s\), 26 too far from a joint"):
        load_bag_input(truth.path, images=IMAGE_TOPIC, max_gap_periods=0.01)
    # no camera: no camera_info beside the images and none given
    blind = recording("rosbag1", camera_info=False)
    assert main(["humanoid", "calibrate", "--bag", str(blind.path), "--images", IMAGE_TOPIC,
                 "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "give --camera-info TOPIC or --camera CAM.yaml" in err
    with pytest.raises(InputError, match="not both"):
        load_input(truth.path, bag=truth.path, images=IMAGE_TOPIC)
    # a camera stamping on another clock (1000 s ahead): every frame off the joint stream, the clocks named
    late = recording("rosbag1", camera_clock_offset=1000.0)
    with pytest.raises(NotEnoughDataError, match=r"26 outside the joint stream; the images' header stamps are on "
                                                 r"another clock"):
        load_bag_input(late.path, images=IMAGE_TOPIC)


def test_joints_in_degrees_named(recording, small_model, tmp_path):
    # a driver publishing degrees: outside the joint limits, within them read as degrees -> the slip named
    from dataclasses import replace

    from robocal.errors import ImplausibleInputError

    run = recording("rosbag1").data
    deg = simulate_humanoid_recording(tmp_path / "deg.bag", model=small_model,
                                      data=replace(run, theta=np.degrees(run.theta)))
    with pytest.raises(ImplausibleInputError, match=r"look like deg, not rad"):
        load_bag_input(deg.path, images=IMAGE_TOPIC)
