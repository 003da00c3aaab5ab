"""The NEES of X on simulated data whose camera poses come from images (issue 13): corner noise -> planar
PnP with covariance (robocal.handeye.images.view_pose) -> X refined on closures whitened by each view's
covariance, as ``calibrate-images`` does -> NEES."""

import numpy as np

from robocal.handeye.nees import nees_image_noise


def test_nees_with_image_noise_is_honest():
    # 20 trials of 8 views, 0.3 px corner noise. Honest covariances give mean NEES / 6 = nu / (nu - 2) = 1.06
    # (the refinement estimates the noise scale from 36 residual dof); the trial-to-trial spread of NEES / 6
    # is ~0.7, so 20 trials measure the mean to +/- 0.16 (this seed: 1.16): the bound catches a covariance
    # off by a factor ~1.5 in variance. The 0.8-1.25 figure itself rests on bench/bench_handeye_nees.py (200
    # trials per set-up, docs/handeye.md). With the views' stds only (no full covariance) the same 20
    # trials reach a NEES of 37.5, near F(6, 36)'s 1e-4 quantile x 6 (39.2); with them this one's largest is 16
    st = nees_image_noise(np.random.default_rng(0), 20, n_views=8, sigma_px=0.3)
    assert 0.8 <= st.mean <= 1.25, (st.mean, st.se)
    # no trial beyond F(6, 36)'s 1e-4 quantile x 6 (39.2): 20 trials pass it by chance with probability 0.998
    assert st.nees.max() < 39.2, st.nees
