"""Hand-eye honesty on simulated images (issue 13): the Monte Carlo NEES of X with image noise, the
jackknife std against the first-order one, the clock offset's std against its spread.

Run: python bench/bench_handeye_nees.py [--trials 200] [--views 8] [--sigma-px 0.3]

* NEES: :func:`robocal.handeye.nees.nees_image_noise` (corners of the 7 x 5 board of ``handeye
  simulate-images`` with Gaussian pixel noise -> planar PnP with covariance per view -> X refined on
  closures whitened by each view's covariance, or weighted by the views' stds only), both set-ups; mean
  NEES / 6 with its standard error, the median, the share of trials above chi-square(6)'s 95 % quantile,
  and per component RMS(error) / RMS(reported std).
* jackknife: 50 data sets of 30 simulated poses (1 mrad / 0.2 mm): jackknife std / first-order std.
* clock: 40 simulated streams (15 s, 100 Hz robot, 10 Hz camera, 37 ms offset): spread of the refined
  offset / RMS of its std, and the 7-dof NEES of (X, offset).

Seed 0 throughout; prints Markdown tables (docs/handeye.md, BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import chi2


def nees_table(trials: int, views: int, sigma_px: float) -> None:
    from robocal.handeye.nees import nees_image_noise

    print("| set-up | weights | trials x views | mean NEES / 6 (+/- se) | median / 6 | > chi2(6) 95 % | "
          "RMS err / RMS std (rx ry rz tx ty tz) | max NEES | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for setup, full in (("eye-in-hand", False), ("eye-in-hand", True), ("eye-to-hand", True)):
        t0 = time.perf_counter()
        st = nees_image_noise(np.random.default_rng(0), trials, n_views=views, sigma_px=sigma_px, setup=setup,
                              full_covariance=full)
        ratio = np.sqrt(np.mean(st.errors ** 2, axis=0) / np.mean(st.std ** 2, axis=0))
        print(f"| {setup} | {'full covariance' if full else 'per-view stds'} | {trials} x {views} | {st.mean:.3f} "
              f"+/- {st.se:.3f} | {np.median(st.nees) / 6:.3f} | {np.mean(st.nees > chi2.ppf(0.95, 6)):.1%} | "
              f"{' '.join(f'{r:.2f}' for r in ratio)} | {st.nees.max():.1f} | {time.perf_counter() - t0:.0f} |",
              flush=True)


def jackknife_table(sets: int = 50, n: int = 30) -> None:
    from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand
    from robocal.handeye.jackknife import jackknife_hand_eye

    rng = np.random.default_rng(0)
    r = []
    for _ in range(sets):
        s = simulate_eye_in_hand(rng, n)
        res = calibrate_hand_eye(s.T_base_gripper, s.T_cam_target)
        r.append(jackknife_hand_eye(s.T_base_gripper, s.T_cam_target, res.X, res.Y).std / np.sqrt(np.diag(res.cov)))
    r = np.array(r)
    print(f"\njackknife / first-order std, {sets} sets of {n} poses (delete-one): mean "
          + " ".join(f"{v:.2f}" for v in r.mean(0)) + " (rx ry rz tx ty tz); sd across sets "
          + " ".join(f"{v:.2f}" for v in r.std(0, ddof=1)))


def clock_table(trials: int = 40) -> None:
    from robocal.geometry import PoseWithCovariance
    from robocal.handeye import calibrate_hand_eye
    from robocal.handeye.clock import pair_streams, refine_with_clock, simulate_streams

    rng = np.random.default_rng(0)
    err, std, nees = [], [], []
    for _ in range(trials):
        s = simulate_streams(rng, duration=15.0)
        p = pair_streams(s.t_robot, s.T_base_gripper, s.t_cam, s.T_cam_target, "auto")
        res = calibrate_hand_eye(p.T_base_gripper, p.T_cam_target, pairs="consecutive", refine=False)
        c = refine_with_clock(p, res.X, res.Y)
        v = np.r_[PoseWithCovariance(c.X).error_to(s.X).vector, c.clock_offset - s.clock_offset]
        idx = [0, 1, 2, 3, 4, 5, 12]
        nees.append(v @ np.linalg.solve(c.cov[np.ix_(idx, idx)], v))
        err.append(v[-1])
        std.append(c.clock_offset_std)
    err, std = np.array(err), np.array(std)
    print(f"\nclock offset, {trials} streams of 15 s (140 camera samples): error mean {1e3 * err.mean():.4f} ms, "
          f"spread {1e3 * err.std(ddof=1):.4f} ms, RMS reported std {1e3 * np.sqrt(np.mean(std ** 2)):.4f} ms "
          f"(ratio {err.std(ddof=1) / np.sqrt(np.mean(std ** 2)):.2f}); NEES of (X, offset) / 7: "
          f"{np.mean(nees) / 7:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--sigma-px", type=float, default=0.3)
    a = ap.parse_args()
    nees_table(a.trials, a.views, a.sigma_px)
    jackknife_table()
    clock_table()


if __name__ == "__main__":
    main()
