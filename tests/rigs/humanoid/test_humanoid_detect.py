"""A board found with a wrong corner is dropped, not used (audit issue 4, defect 3)."""

import numpy as np

from robocal.rigs.humanoid import simulate as sim
from robocal.rigs.humanoid.detect import homography_outliers


def test_homography_check_flags_one_gross_corner_only(model, corner_data):
    rng = np.random.default_rng(3)
    uv = corner_data.corners[0]
    assert homography_outliers(model, uv)[0].size == 0  # 0.3 px noise: nothing flagged
    for v in range(corner_data.n_views):  # 20 views x 24 corners, no false alarm
        assert homography_outliers(model, corner_data.corners[v])[0].size == 0
    bad = uv.copy()
    bad[18] += [1.0, -5.0]
    idx, err, tol = homography_outliers(model, bad + rng.normal(0, 0.01, bad.shape))
    assert idx.tolist() == [18] and err[18] > 4.0 and 1.0 <= tol < 2.5  # 6 sigma of 0.3 px


def test_rendered_view_with_a_misdetected_corner_is_dropped(model, monkeypatch):
    # `simulate --seed 5` before the whole-board rule: view004's corner 18 was found 5.5 px off
    # (an outer square cut by the image border) and used, inflating the measured noise 12x
    rng = np.random.default_rng(5)
    truth = sim.draw_truth(model, rng)
    monkeypatch.setattr(sim, "OUTLINE_MARGIN", -np.inf)  # the old sampler: inner corners only
    feet, q = sim.sample_poses(model, 8, rng, truth=truth, batch=80)
    monkeypatch.undo()
    # the whole-board rule now rejects that pose
    assert not sim._views_ok(model, q[4:5], feet[4], truth.params, 15.0, 0.5, 0.2)[0]
    data = sim.simulate_dataset(model, np.random.default_rng(0), truth=truth, feet=feet[3:5], q=q[3:5],
                                render=True)
    assert np.all(np.isfinite(data.corners[0])) and np.all(np.isnan(data.corners[1]))
    assert len(data.messages) == 1 and "'view001': corner(s) [18]" in data.messages[0]
    assert "view dropped" in data.messages[0]
