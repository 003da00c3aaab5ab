"""Calibration wall time of the humanoid rig: analytic Jacobian vs finite differences.

Two data sets, corner-level simulation (0.3 px noise, readings quantised to
0.1 deg), the seed's 21 parameters, LM from zero (both passes of
:func:`robocal.rigs.humanoid.calibrate`, i.e. everything a user waits for
after detection):

* realistic: 10 views per foot (20 images, 480 corners) -- about three times
  the seed's 3 runs x 3 views x 2 boards;
* 10x: 100 views per foot (200 images, 4800 corners).

Methods, measured in the same run on the same data:

* ``analytic`` -- the model's analytic Jacobian (:meth:`HumanoidModel.project`);
* ``2-point`` -- SciPy's forward differences through the estimation layer.

The Jacobian is dense in the parameters (every corner depends on the camera,
its leg's 6 joints and its board: 12 of 21 columns), so a sparse solver has
nothing to gain here and is not offered. The two estimates are checked to
agree (1e-6 rad) before timing. Ratio = finite differences / analytic
(> 1: analytic faster). Also timed: rendering and detecting one image, and
the robust homography check of its corners (:func:`homography_outliers`).

Run: ``python bench/bench_humanoid.py`` (``--quick``: one repetition).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

import robocal
from robocal.camera import detect_checkerboard
from robocal.rigs.humanoid.calibrate import calibrate
from robocal.rigs.humanoid.detect import homography_outliers, render_view
from robocal.rigs.humanoid.model import default_model
from robocal.rigs.humanoid.simulate import simulate_dataset


def best_of(fn, reps):
    times, out = [], None
    for _ in range(reps):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    reps = 1 if args.quick else 3
    model = default_model()
    rng = np.random.default_rng(2026)
    print(f"robocal {robocal.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}")
    rows = []
    for label, npf in (("realistic (20 views)", 10), ("10x (200 views)", 100)):
        data = simulate_dataset(model, rng, n_per_foot=npf)
        t_a, ca = best_of(lambda: calibrate(model, data), reps)
        t_f, cf = best_of(lambda: calibrate(model, data, jac="2-point"), reps)
        diff = float(np.max(np.abs(ca.params - cf.params)))
        if diff > 1e-6:
            print(f"estimates disagree by {diff:.3g}", file=sys.stderr)
            return 1
        rows.append((label, data.n_views * 24, t_a, t_f, ca.first_iterations + ca.lsq.iterations,
                     ca.lsq.nfev, cf.lsq.nfev))
    print()
    print("| data set | corners | analytic [s] | 2-point FD [s] | FD / analytic | LM iterations (2 passes) |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, nc, ta, tf, it, _, _ in rows:
        print(f"| {label} | {nc} | {ta:.3f} | {tf:.3f} | {tf / ta:.1f} | {it} |")
    # image side, for scale
    data = simulate_dataset(model, rng, n_per_foot=2)
    th, feet = data.theta, data.feet
    t_r, imgs = best_of(lambda: [render_view(model, th[v], feet[v], data.truth.params, rng)
                                 for v in range(len(th))], reps)
    exp = model.project(th, feet, data.truth.params)
    t_d, uvs = best_of(lambda: [detect_checkerboard(imgs[v], model.board, expected_uv=exp[v])
                                for v in range(len(th))], reps)
    t_h, _ = best_of(lambda: [homography_outliers(model, uv) for uv in uvs], reps)
    print()
    print(f"render one 640x480 view: {1e3 * t_r / len(th):.0f} ms; detect its corners "
          f"(findChessboardCorners + cornerSubPix; SB only as fallback): {1e3 * t_d / len(th):.0f} ms; "
          f"check them against the board's homography: {1e3 * t_h / len(th):.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
