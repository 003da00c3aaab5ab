"""Small simulated recordings of the three kinds, written once per test session (known truth)."""

import pytest

from robocal.bags import RECORDING_FORMATS, simulate_recording

ALL_ENCODINGS = ("mono8", "bgr8", "rgb8", "mono16", "png")


@pytest.fixture(scope="session")
def recordings(tmp_path_factory):
    """``{format: RecordingTruth}``: 2 s, tf at 50/100 Hz, joints at 100 Hz, 5 images of every encoding, 160x120."""
    root = tmp_path_factory.mktemp("recordings")
    names = {"rosbag1": "sim.bag", "rosbag2": "sim_db3", "mcap": "sim_mcap"}
    return {f: simulate_recording(root / names[f], format=f, encodings=ALL_ENCODINGS) for f in RECORDING_FORMATS}


@pytest.fixture(params=RECORDING_FORMATS)
def recording(request, recordings):
    return recordings[request.param]
