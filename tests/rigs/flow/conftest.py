import numpy as np
import pytest

from robocal.rigs.flow.simulate import load_texture, shifted_pairs


@pytest.fixture(scope="session")
def gravel_pairs():
    """120 frame pairs from the gravel photograph, shifted by known sub-pixel amounts (2x2 binning)."""
    tex, note = load_texture("gravel")
    assert "scikit-image" in note  # the test extra is installed: real photographs, not the fallback
    return shifted_pairs(tex, 120, np.random.default_rng(11), binning=2, max_shift=3.0)
