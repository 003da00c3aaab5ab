"""Sizes (issue 18): the joint solve's dense Jacobian grows with the square of the placements; beyond the
memory at hand it is refused in one line before any work."""

import numpy as np
import pytest

from robocal.errors import ResourceError
from robocal.rigs.mirror.calibrate import calibrate
from robocal.rigs.mirror.simulate import default_setup, simulate_observations


def test_joint_solve_beyond_the_memory_at_hand_is_refused_before_work(monkeypatch):
    rng = np.random.default_rng(3)
    cam, scene = default_setup(4, rng)
    obs = simulate_observations(cam, scene, rng, sigma_px=0.5)
    # 4 placements x (4 markers + 20 points): 8 x 8 B x 192 rows x 30 columns = 369 kB; pretend 100 kB are free
    monkeypatch.setattr("robocal.resources.available_memory", lambda: 100_000)
    with pytest.raises(ResourceError, match=r"the joint solve of 4 mirror placements \(96 points; dense, grows with "
                                            r"the square of the placements\) needs 360\.0 KiB of memory, 97\.7 KiB "
                                            r"available"):
        calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    # --no-refine averages the single-image estimates: no joint problem, no such memory
    calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5, refine=False)
    monkeypatch.setattr("robocal.resources.available_memory", lambda: 10_000_000)
    calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
