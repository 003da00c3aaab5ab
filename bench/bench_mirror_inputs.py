"""Mirror rig: what a user's inputs can and cannot reveal, and the ArUco path on degraded images.

Run: python bench/bench_mirror_inputs.py [--trials 200] [--quick]

Prints (1) the handedness test (a body model whose x sign is wrong, i.e. given
in the mirrored frame ri) on the published scene: how often it is flagged with
and without sigma_px, and false alarms on the correct model; (2) the ArUco
path on rendered images of the published scene with and without distortion,
at increasing blur and grey-level noise: tags found, corner error against the
true reflections, marker-centre error, and the calibration error against its
reported std.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from robocal.errors import RobocalError
from robocal.rigs.mirror.calibrate import calibrate, calibrate_single
from robocal.rigs.mirror.model import MirrorScene, mirror_plane, ri_from_r_points
from robocal.rigs.mirror.render import default_body_tags, detect_mirror_image, render_mirror_image
from robocal.rigs.mirror.simulate import default_setup, simulate_observations


def _flagged(res) -> bool:
    return any("mirror image of body_points" in w.message or "handedness" in w.message for w in res.warnings)


def handedness_study(trials: int) -> None:
    rng = np.random.default_rng(5)
    cam, scene = default_setup(1, rng)
    P, Pf = scene.body_points_r, ri_from_r_points(scene.body_points_r)
    print(f"handedness (body model with x not flipped), published scene, {trials} trials per row")
    print("  sigma [px]  flagged w/o sigma_px  flagged with sigma_px  false alarms (correct model)")
    for sig in (0.5, 1.0, 2.0):
        fa = det = det_s = 0
        for _ in range(trials):
            o = simulate_observations(cam, scene, rng, sigma_px=sig)[0]
            fa += _flagged(calibrate_single(cam, scene.rectangle, P, o))
            for sigma, acc in ((None, "det"), (sig, "det_s")):
                try:
                    hit = _flagged(calibrate_single(cam, scene.rectangle, Pf, o, sigma_px=sigma))
                except RobocalError:
                    hit = True  # refused outright
                if acc == "det":
                    det += hit
                else:
                    det_s += hit
        print(f"  {sig:10.1f}  {det:14d} / {trials}  {det_s:15d} / {trials}  {fa:12d} / {trials}")


def aruco_study(trials: int) -> None:
    cam0, s0 = default_setup(1, np.random.default_rng(0))
    tags = default_body_tags()
    print(f"ArUco path, one rendered image of the published scene, {trials} noise draws per row")
    print("  distortion  blur  noise  tags found  corner rms [px] (max)  marker rms [px]  "
          "|t err| median [mm]  |err|/|std| median  failed")
    for distort in (True, False):
        cam = cam0 if distort else dataclasses.replace(cam0, dist=np.zeros(5))
        sc = MirrorScene(s0.T_c_r, s0.T_c_m, tags.body_points_r(), s0.rectangle)
        n, d = mirror_plane(sc.T_c_m[0])
        for blur, noise in ((0.0, 0.0), (0.6, 2.0), (0.9, 3.0), (1.2, 5.0), (2.0, 10.0)):
            errs, merrs, found, t_err, z, failed = [], [], [], [], [], 0
            for t in range(trials):
                img = render_mirror_image(cam, sc, tags, rng=np.random.default_rng(t), blur_sigma=blur,
                                          noise_sigma=noise)
                try:
                    o = detect_mirror_image(img, cam, tags)
                    c = calibrate(cam, sc.rectangle, sc.body_points_r, [o])
                except RobocalError:
                    failed += 1
                    continue
                pc = sc.body_points_r[o.body_ids] @ sc.T_c_r[:3, :3].T + sc.T_c_r[:3, 3]
                errs.append(o.body_uv - cam.project(pc - 2 * (pc @ n - d)[:, None] * n))
                merrs.append(o.marker_uv - cam.project_points(sc.rectangle.object_points(), sc.T_c_m[0]))
                found.append(len(o.body_ids) // 4)
                e = c.T_r_c[:3, 3] - sc.T_r_c[:3, 3]
                t_err.append(np.linalg.norm(e) * 1e3)
                z.append(np.linalg.norm(e) / np.linalg.norm(c.std_translation))
            if not errs:
                print(f"  {distort!s:10}  {blur:4.1f}  {noise:5.1f}  {'-':>10}  {'-':>21}  {'-':>15}  {'-':>19}  "
                      f"{'-':>18}  {failed} / {trials}")
                continue
            e, m = np.concatenate(errs), np.concatenate(merrs)
            print(f"  {distort!s:10}  {blur:4.1f}  {noise:5.1f}  {np.mean(found):6.1f} / 6  "
                  f"{np.sqrt(np.mean(e**2)):13.2f} ({np.abs(e).max():.2f})  {np.sqrt(np.mean(m**2)):15.2f}  "
                  f"{np.median(t_err):19.0f}  {np.median(z):18.2f}  {failed} / {trials}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    handedness_study(40 if a.quick else a.trials)
    aruco_study(4 if a.quick else max(10, a.trials // 20))


if __name__ == "__main__":
    main()
