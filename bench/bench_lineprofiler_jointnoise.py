"""Line-profiler rig: FPDP vs the geometric refinement with and without joint-noise modelling.

    python bench/bench_lineprofiler_jointnoise.py [--trials 40] [--dh] [--comparisons 12]

Monte Carlo against the simulated truth (16 poses, encoder noise 0.02 mm / 0.02 deg / 0.02 mm on
the recorded joint values; ``--dh`` adds the comparison's 0.3 mm / 0.1 deg D-H errors, a new arm
per trial). Per method: RMS rotation error about the E axes (rotation vector of ``R R_true^T``),
RMS t_x / t_z error, and the median std the method reports. ``--comparisons N`` also runs
``run_comparison`` N times (seeds 100..) and prints the RMS of e_v, e_theta, e_p (seed eqs.
13-15) and how often the refinements' e_theta / e_p exceed FPDP's. Single-threaded BLAS.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from robocal.geometry import rotvec_from_matrix  # noqa: E402
from robocal.rigs.lineprofiler.compare import run_comparison  # noqa: E402
from robocal.rigs.lineprofiler.fpdp import fpdp_calibrate  # noqa: E402
from robocal.rigs.lineprofiler.model import default_rig  # noqa: E402
from robocal.rigs.lineprofiler.refine import refine_sphere  # noqa: E402
from robocal.rigs.lineprofiler.simulate import perturbed_chain, simulate_fpdp  # noqa: E402

SQ = np.array([0.02e-3, np.deg2rad(0.02), 0.02e-3])
LABS = ("X.rx", "X.ry", "X.rz", "X.tx", "X.tz")


def monte_carlo(trials: int, dh: bool) -> None:
    rig = default_rig()
    err = {"FPDP": [], "refine, q exact": [], "refine, joint_sigma": []}
    std = {"refine, q exact": [], "refine, joint_sigma": []}
    t_eiv = []
    for s in range(trials):
        rng = np.random.default_rng(1000 + s)
        chain = perturbed_chain(rig.chain, rng, sigma_length=0.3e-3 if dh else 0.0,
                                sigma_angle=np.deg2rad(0.1) if dh else 0.0)
        d, _ = simulate_fpdp(rig, rng, true_chain=chain, sigma_q=SQ)
        f = fpdp_calibrate(d.q, d.profiles, rig.chain, d.sphere_radius)
        hold = [k for k in f.undetermined if k.startswith("X.")]
        g0 = refine_sphere(d.q, d.profiles, rig.chain, d.sphere_radius, f.X, f.Q, hold=hold)
        t = time.process_time()
        g = refine_sphere(d.q, d.profiles, rig.chain, d.sphere_radius, g0.X, g0.Q, hold=hold, joint_sigma=SQ)
        t_eiv.append(time.process_time() - t)
        for k, X in (("FPDP", f.X), ("refine, q exact", g0.X), ("refine, joint_sigma", g.X)):
            err[k].append(np.r_[rotvec_from_matrix(X[:3, :3] @ rig.X[:3, :3].T), X[[0, 2], 3] - rig.X[[0, 2], 3]])
        for k, r in (("refine, q exact", g0), ("refine, joint_sigma", g)):
            std[k].append([r.std[lab] for lab in LABS])
    print(f"\n{trials} trials, encoder noise 0.02 mm / 0.02 deg{', D-H errors 0.3 mm / 0.1 deg' if dh else ''}; "
          f"joint_sigma refinement CPU {np.median(t_eiv):.2f} s (median)\n")
    print("| method | rotation RMS x/y/z [deg] | reported std [deg] | t_x, t_z RMS [mm] | reported std [mm] |")
    print("|---|---|---|---|---|")
    for k, e in err.items():
        e = np.array(e)
        rms = np.sqrt(np.mean(e**2, axis=0))
        s = np.median(np.array(std[k], float), axis=0) if k in std else None
        fmt = lambda v, sc, n: " / ".join(f"{sc * x:.{n}f}" for x in v)  # noqa: E731
        print(f"| {k} | {fmt(rms[:3], np.rad2deg(1), 3)} | {'-' if s is None else fmt(s[:3], np.rad2deg(1), 3)} | "
              f"{fmt(rms[3:], 1e3, 2)} | {'-' if s is None else fmt(s[3:], 1e3, 3)} |")


def comparisons(n: int) -> None:
    E = {}
    for seed in range(n):
        c = run_comparison(default_rig(), np.random.default_rng(100 + seed))
        for k in c.X:
            e = E.setdefault(k, {"v": [], "th": [], "p": [], "rot": []})
            e["v"] += list(c.e_v[k])
            e["th"] += list(c.e_theta[k])
            e["p"] += list(c.e_p[k])
            e["rot"] += list(c.err_true_rot[k])
    print(f"\n{n} comparisons x 3 runs (run_comparison, seeds 100..{99 + n})\n")
    print("| method | RMS e_v | RMS e_theta [deg] | RMS e_p [mm] | mean rot err vs truth [deg] | e_theta > FPDP's | "
          "e_p > FPDP's |")
    print("|---|---|---|---|---|---|---|")
    f = {a: np.array(b) for a, b in E["FPDP"].items()}
    for k, e in E.items():
        e = {a: np.array(b) for a, b in e.items()}
        rms = lambda v: np.sqrt(np.mean(v**2))  # noqa: E731
        more = "-" if k == "FPDP" else f"{np.mean(e['th'] > f['th']):.0%}"
        more_p = "-" if k == "FPDP" else f"{np.mean(e['p'] > f['p']):.0%}"
        print(f"| {k} | {rms(e['v']):.2e} | {np.rad2deg(rms(e['th'])):.4f} | {1e3 * rms(e['p']):.3f} | "
              f"{np.rad2deg(e['rot'].mean()):.3f} | {more} | {more_p} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--dh", action="store_true", help="add D-H errors (a new arm per trial)")
    ap.add_argument("--comparisons", type=int, default=0, help="also run run_comparison this many times")
    a = ap.parse_args()
    if a.trials > 0:
        monte_carlo(a.trials, a.dh)
    if a.comparisons > 0:
        comparisons(a.comparisons)


if __name__ == "__main__":
    main()
