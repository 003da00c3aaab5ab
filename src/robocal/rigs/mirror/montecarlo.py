"""Monte Carlo studies on the published scene (used by the tests, the bench and the docs).

* :func:`single_image_study` — the patent's single-image method at a given
  pixel noise: error statistics of ``T_r_c`` (rotation [deg], translation
  [mm]) against the first-order predicted covariance.
* :func:`multi_placement_study` — the joint refinement over K mirror
  placements, its RMS error against the prediction and against
  ``rms(1) / sqrt(K)``.

Errors are ``rotvec(R_est R_true^T)`` (robot-side) and ``t_est - t_true`` of
``T_r_c``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.estimation import MonteCarloResult, monte_carlo
from robocal.rigs.mirror.calibrate import calibrate, calibrate_single, predicted_covariance
from robocal.rigs.mirror.model import MirrorScene
from robocal.rigs.mirror.result import pose_error
from robocal.rigs.mirror.scene import perturbed_placements
from robocal.rigs.mirror.simulate import default_setup, simulate_observations

__all__ = ["pose_error", "single_image_study", "multi_placement_study", "markerless_study", "MarkerlessStudy",
           "StudyRow", "LABELS"]

LABELS = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z"]


def single_image_study(n_trials: int, rng: np.random.Generator, *, sigma_px: float = 0.5,
                       progress: bool = False) -> tuple[MonteCarloResult, np.ndarray]:
    """The patent's method on the published scene: ``(MonteCarloResult, predicted cov (6, 6))``.

    The bound passed to :func:`~robocal.estimation.monte_carlo` is the
    first-order covariance at the truth (:func:`predicted_covariance`), so
    ``ratio_to_bound`` is MC RMS / predicted std.
    """
    cam, scene = default_setup()
    obs0 = simulate_observations(cam, scene, np.random.default_rng(0), sigma_px=sigma_px)
    cov = predicted_covariance(cam, scene.rectangle, scene.body_points_r, scene.T_r_c, scene.T_c_m, obs0, sigma_px)

    def sim(r):
        return simulate_observations(cam, scene, r, sigma_px=sigma_px)[0], scene.T_r_c

    def est(o):
        return calibrate_single(cam, scene.rectangle, scene.body_points_r, o, sigma_px=sigma_px).T_r_c.ravel()

    mc = monte_carlo(sim, est, n_trials, rng, error=pose_error, bound=cov, labels=LABELS, progress=progress)
    return mc, cov


@dataclass
class StudyRow:
    """One K of :func:`multi_placement_study` (rotation in deg, translation in mm, RMS of the error norm)."""

    K: int
    rms_rot_deg: float
    rms_t_mm: float
    pred_rot_deg: float
    pred_t_mm: float
    n_trials: int

    @property
    def ratio_t(self) -> float:
        return self.rms_t_mm / self.pred_t_mm

    @property
    def ratio_rot(self) -> float:
        return self.rms_rot_deg / self.pred_rot_deg


def similar_placements(k: int, rng: np.random.Generator) -> tuple:
    """Camera and the published scene with ``k`` mirror placements of similar information.

    The placements are small moves (3 deg, 5 cm) of the published one, so that
    each image alone is about as informative as the published one and the
    ``1/sqrt(K)`` law can be seen. (Larger moves give more than that: the
    published placement is not the most informative one.)
    """
    cam, scene = default_setup()
    T = [scene.T_c_m[0]]
    while len(T) < k:
        cand = perturbed_placements(scene, 2, rng, tilt_deg=3.0, shift=0.05)[1]
        try:
            s = MirrorScene(scene.T_c_r, cand, scene.body_points_r, scene.rectangle)
        except Exception:  # a placement with the camera or the body behind the mirror: draw again
            continue
        if np.all(cam.in_image(cam.project(s.virtual_points_c()[0], check=False), 5.0)):
            T.append(cand)
    return cam, MirrorScene(scene.T_c_r, np.stack(T), scene.body_points_r, scene.rectangle)


def multi_placement_study(Ks, n_trials: int, rng: np.random.Generator, *, sigma_px: float = 0.5,
                          progress: bool = False) -> list[StudyRow]:
    """Joint refinement over K placements (:func:`similar_placements`) for each K in ``Ks``."""
    rows = []
    for K in Ks:
        cam, scene = similar_placements(K, np.random.default_rng(1000 + K))
        obs0 = simulate_observations(cam, scene, np.random.default_rng(0), sigma_px=sigma_px)
        cov = predicted_covariance(cam, scene.rectangle, scene.body_points_r, scene.T_r_c, scene.T_c_m, obs0,
                                   sigma_px)

        def sim(r, cam=cam, scene=scene):
            return simulate_observations(cam, scene, r, sigma_px=sigma_px), scene.T_r_c

        def est(o, cam=cam, scene=scene):
            return calibrate(cam, scene.rectangle, scene.body_points_r, o, sigma_px=sigma_px).T_r_c.ravel()

        mc = monte_carlo(sim, est, n_trials, rng, error=pose_error, bound=cov, labels=LABELS, progress=progress)
        e = mc.errors
        rows.append(StudyRow(
            K=K,
            rms_rot_deg=float(np.degrees(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, axis=1))))),
            rms_t_mm=float(1e3 * np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, axis=1)))),
            pred_rot_deg=float(np.degrees(np.sqrt(np.trace(cov[:3, :3])))),
            pred_t_mm=float(1e3 * np.sqrt(np.trace(cov[3:, 3:]))),
            n_trials=int(e.shape[0]),
        ))
    return rows


@dataclass
class MarkerlessStudy:
    """Per-trial errors (``rotvec [rad], t [m]``, shape (n, 6)) of the markerless closed form, its refinement
    and the patent path on the same scenes, and the refinement's reported std (n, 6).

    ``failed``: trials whose markerless calibration raised (counted, not hidden); ``patent`` is None when the
    patent path was not run. :attr:`z_rms` is the per-component RMS of ``error / reported std`` (1 when the
    reported uncertainty is right)."""

    closed_form: np.ndarray
    refined: np.ndarray
    std: np.ndarray
    patent: np.ndarray | None
    failed: int
    seconds: float
    #: ``(trial index, one-line error)`` of each failed trial
    failures: list = None

    @property
    def z_rms(self) -> np.ndarray:
        return np.sqrt(np.mean((self.refined / self.std) ** 2, axis=0))


def markerless_study(n_trials: int, rng: np.random.Generator, *, mirrors: int = 4, points: int = 8,
                     sigma_px: float = 0.5, patent: bool = False, progress: bool = False) -> MarkerlessStudy:
    """The markerless method (:mod:`.markerless`) over ``n_trials`` simulated scenes.

    Each trial draws its own scene (the published camera and body, ``mirrors``
    mirror poses tilted by up to 30 deg, :func:`~robocal.rigs.mirror.workflow.markerless_setup`),
    with ``points`` well-spread body points as the reference points, and
    pixel noise ``sigma_px`` (declared to the calibration). ``patent``: also
    run the patent's method + joint refinement on the same mirror poses (the
    rectangle's markers imaged too) and the same points (NaN rows with fewer
    than 4 points: the patent's body-point PnP needs 4).
    """
    import time

    from robocal.errors import RobocalError
    from robocal.progress import progress as _progress
    from robocal.rigs.mirror.markerless import calibrate_markerless, simulate_markerless
    from robocal.rigs.mirror.workflow import markerless_setup

    cf, ref, std, pat = [], [], [], []
    failed = 0
    failures = []
    t0 = time.perf_counter()
    children = rng.spawn(int(n_trials))
    trials = _progress(children, desc="markerless trials", total=len(children)) if progress else children
    for i, r in enumerate(trials):
        cam, scene, P = markerless_setup(mirrors, r, points=points)
        n, d = scene.planes()
        obs = simulate_markerless(cam, scene.T_c_r, P, n, d, r, sigma_px=sigma_px)
        try:
            cal = calibrate_markerless(cam, P, obs, sigma_px=sigma_px)
        except RobocalError as exc:
            failed += 1
            failures.append((i, str(exc)))
            continue
        cf.append(pose_error(cal.T_r_c_closed_form, scene.T_r_c))
        ref.append(pose_error(cal.T_r_c, scene.T_r_c))
        std.append(np.r_[cal.std_rotation, cal.std_translation])
        if patent:
            if len(P) < 4:  # the patent's body-point PnP needs 4 points: no figure, not a failure
                pat.append(np.full(6, np.nan))
                continue
            s = MirrorScene(scene.T_c_r, scene.T_c_m, P, scene.rectangle)
            pc = calibrate(cam, scene.rectangle, P, simulate_observations(cam, s, r, sigma_px=sigma_px),
                           sigma_px=sigma_px)
            pat.append(pose_error(pc.T_r_c, scene.T_r_c))
    return MarkerlessStudy(np.array(cf), np.array(ref), np.array(std), np.array(pat) if patent else None, failed,
                           time.perf_counter() - t0, failures)
