"""Line-profiler rig: time of the geometric refinement and of MCT on the example data.

    python bench/bench_lineprofiler_refine.py [--repeats 7]

Prints a Markdown table. ``refine_sphere`` runs on ``robocal.estimation.solve``;
the row "SciPy least_squares alone" solves the same problem (same residuals,
analytic Jacobian, loss, scales and tolerances) with SciPy directly and no
analysis, which is what the rig did before: the difference is the price of the
core's diagnostics (covariance, identifiability, outliers by point). MCT is
timed without and with its first-order covariance (tracker, heights, block
scan and P3 encoder terms).

Times are CPU seconds of this process (``time.process_time``, best of
``--repeats``, BLAS on one thread): the machine is shared, and wall time would
measure the neighbours.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from robocal.io import load_document  # noqa: E402
from robocal.rigs.lineprofiler.calibrate import load_arm, load_mct_file  # noqa: E402
from robocal.rigs.lineprofiler.fpdp import fpdp_calibrate  # noqa: E402
from robocal.rigs.lineprofiler.io import load_profiles_csv  # noqa: E402
from robocal.rigs.lineprofiler.mct import mct_calibrate  # noqa: E402
from robocal.rigs.lineprofiler.refine import refine_sphere  # noqa: E402

EX = Path(__file__).resolve().parents[1] / "examples" / "lineprofiler"


def best(f, repeats):
    times = []
    for _ in range(repeats):
        t = time.process_time()
        out = f()
        times.append(time.process_time() - t)
    return out, min(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args()

    doc = load_document(EX / "fpdp_input.yaml")
    chain = load_arm(doc)
    profiles, q, _ = load_profiles_csv(EX / "fpdp_profiles.csv", dof=chain.dof)
    R = doc.float("sphere_radius", kind="length")
    f = fpdp_calibrate(q, profiles, chain, R)
    used = [profiles[i] for i in f.used]
    hold = [k for k in f.undetermined if k.startswith("X.")]
    args = (q[f.used], used, chain, R, f.X, f.Q)
    g, t_solve = best(lambda: refine_sphere(*args, hold=hold), a.repeats)
    # errors in variables (the calibrate test's joint_sigma: 0.02 mm, 0.35 mrad, 0.02 mm), from the
    # plain refinement as calibrate_sphere runs it
    js = [0.02e-3, 0.35e-3, 0.02e-3]
    ge, t_eiv = best(lambda: refine_sphere(*args[:4], g.X, g.Q, hold=hold, joint_sigma=js), a.repeats)

    prob = refine_sphere(*args, hold=hold, return_problem=True)
    sc = g.lsq.f_scale / 3

    def scipy_alone():
        ev = prob.evaluator()
        return least_squares(ev.weighted, prob.x0_free, jac=ev.jacobian, method="trf", loss="soft_l1",
                             f_scale=3 * sc, x_scale="jac", xtol=1e-12, ftol=1e-12)

    ls, t_scipy = best(scipy_alone, a.repeats)
    same = np.max(np.abs(ls.x - g.lsq.x))

    mdoc = load_document(EX / "mct_input.yaml")
    mchain = load_arm(mdoc)
    data, _, t_sig, h_sig, dh_sig, enc_sig = load_mct_file(mdoc, mchain)
    _, t_mct = best(lambda: mct_calibrate(data, mchain, covariance=False), a.repeats)
    r, t_mct_cov = best(lambda: mct_calibrate(data, mchain, tracker_sigma=t_sig, height_sigma=h_sig,
                                              dh_sigma=dh_sig, encoder_sigma=enc_sig), max(2, a.repeats // 3))

    print(f"example data: {g.n_points} profile points in {len(used)} profiles (FPDP input); "
          f"{r.n_scan_points} block-scan points (MCT input)\n")
    print("| step | CPU time [ms] |")
    print("|---|---|")
    print(f"| refine_sphere (robocal.estimation.solve + analysis) | {1e3 * t_solve:.0f} |")
    print(f"| same problem, SciPy least_squares alone (no analysis) | {1e3 * t_scipy:.0f} |")
    print(f"| refine_sphere with joint_sigma (one joint correction per pose) | {1e3 * t_eiv:.0f} |")
    print(f"| MCT, no covariance | {1e3 * t_mct:.0f} |")
    print(f"| MCT with covariance (4 sources) | {1e3 * t_mct_cov:.0f} |")
    print(f"\nmax |x_solve - x_scipy| = {same:.3g}; refine iterations {g.lsq.iterations}, "
          f"std X.tx {1e6 * g.std['X.tx']:.2f} um")
    print(f"joint_sigma: {ge.lsq.iterations} core iterations ({ge.lsq.message}), std X.tx "
          f"{1e6 * ge.std['X.tx']:.2f} um")


if __name__ == "__main__":
    main()
