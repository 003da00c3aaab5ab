"""Mirror rig, ArUco path: where the tag-corner error comes from, and the calibration error / reported std.

Run: python bench/bench_mirror_corners.py [--trials 60] [--quick]

(1) Corner error per cause on noise-free renders of the published scene (no
blur, no noise; with and without lens distortion): mean vector, RMS and the
mean *radial* component (along the tag's diagonal, + = outward) against the
true corners (mirror tags seen directly; body tags seen in the mirror, found
in the flipped image). Rows isolate:

* the OpenCV ArUco detector alone on a pixel-exact axis-aligned tag (its
  corner convention, per refinement method);
* the image flip (``u = W - 1 - u'`` vs ``W - u'``);
* the detector's corner refinement (NONE / SUBPIX / CONTOUR) vs the rig's
  edge fit (:func:`refine_tag_corners`);
* the renderer: point-sampled ``PlaneTexture("nearest")`` at 4 x 4 samples
  vs the box-filtered texture at 2 x 2.

(2) Monte Carlo of the ArUco path (random mirror placement around the
published one, blur 0.6 px, grey noise 2, sigma estimated from the
residuals as the CLI does): RMS over trials of error / reported std per
component of T_r_c, for the pipeline before the corner fix, with the corner
fix only (markers weighted like body corners, independent corners), with
the markers (tag centres) weighted by the scalar ``TAG_CENTRE_SIGMA_SCALE``
(0.265; the previous "after the fix"), and now: each tag's corners and
centre with their covariance from the edge-fit geometry
(:func:`~robocal.rigs.mirror.render.tag_corner_covariance`, whitened in the
joint fit) and the std from a two-component noise model (edge-fit part +
independent corner part, both variances from the residuals).

(3) Why: ``--draws`` noise draws (grey noise 2) of one blurred render of
the published scene. Per body tag: the empirical covariance of its 8 corner
coordinates against the line-fit model (relative Frobenius difference after
the best scale, and how much of the matrix is off-diagonal: 0 for the
independent-corner model); the mirror markers' (tag centres') std against
the model's and against the body corners' (the former scalar weight
assumed 0.265); and the noise-free (systematic) errors of body corners and
markers, which the residual-based sigma also sees.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from contextlib import contextmanager

import cv2
import numpy as np

from robocal.camera import PlaneTexture, render_planar_target
from robocal.errors import RobocalError
from robocal.rigs.mirror import render as R
from robocal.rigs.mirror.calibrate import calibrate
from robocal.rigs.mirror.model import MirrorScene, mirror_plane, virtual_transform
from robocal.rigs.mirror.montecarlo import LABELS, pose_error
from robocal.rigs.mirror.scene import perturbed_placements
from robocal.rigs.mirror.simulate import default_setup


def scene_with_tags(T_c_m=None):
    cam, s0 = default_setup()
    tags = R.default_body_tags()
    T = s0.T_c_m if T_c_m is None else T_c_m[None]
    return cam, MirrorScene(s0.T_c_r, T, tags.body_points_r(), s0.rectangle), tags


def true_corners(cam, sc, tags):
    """``{tag id: (4, 2)}`` true corners of the mirror tags and of the reflected body tags [px]."""
    n, d = mirror_plane(sc.T_c_m[0])
    pc = sc.body_points_r @ sc.T_c_r[:3, :3].T + sc.T_c_r[:3, 3]
    body = cam.project(pc - 2 * (pc @ n - d)[:, None] * n).reshape(-1, 4, 2)
    w, h, s = sc.rectangle.width, sc.rectangle.height, R.MIRROR_TAG_SIZE / 2
    out = {}
    for tid, (x, y) in zip(R.MIRROR_TAG_IDS, [(0, 0), (w, 0), (w, h), (0, h)]):
        P = np.array([[x - s, y - s, 0], [x + s, y - s, 0], [x + s, y + s, 0], [x - s, y + s, 0]])
        out[("mirror", tid)] = cam.project_points(P, sc.T_c_m[0])
    for k, tid in enumerate(tags.ids):
        out[("body", tid)] = body[k]
    return out


def render_plane_texture(cam, T, bitmap, size, *, origin, image):
    """The renderer before the core fix: the texel under each sample point (``interpolation="point"``)."""
    return render_planar_target(cam, T, PlaneTexture(bitmap, size, origin=origin, interpolation="point"), image=image)


def render_legacy(cam, sc, tags, *, blur_sigma=0.0, noise_sigma=0.0, rng=None):
    """The renderer before the fix: point-sampled nearest texels, 4 x 4 samples per pixel."""
    n, d = mirror_plane(sc.T_c_m[0])
    img = R.blank_image(cam, background=150.0)
    for tag_id, T_r_tag in zip(tags.ids, tags.T_r_tag):
        T_c_vtag = virtual_transform(sc.T_c_r @ T_r_tag, n, d)
        full = tags.size * 8 / 6
        img = render_plane_texture(cam, T_c_vtag, np.fliplr(R._tag_bitmap(tag_id)), full,
                                   origin=(-full / 2, -full / 2), image=img)
    w, h = sc.rectangle.width, sc.rectangle.height
    full = R.MIRROR_TAG_SIZE * 8 / 6
    for tag_id, (x, y) in zip(R.MIRROR_TAG_IDS, [(0, 0), (w, 0), (w, h), (0, h)]):
        img = render_plane_texture(cam, sc.T_c_m[0], R._tag_bitmap(tag_id), full,
                                   origin=(x - full / 2, y - full / 2), image=img)
    return R.add_blur_and_noise(img, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)


def aruco(gray, method):
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = method
    p.cornerRefinementWinSize = 3
    corners, ids, _ = cv2.aruco.ArucoDetector(R.aruco_dictionary(), p).detectMarkers(gray)
    out = {}
    for i, c in zip([] if ids is None else ids.ravel(), corners):
        out.setdefault(int(i), []).append(c.reshape(4, 2).astype(float))
    return out


def corner_errors(cam, img, truth, method, *, edge_fit, flip_offset=1):
    W = img.shape[1]
    direct = aruco(img, method)
    flipped = aruco(np.ascontiguousarray(img[:, ::-1]), method)
    err, rad = [], []
    for (kind, tid), t in truth.items():
        found = (direct if kind == "mirror" else flipped).get(tid, [])
        if len(found) != 1:
            continue
        c = found[0].copy()
        if kind == "body":
            c[:, 0] = (W - flip_offset) - c[:, 0]
        if edge_fit:
            c = R.refine_tag_corners(img, c, cam)
        e = c - t
        u = (t - t.mean(0)) / np.linalg.norm(t - t.mean(0), axis=1, keepdims=True)
        err.append(e)
        rad.append(np.sum(e * u, axis=1))
    return np.concatenate(err), np.concatenate(rad)


def fmt(e, rad):
    return (f"mean ({e[:, 0].mean():+.3f}, {e[:, 1].mean():+.3f})  rms {np.sqrt(np.mean(np.sum(e**2, 1))):.3f}  "
            f"radial {rad.mean():+.3f}  max {np.linalg.norm(e, axis=1).max():.3f}  n {len(e)}")


def detector_alone():
    print("(1a) OpenCV ArUco detector alone, pixel-exact axis-aligned tag (black square on pixels [a, a+S)): "
          "corner - (a - 0.5), per axis, top-left corner")
    d = R.aruco_dictionary()
    for S in (24, 60):
        row = []
        for name, m in (("NONE", cv2.aruco.CORNER_REFINE_NONE), ("SUBPIX", cv2.aruco.CORNER_REFINE_SUBPIX),
                        ("CONTOUR", cv2.aruco.CORNER_REFINE_CONTOUR), ("edge fit", None)):
            img = np.full((200, 200), 235, np.uint8)
            img[40:40 + S, 40:40 + S] = np.where(cv2.aruco.generateImageMarker(d, 3, S) > 0, 235, 20)
            c = aruco(img, m if m is not None else cv2.aruco.CORNER_REFINE_NONE)[3][0]
            if m is None:
                c = R.refine_tag_corners(img, c)
            row.append(f"{name} {c[0, 0] - 39.5:+.3f}")
        print(f"  S = {S:3d} px: " + ", ".join(row))


def per_cause():
    print("(1b) noise-free renders of the published scene (mirror + body tags; radial + = outward)")
    cam0, sc, tags = scene_with_tags()
    for distort in (True, False):
        cam = cam0 if distort else dataclasses.replace(cam0, dist=np.zeros(5))
        truth = true_corners(cam, sc, tags)
        t0 = time.perf_counter()
        legacy = render_legacy(cam, sc, tags)
        t1 = time.perf_counter()
        new = R.render_mirror_image(cam, sc, tags, blur_sigma=0.0, noise_sigma=0.0)
        t2 = time.perf_counter()
        print(f"  distortion {distort}  (render: legacy {t1 - t0:.2f} s, box-filtered 2x2 {t2 - t1:.2f} s)")
        rows = [
            ("legacy render, SUBPIX (before the fix)", legacy, cv2.aruco.CORNER_REFINE_SUBPIX, False, 1),
            ("legacy render, NONE", legacy, cv2.aruco.CORNER_REFINE_NONE, False, 1),
            ("legacy render, CONTOUR", legacy, cv2.aruco.CORNER_REFINE_CONTOUR, False, 1),
            ("legacy render, SUBPIX, flip W - u", legacy, cv2.aruco.CORNER_REFINE_SUBPIX, False, 0),
            ("legacy render, edge fit", legacy, cv2.aruco.CORNER_REFINE_NONE, True, 1),
            ("box-filtered render, SUBPIX", new, cv2.aruco.CORNER_REFINE_SUBPIX, False, 1),
            ("box-filtered render, edge fit (after the fix)", new, cv2.aruco.CORNER_REFINE_NONE, True, 1),
        ]
        for label, img, m, fit, off in rows:
            print(f"    {label:47s} {fmt(*corner_errors(cam, img, truth, m, edge_fit=fit, flip_offset=off))}")


@contextmanager
def legacy_pipeline():
    """Detection and rendering as before the fix (SUBPIX, no edge fit, point-sampled 4x4 render)."""
    old_detect, old_refine = R._detect, R.refine_tag_corners
    R._detect = lambda gray, dictionary=R.ARUCO_DICT: aruco(gray, cv2.aruco.CORNER_REFINE_SUBPIX)
    R.refine_tag_corners = lambda image, corners, camera=None, cells=6: np.asarray(corners, float)
    old_scale, R.TAG_CENTRE_SIGMA_SCALE = R.TAG_CENTRE_SIGMA_SCALE, 1.0
    try:
        yield
    finally:
        R._detect, R.refine_tag_corners, R.TAG_CENTRE_SIGMA_SCALE = old_detect, old_refine, old_scale


@contextmanager
def scalar_weights(scale):
    """The fixed corners, independent corners, markers weighted by ``scale`` (no per-tag covariance)."""
    old = R.detect_mirror_image

    def detect(*a, **k):
        return dataclasses.replace(old(*a, **k), body_cov=None, marker_cov=None, marker_sigma_scale=scale)

    R.detect_mirror_image = detect
    try:
        yield
    finally:
        R.detect_mirror_image = old


def monte_carlo(trials, legacy: bool, seed=7):
    rng = np.random.default_rng(seed)
    cam, s0, tags = scene_with_tags()
    z, t_err, std_t, failed = [], [], [], 0
    for _ in range(trials):
        T = perturbed_placements(s0, 2, rng, tilt_deg=3.0, shift=0.05)[1]
        try:
            cam_, sc, _ = scene_with_tags(T)
        except RobocalError:
            failed += 1
            continue
        r = np.random.default_rng(rng.integers(1 << 31))
        try:
            if legacy:
                img = render_legacy(cam, sc, tags, blur_sigma=0.6, noise_sigma=2.0, rng=r)
                with legacy_pipeline():
                    o = R.detect_mirror_image(img, cam, tags)
                # independent corners, markers weighted like them (as before the fix)
                o = dataclasses.replace(o, body_cov=None, marker_cov=None, marker_sigma_scale=1.0)
            else:
                img = R.render_mirror_image(cam, sc, tags, blur_sigma=0.6, noise_sigma=2.0, rng=r)
                o = R.detect_mirror_image(img, cam, tags)
            c = calibrate(cam, sc.rectangle, sc.body_points_r, [o])
        except RobocalError:
            failed += 1
            continue
        e = pose_error(c.T_r_c, sc.T_r_c)
        z.append(e / np.sqrt(np.diag(c.cov)))
        t_err.append(np.linalg.norm(e[3:]) * 1e3)
        std_t.append(np.linalg.norm(c.std_translation) * 1e3)
    z = np.array(z)
    return z, np.array(t_err), np.array(std_t), failed


def mc_report(trials):
    print(f"(2) Monte Carlo, ArUco path, {trials} random placements (3 deg, 5 cm around the published one), "
          "blur 0.6 px, grey noise 2, sigma from the residuals")
    print("    pipeline          " + "  ".join(f"{lab:>6s}" for lab in LABELS)
          + "   <- RMS(error / reported std); median |t err|, |std_t| [mm]; mean(error / std)")
    for label, legacy, scale in (("before the fix", True, None), ("corners only", False, 1.0),
                                 ("scalar 0.265", False, R.TAG_CENTRE_SIGMA_SCALE), ("tag covariance", False, None)):
        t0 = time.perf_counter()
        if scale is not None:
            with scalar_weights(scale):
                z, te, st, failed = monte_carlo(trials, False)
        else:
            z, te, st, failed = monte_carlo(trials, legacy)
        rms = np.sqrt(np.mean(z**2, axis=0))
        print(f"    {label:16s}  " + "  ".join(f"{v:6.2f}" for v in rms)
              + f"   {np.median(te):6.1f}  {np.median(st):6.1f}  "
              + " ".join(f"{v:+.2f}" for v in z.mean(0)) + f"  ({failed} failed, {time.perf_counter() - t0:.0f} s)")


def covariance_report(draws, seed=1):
    from robocal.camera import add_blur_and_noise

    print(f"(3) per-tag corner covariance over {draws} noise draws (published scene, blur 0.6, grey noise 2)")
    cam, sc, tags = scene_with_tags()
    img0 = R.render_mirror_image(cam, sc, tags, blur_sigma=0.0, noise_sigma=0.0)
    clean = R.detect_mirror_image(add_blur_and_noise(img0, blur_sigma=0.6), cam, tags)
    rng = np.random.default_rng(seed)
    B, M = [], []
    for _ in range(draws):
        o = R.detect_mirror_image(add_blur_and_noise(img0, blur_sigma=0.6, noise_sigma=2.0, rng=rng), cam, tags)
        if not np.array_equal(o.body_ids, clean.body_ids):
            continue
        B.append(o.body_uv - clean.body_uv)
        M.append(o.marker_uv - clean.marker_uv)
    B, M = np.array(B), np.array(M)
    n = len(B)
    corner_var = []
    for k in range(B.shape[1] // 4):
        C = np.cov(B[:, 4 * k:4 * k + 4].reshape(n, 8).T)
        Cm = R.tag_corner_covariance(clean.body_uv[4 * k:4 * k + 4])
        s = np.trace(C) / np.trace(Cm)
        off = np.linalg.norm(C - np.diag(np.diag(C))) / np.linalg.norm(C)
        r = np.sqrt(np.diag(C))
        corner_var.append(np.mean(np.diag(C)))
        print(f"    body tag {tags.ids[clean.body_ids[4 * k] // 4]}: corner std {np.sqrt(np.mean(np.diag(C))):.4f} px, "
              f"|C - s C_model| / |C| {np.linalg.norm(C - s * Cm) / np.linalg.norm(C):.2f} (iid model: {off:.2f}), "
              f"corr(ends of a side) {C[0, 6] / (r[0] * r[6]):+.2f} (model {Cm[0, 6] / np.sqrt(Cm[0, 0] * Cm[6, 6]):+.2f}), "
              f"edge-point sigma_e {np.sqrt(s):.4f} px")
    s_e = np.sqrt(np.mean(np.diag(np.cov(B.reshape(n, -1).T))) / np.mean([np.trace(R.tag_corner_covariance(
        clean.body_uv[4 * k:4 * k + 4])) / 8 for k in range(B.shape[1] // 4)]))
    print(f"    markers (tag centres): std {np.sqrt(M.var(axis=0).mean()):.4f} px, model (relative marker_cov x "
          f"corner variance) {np.sqrt(np.mean(clean.marker_cov[:, [0, 1], [0, 1]]) * np.mean(corner_var)):.4f} px; "
          f"centre / corner std {np.sqrt(M.var(axis=0).mean() / np.mean(corner_var)):.2f} (model "
          f"{np.sqrt(np.mean(clean.marker_cov[:, [0, 1], [0, 1]])):.2f}, former scalar {R.TAG_CENTRE_SIGMA_SCALE:.3f})"
          f"; sigma_e pooled {s_e:.4f} px")
    truth = true_corners(cam, sc, tags)
    e = np.concatenate([clean.body_uv[4 * k:4 * k + 4] - truth[("body", tags.ids[clean.body_ids[4 * k] // 4])]
                        for k in range(len(clean.body_ids) // 4)])
    m = clean.marker_uv - cam.project_points(sc.rectangle.object_points(), sc.T_c_m[0])
    print(f"    noise-free (systematic) error: body corners {np.sqrt(np.mean(e**2)):.4f} px, markers "
          f"{np.sqrt(np.mean(m**2)):.4f} px RMS per coordinate")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=60)
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    detector_alone()
    per_cause()
    mc_report(8 if a.quick else a.trials)
    covariance_report(20 if a.quick else a.draws)


if __name__ == "__main__":
    main()
