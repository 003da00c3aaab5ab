"""Pose planning: leg poses that make the calibration well conditioned (docs/rigs/humanoid.md, "Beyond the seed").

Greedy D-optimal design: from a pool of candidate poses (within the joint
limits, board fully visible with its face toward the camera, feet apart --
:func:`~robocal.rigs.humanoid.simulate.sample_poses`), add one pose at a time,
the one that most increases ``log det`` of the Fisher information of the
selected parameters,

.. math:: I = \\sum_v J_v^T \\Sigma_v^{-1} J_v,

with ``Sigma_v`` the per-view noise model of :func:`calibrate.noise_weights`
(corner noise plus joint quantisation). The predicted standard deviations
``sqrt(diag I^-1)`` after each addition show how the uncertainty shrinks; a
parameter is reported as undetermined (NaN) while ``I`` is singular in its
direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError
from robocal.estimation import analyze_jacobian
from robocal.rigs.humanoid.calibrate import noise_weights, resolve_parameters
from robocal.rigs.humanoid.model import HumanoidModel
from robocal.rigs.humanoid.simulate import DEFAULT_HEAD, JOINT_RESOLUTION, HumanoidDataset, sample_poses

__all__ = ["PosePlan", "view_information", "predicted_std", "plan_poses"]


@dataclass
class PosePlan:
    """Outcome of :func:`plan_poses`.

    Attributes
    ----------
    feet : list of str
        Foot of each chosen pose, in the order chosen.
    theta : ndarray, shape (K, n_joints)
        Joint angles to command [rad] (model ``joint_names`` order).
    labels : list of str
        Parameters the plan is for.
    std_history : ndarray, shape (K, P)
        Predicted std of each parameter after 1..K poses (NaN while undetermined).
    random_std : ndarray, shape (K, P) or None
        The same for poses taken in random order from the pool (a baseline).
    condition : ndarray, shape (K,)
        Condition number of the column-scaled Jacobian after each pose.
    """

    feet: list
    theta: np.ndarray
    labels: list
    units: list
    std_history: np.ndarray
    random_std: np.ndarray | None
    condition: np.ndarray

    def table(self) -> list[dict]:
        """Rows: poses so far, foot added, worst joint-offset std [deg], camera rotation std [deg]."""
        rows = []
        joint = [i for i, (lab, u) in enumerate(zip(self.labels, self.units)) if u == "rad"
                 and not lab.startswith(("camera.", "board."))]
        cam = [i for i, lab in enumerate(self.labels) if lab in ("camera.roll", "camera.pitch", "camera.yaw")]
        for k in range(len(self.feet)):
            s = self.std_history[k]
            row = {"poses": k + 1, "foot added": self.feet[k],
                   "worst joint std [deg]": _worst(s[joint]), "worst camera std [deg]": _worst(s[cam]),
                   # a rank-deficient step has no meaningful condition number (it printed 8.8e15)
                   "condition number": float(self.condition[k]) if np.all(np.isfinite(s)) else None}
            if self.random_std is not None:
                row["random order: worst joint std [deg]"] = _worst(self.random_std[k][joint])
            rows.append(row)
        return rows

    def plot(self, ax=None):
        """Predicted worst joint-offset std vs number of poses (planned and random); returns the axes."""
        if ax is None:
            from robocal.report import new_figure

            _, ax = new_figure()
        joint = [i for i, lab in enumerate(self.labels) if not lab.startswith(("camera.", "board."))]
        k = np.arange(1, len(self.feet) + 1)
        for i in joint:
            ax.semilogy(k, np.degrees(self.std_history[:, i]), color="0.75", lw=0.8)
        ax.semilogy(k, [np.degrees(_worst_rad(s[joint])) for s in self.std_history], "C0-o", ms=3,
                    label="planned (D-optimal), worst joint")
        if self.random_std is not None:
            ax.semilogy(k, [np.degrees(_worst_rad(s[joint])) for s in self.random_std], "C3--", label="random order, worst joint")
        ax.set_xlabel("poses")
        ax.set_ylabel("predicted std [deg]")
        ax.set_title("joint-offset uncertainty as poses are added (grey: each joint)")
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
        return ax

    def monte_carlo(self, model: HumanoidModel, n_trials: int, rng: np.random.Generator, *,
                    noise_px: float = 0.3, resolution: float = JOINT_RESOLUTION, executor=None,
                    workers: int | None = None, batch_size: int | None = None, progress: bool = False):
        """Check the plan by simulation: ``n_trials`` calibrations from these poses (new offsets and noise each).

        The Monte Carlo spread of each parameter against the plan's predicted
        std (``std_history[-1]``) tells whether the linearised Fisher
        information holds for this design. Trials run on ``executor`` (a Dask
        ``Client``) or ``workers`` local processes, bit-identical to a serial
        run (:func:`~robocal.rigs.humanoid.montecarlo.calibration_monte_carlo`).
        """
        from robocal.rigs.humanoid.montecarlo import calibration_monte_carlo

        return calibration_monte_carlo(model, n_trials, rng, noise_px=noise_px, resolution=resolution,
                                       parameters=list(self.labels), design=(self.feet, self.theta),
                                       executor=executor, workers=workers, batch_size=batch_size,
                                       progress=progress)

    def dataset(self) -> HumanoidDataset:
        """The plan as a data set without corners (to simulate or to save as commands)."""
        return HumanoidDataset(list(self.feet), self.theta, names=[f"pose{k:03d}" for k in range(len(self.feet))])


def _worst_rad(s):
    s = np.asarray(s, dtype=float)
    return np.inf if np.any(~np.isfinite(s)) else float(np.max(s))


def _worst(s):
    w = _worst_rad(s)
    return None if not np.isfinite(w) else float(np.degrees(w))


def view_information(model: HumanoidModel, feet, theta, labels, *, corner_sigma: float = 0.3,
                     joint_resolution: float = JOINT_RESOLUTION) -> np.ndarray:
    """Per-view whitened Jacobians ``W_v J_v`` (V, 2N, P) w.r.t. ``labels`` at zero offsets."""
    x = np.zeros(len(model.parameter_labels()))
    theta = np.atleast_2d(theta)
    V = len(theta)
    data = HumanoidDataset(list(feet), theta, corners=np.zeros((V, len(model.object_points), 2)))
    # every leg joint counts as moving in a plan (the head stays still)
    W, _ = noise_weights(model, _moving_view(model, data), x, corner_sigma=corner_sigma,
                         joint_sigma=joint_resolution / np.sqrt(12.0))
    W = W[:V]
    _, J = model.project(theta, list(feet), x, jacobian=True, check=False)
    idx = [model.parameter_labels().index(lab) for lab in labels]
    return W @ J[..., idx].reshape(V, -1, len(idx))


def _moving_view(model, data):
    """``data`` plus one extra row so that every leg joint reads as moving (head fixed)."""
    extra = data.theta[:1].copy()
    legs = [model.joint_names.index(j) for j in model.leg_joints]
    extra[:, legs] += 1e-3
    return HumanoidDataset(list(data.feet) + [data.feet[0]], np.vstack([data.theta, extra]),
                           corners=np.zeros((data.n_views + 1,) + data.corners.shape[1:]))


def predicted_std(info: np.ndarray) -> tuple[np.ndarray, float]:
    """Std of each parameter (NaN where undetermined) and condition number from a stacked whitened Jacobian."""
    ana = analyze_jacobian(info)
    return ana.std, ana.condition_number


def plan_poses(model: HumanoidModel, n_poses: int, rng: np.random.Generator, *, parameters="seed",
               n_candidates: int = 60, corner_sigma: float = 0.3, joint_resolution: float = JOINT_RESOLUTION,
               head=DEFAULT_HEAD, random_baseline: bool = True, progress: bool = False) -> PosePlan:
    """Greedy D-optimal choice of ``n_poses`` poses from ``n_candidates`` per foot.

    Parameters
    ----------
    model : HumanoidModel
    n_poses : int
        Poses to choose (both feet together).
    rng : numpy.random.Generator
        Draws the candidate pool (and the random-order baseline).
    parameters : str or list
        Parameters to plan for (:func:`resolve_parameters`).
    n_candidates : int
        Candidate poses per foot.
    progress : bool
        A progress bar over the chosen poses on a terminal (20 poses from 200 candidates: ~3 s).
    """
    if n_poses < 1:
        raise InputError(f"n_poses must be >= 1, got {n_poses}")
    labels = resolve_parameters(model, parameters)
    units = [model.parameter_units()[model.parameter_labels().index(lab)] for lab in labels]
    feet, theta = sample_poses(model, n_candidates, rng, head=head, margin=25.0)
    if n_poses > len(feet):
        raise InputError(f"n_poses = {n_poses} exceeds the candidate pool ({len(feet)})")
    Jv = view_information(model, feet, theta, labels, corner_sigma=corner_sigma, joint_resolution=joint_resolution)
    Iv = np.einsum("vmi,vmj->vij", Jv, Jv)
    # a weak prior (1e-6 of each parameter's average information) lets log det rank the first poses
    prior = 1e-6 * np.diag(np.mean(np.diagonal(Iv, axis1=1, axis2=2), axis=0))
    info = prior.copy()
    chosen: list[int] = []
    stds, conds = [], []
    from robocal.progress import progress as _progress

    for _ in _progress(range(n_poses), desc="choosing poses", total=n_poses, enabled=progress):
        best, best_val = -1, -np.inf
        for c in range(len(feet)):
            if c in chosen:
                continue
            val = np.linalg.slogdet(info + Iv[c])[1]
            if val > best_val:
                best, best_val = c, val
        chosen.append(best)
        info += Iv[best]
        s, cond = predicted_std(Jv[chosen].reshape(-1, len(labels)))
        stds.append(s)
        conds.append(cond)
    rnd = None
    if random_baseline:
        order = rng.permutation(len(feet))[:n_poses]
        rnd = np.array([predicted_std(Jv[order[:k + 1]].reshape(-1, len(labels)))[0] for k in range(n_poses)])
    return PosePlan([feet[i] for i in chosen], theta[chosen], labels, units, np.array(stds), rnd,
                    np.array(conds))
