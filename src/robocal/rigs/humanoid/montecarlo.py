"""Monte Carlo check of the calibration against its own reported uncertainty.

Each trial draws new true offsets, corner noise and hence new joint
quantisation errors (the readings ``quantise(q - alpha)`` of the same
physical poses move on the 0.1 deg grid as the offsets change, so the
quantisation error is random across trials, as it is across robots),
optionally new poses too, calibrates from zero, and compares the error of every
parameter with the standard deviation the calibration reported
(:func:`robocal.estimation.monte_carlo`, :func:`check_coverage`).
"""

from __future__ import annotations

import numpy as np

from robocal.estimation import MonteCarloResult, monte_carlo
from robocal.rigs.humanoid.calibrate import calibrate, resolve_parameters
from robocal.rigs.humanoid.model import HumanoidModel
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, sample_poses, simulate_dataset

__all__ = ["calibration_monte_carlo", "repeatability"]


def calibration_monte_carlo(model: HumanoidModel, n_trials: int, rng: np.random.Generator, *,
                            n_per_foot: int = 6, noise_px: float = 0.3,
                            resolution: float = JOINT_RESOLUTION, parameters="seed",
                            new_poses: bool = False, progress: bool = False, design=None, executor=None,
                            workers: int | None = None, batch_size: int | None = None) -> MonteCarloResult:
    """Errors and reported stds of the selected parameters over ``n_trials`` simulated runs.

    Corner-level simulation (projected corners + Gaussian noise ``noise_px``)
    for speed; the image pipeline is exercised separately. Returns a
    :class:`MonteCarloResult` whose ``coverage`` holds the fraction of trials
    within 3 reported sigma and the Monte Carlo / reported spread ratio.

    ``design``: ``(feet, theta)``, the poses of every trial (e.g. a
    :class:`~robocal.rigs.humanoid.plan.PosePlan`'s); default: drawn from
    ``rng``. ``executor`` / ``workers`` / ``batch_size`` run the trials in
    parallel (:func:`robocal.estimation.monte_carlo`): one seed per trial, so
    the result is the same bits for any number of workers.
    """
    labels = resolve_parameters(model, parameters)
    idx = [model.parameter_labels().index(lab) for lab in labels]
    # one design for all trials (unless new_poses): the reported std is then one number per
    # parameter and the Monte Carlo spread is compared with it directly
    if design is None:
        feet, q = sample_poses(model, n_per_foot, rng, margin=25.0)
    else:
        feet, q = list(design[0]), np.array(design[1], dtype=float)
    head = [model.joint_names.index(j) for j in model.head_joints]

    def simulate(child):
        if new_poses:
            data = simulate_dataset(model, child, n_per_foot=n_per_foot, noise_px=noise_px, resolution=resolution)
        else:
            # Jitter the poses by less than one sensor step: the design stays the same, but the
            # quantisation errors of different views become independent. (With the very same
            # poses in every trial, two views' errors are a fixed function of their angle
            # difference modulo 0.1 deg -- correlated in a way no real run repeats.)
            jitter = child.uniform(-0.5, 0.5, q.shape) * resolution
            jitter[:, head] = 0.0
            data = simulate_dataset(model, child, feet=feet, q=q + jitter, noise_px=noise_px,
                                    resolution=resolution)
        return data, data.truth.params[idx]

    def estimate(data):
        cal = calibrate(model, data, parameters=labels, joint_resolution=resolution, corner_sigma=noise_px)
        est = np.array([np.nan if cal.value(lab) is None else cal.value(lab) for lab in labels])
        std = np.array([np.nan if cal.std(lab) is None else cal.std(lab) for lab in labels])
        return est, std

    return monte_carlo(simulate, estimate, n_trials, rng, labels=labels, progress=progress, executor=executor,
                       workers=workers, batch_size=batch_size)


def repeatability(model: HumanoidModel, n_runs: int, rng: np.random.Generator, *, n_per_foot: int = 3,
                  truth=None, noise_px: float = 0.3, render: bool = False, parameters="seed") -> list[dict]:
    """Several calibration runs of one robot (same offsets, new poses each run), as the seed's
    three consecutive runs: per parameter the mean, the spread over runs and the mean reported
    std [deg or mm].
    """
    from robocal.rigs.humanoid.simulate import draw_truth

    truth = truth if truth is not None else draw_truth(model, rng)
    labels = resolve_parameters(model, parameters)
    units = model.parameter_units()
    est, std = [], []
    for _ in range(n_runs):
        data = simulate_dataset(model, rng, n_per_foot=n_per_foot, truth=truth, noise_px=noise_px, render=render)
        cal = calibrate(model, data, parameters=labels)
        est.append([np.nan if cal.value(lab) is None else cal.value(lab) for lab in labels])
        std.append([np.nan if cal.std(lab) is None else cal.std(lab) for lab in labels])
    est, std = np.array(est), np.array(std)
    rows = []
    for k, lab in enumerate(labels):
        i = model.parameter_labels().index(lab)
        f = np.degrees(1.0) if units[i] == "rad" else 1e3
        rows.append({"parameter": lab, "unit": "deg" if units[i] == "rad" else "mm", "truth": truth.params[i] * f,
                     "mean": float(np.nanmean(est[:, k]) * f), "spread (std over runs)": float(np.nanstd(est[:, k], ddof=1) * f),
                     "mean reported std": float(np.nanmean(std[:, k]) * f)})
    return rows
