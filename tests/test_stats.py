"""``robocal._stats.median``: np.median's value to the bit, without its numpy.ma import."""

import subprocess
import sys

import numpy as np


def test_median_is_numpys_to_the_bit():
    """The same value, not a close one, for odd and even sizes, below and above NumPy's small-array paths;
    NaN as NumPy."""
    from robocal._stats import median

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 7, 10, 599, 600, 601, 12000):
        a = rng.normal(size=n) * 10.0 ** rng.uniform(-6, 6, size=n)
        assert median(a) == np.median(a), n
        a[n // 3] = np.nan
        assert np.isnan(median(a)) and np.isnan(np.median(a))
    assert np.isnan(median([]))


def test_the_flow_rig_and_the_hand_eye_check_use_it_and_numpy_ma_stays_out():
    import robocal.handeye.motions as motions
    import robocal.rigs.flow.model as model
    from robocal._stats import median

    assert model.median is median and motions.median is median
    # NumPy 1.x imports numpy.ma with numpy itself (the lowest pins): the claim is that median adds no import
    code = ("import sys; from robocal._stats import median; before = 'numpy.ma' in sys.modules; "
            "median([3.0, 1.0, 2.0]); median([4.0, 1.0]); print(before, 'numpy.ma' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, after = out.stdout.split()
    assert after == before
