"""Mirror rig, markerless calibration (issue 14): closed form vs refined vs the patent path, same scenes.

Run: python bench/bench_mirror_markerless.py [--trials 200] [--quick]

Each trial draws a scene (the published camera and robot body, K mirror
poses tilted by up to 30 deg, :func:`robocal.rigs.mirror.workflow.markerless_setup`),
N well-spread body points as the reference points, 0.5 px noise, and runs on
the same mirror poses and points:

* the markerless closed form (Takahashi et al., CVPR 2012, on per-pose
  P3P/SQPnP) and its joint refinement (:mod:`robocal.rigs.mirror.markerless`);
* the patent's path with the mirror's four markers imaged too (single-image
  estimates + joint refinement, :func:`robocal.rigs.mirror.calibrate.calibrate`).

Prints per configuration the RMS rotation [deg] and translation [mm] errors
of ``T_r_c`` and, for the refined markerless answer, the per-component RMS of
error / reported std (1 when the reported uncertainty is right). The 3-point
rows use half the trials (a 3-point calibration refines up to 4 P3P starts:
~1-3 s each on 2 shared cores).
"""

from __future__ import annotations

import argparse

import numpy as np

from robocal.rigs.mirror.montecarlo import markerless_study

CONFIGS = ((3, 3), (3, 20), (4, 8), (5, 20))


def _rms(e) -> tuple[float, float]:
    return (float(np.degrees(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, axis=1))))),
            float(1e3 * np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, axis=1)))))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="20 trials per configuration")
    a = ap.parse_args()
    n = 20 if a.quick else a.trials
    print("| poses K | points N | trials (failed) | closed form rot [deg] / t [mm] | refined rot [deg] / t [mm] | "
          "patent + markers rot [deg] / t [mm] | refined RMS(error/std) per component | time [s] |")
    print("|---|---|---|---|---|---|---|---|")
    failures = []
    for k, (K, N) in enumerate(CONFIGS):
        trials = max(10, n // 2) if N == 3 else n
        st = markerless_study(trials, np.random.default_rng(7000 + k), mirrors=K, points=N, sigma_px=0.5,
                              patent=True)
        cf, ref, pat = _rms(st.closed_form), _rms(st.refined), _rms(st.patent)
        pat_text = "n/a (needs >= 4 points)" if N < 4 else f"{pat[0]:.2f} / {pat[1]:.0f}"
        z = " ".join(f"{v:.2f}" for v in st.z_rms)
        print(f"| {K} | {N} | {len(st.refined)} ({st.failed}) | {cf[0]:.2f} / {cf[1]:.0f} | {ref[0]:.2f} / "
              f"{ref[1]:.0f} | {pat_text} | {z} | {st.seconds:.0f} |", flush=True)
        failures.extend(f"K={K}, N={N}, trial {i}: {msg}" for i, msg in st.failures)
    for line in failures:
        print(f"failed: {line}")


if __name__ == "__main__":
    main()
