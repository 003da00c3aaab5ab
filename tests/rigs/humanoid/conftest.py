import numpy as np
import pytest

from robocal.rigs.humanoid.model import default_model
from robocal.rigs.humanoid.simulate import simulate_dataset


@pytest.fixture(scope="session")
def model():
    return default_model()


@pytest.fixture(scope="session")
def tied_model():
    return default_model(tie_hip_yaw_pitch=True)


@pytest.fixture(scope="session")
def corner_data(model):
    """10 views per foot, corners with 0.3 px noise, readings quantised to 0.1 deg."""
    return simulate_dataset(model, np.random.default_rng(11), n_per_foot=10)
