"""Plausibility of a humanoid data set before the solve: the slips a careful user makes, named.

A wrong unit, a transposed board, mirrored images or swapped legs still give
corners and joint records that read without error; the seed's LM then either
"converges" to offsets of 100-190 deg or wanders until a board falls behind
the camera (a NaN residual). Before the solve, three cheap checks compare the
detected corners with what the robot model predicts from the joint records at
zero offsets (seed 001 eq. 5; one projection of every corner, a few ms for
hundreds of views):

1. **handedness**: the board's printed face looks at the camera, so its grid
   appears with a fixed orientation (the signed area of the grid's x and y
   edges in the image is positive for ``fx, fy > 0``). A transposed board
   (``rows``/``cols`` swapped) shows it mirrored in every view. (Left-right
   mirrored images do not: the detector picks whichever labelling of the grid,
   mirrored ones included, lies closest to the predicted corners; check 3
   finds them.)
2. **apparent size**: the board's spread in the image against the predicted
   one, which follows from ``board.square``, the camera-to-foot distance of
   the kinematic model and ``fx, fy``. A square in m declared mm is 1000x off.
3. **corner distance**: the median distance between detected and predicted
   corners. Offsets of ~0.5 deg put corners ~2-30 px off, 2 deg up to 110 px;
   angles in rad declared deg, a board centre in the wrong unit, swapped
   legs, a reversed image list, mirrored images, or joint columns out of
   order (left and right legs, or any two joints) put them 200-500 px off or
   behind the camera.

When a check fails, each likely slip is undone and the same figure
recomputed (:func:`robocal.plausibility.check_slips`); the one that explains
the data is named in one line. Undoing a slip that changes which corner is
which (transposed board, mirrored image, another record) re-labels each
view's grid by whichever of its four symmetric orderings lies closest to the
prediction, as the detector does with its expected corners.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from robocal.camera import Checkerboard
from robocal.diagnostics import Diagnostic
from robocal.errors import InputError
from robocal.plausibility import LENGTH_UNITS, Slip, check_slips, length_slips, try_slips
from robocal.rigs.humanoid.model import _BOARD_ROTATION, FEET, HumanoidModel

__all__ = ["DECLARED_SI", "LENGTH_UNITS", "check_data", "distance_slips", "corner_distance", "size_ratio", "handedness",
           "with_board", "SIZE_LIMIT", "DISTANCE_FACTOR", "length_slips", "joint_unit_slip"]

#: Units a data set's fields were read in (the loader's ``info["declared"]``); the library's default is SI.
DECLARED_SI = {"board.square": "m", "board.centre": "m", "joints": "rad"}
#: The board's apparent size may differ from the prediction by this factor before it is a slip:
#: offsets of a few degrees change the camera-to-board distance by a few %, not 50 %.
SIZE_LIMIT = 1.5
#: The corner distance is implausible beyond this multiple of ``consistency_px`` (60 px by default:
#: 0.5 deg offsets put corners up to 28 px off, 2 deg up to 110 px; slips 200-500 px).
DISTANCE_FACTOR = 3.0


def with_board(model: HumanoidModel, *, board: Checkerboard | None = None, centre=None) -> HumanoidModel:
    """The model with another board grid and/or nominal board centre [m] (mounts rebuilt as
    :meth:`HumanoidModel.from_urdf` does)."""
    board = model.board if board is None else board
    grid = np.asarray(board.object_points(), dtype=float)
    grid_centre = 0.5 * (grid.min(axis=0) + grid.max(axis=0))
    mounts = {}
    for foot, m in model.mounts.items():
        c = m.centre if centre is None else np.asarray(centre, dtype=float)
        T = np.eye(4)
        T[:3, :3] = _BOARD_ROTATION
        T[:3, 3] = c - _BOARD_ROTATION @ grid_centre
        mounts[foot] = replace(m, T_sole_board0=T, centre=c.copy())
    return HumanoidModel(model.tree, model.camera, board, mounts, model.camera_link, model.optical_link,
                         model.head_joints, model.source)


def _predict(model: HumanoidModel, theta, feet) -> np.ndarray:
    """Corners (V, N, 2) [px] predicted at zero offsets; NaN for a board behind the camera."""
    return model.project(theta, feet, np.zeros(len(model.parameter_labels())), check=False)


def _orderings(corners, rows: int, cols: int) -> list[np.ndarray]:
    """The four labellings (V, N, 2) of each view's grid that keep its rows x cols shape."""
    g = np.asarray(corners).reshape(len(corners), rows, cols, 2)
    return [o.reshape(len(corners), rows * cols, 2)
            for o in (g, g[:, ::-1], g[:, :, ::-1], g[:, ::-1, ::-1])]


def _view_distance(pred, corners) -> np.ndarray:
    """Median distance [px] per view between present corners and the prediction (inf: board behind
    the camera or no corner)."""
    d = np.linalg.norm(pred - corners, axis=-1)
    present = np.all(np.isfinite(corners), axis=-1)
    d = np.where(present, np.where(np.isfinite(d), d, np.inf), np.nan)
    out = np.full(len(d), np.inf)
    ok = present.any(axis=1)
    out[ok] = np.nanmedian(d[ok], axis=1)
    return out


def corner_distance(model: HumanoidModel, theta, feet, corners, *, relabel: bool = False, pred=None) -> float:
    """Median over views of the median corner distance [px] from the zero-offset prediction.

    ``relabel``: per view, the closest of the grid's four orderings (:func:`_orderings`) counts.
    ``pred``: the prediction, when already computed.
    """
    pred = _predict(model, theta, feet) if pred is None else pred
    cands = _orderings(corners, model.board.rows, model.board.cols) if relabel else [np.asarray(corners)]
    d = np.min(np.stack([_view_distance(pred, c) for c in cands]), axis=0)
    return float(np.median(d)) if d.size else float("inf")


def _spread(uv) -> np.ndarray:
    """RMS distance (V,) [px] of each view's present corners from their centroid."""
    present = np.all(np.isfinite(uv), axis=-1)
    c = np.where(present[..., None], uv, 0.0)
    n = np.maximum(present.sum(axis=1), 1)
    mean = c.sum(axis=1) / n[:, None]
    sq = np.where(present, np.sum((uv - mean[:, None]) ** 2, axis=-1), 0.0)
    return np.sqrt(sq.sum(axis=1) / n)


def size_ratio(model: HumanoidModel, theta, feet, corners, *, pred=None) -> float:
    """Median over views of (detected spread / predicted spread) of the board's corners; NaN when the
    model puts every board behind the camera. Only the corners present in both count."""
    pred = _predict(model, theta, feet) if pred is None else pred
    corners = np.asarray(corners)
    both = np.all(np.isfinite(pred), -1) & np.all(np.isfinite(corners), -1)
    ok = both.sum(axis=1) >= 3
    if not ok.any():
        return float("nan")
    mask = np.where(both[..., None], 1.0, np.nan)
    r = _spread(corners[ok] * mask[ok]) / np.maximum(_spread(pred[ok] * mask[ok]), 1e-300)
    return float(np.median(r))


def handedness(corners, rows: int, cols: int) -> np.ndarray:
    """Sign (V,) of each view's grid orientation: +1 as a board whose printed face looks at the
    camera appears (the image of the board's x edge crossed with its y edge is positive for
    ``fx, fy > 0``), -1 mirrored, 0 undecided (corners missing at the grid's ends)."""
    g = np.asarray(corners).reshape(len(corners), rows, cols, 2)
    a = g[:, 0, -1] - g[:, 0, 0]
    b = g[:, -1, 0] - g[:, 0, 0]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return np.where(np.isfinite(cross), np.sign(cross), 0.0)


def joint_unit_slip(declared: str, apply: Callable[[float], float]) -> list[Slip]:
    """The joint records were in the other angle unit than ``joints.unit`` says."""
    if declared == "deg":
        return [Slip("joints_rad_as_deg", "`joints` look like rad, not deg (joints.unit)", "read as rad",
                     lambda: apply(np.degrees(1.0)))]
    if declared == "rad":
        return [Slip("joints_deg_as_rad", "`joints` look like deg, not rad (joints.unit)", "read as deg",
                     lambda: apply(np.radians(1.0)))]
    return []


def _images_mirrored(model: HumanoidModel, theta, feet, corners) -> Slip:
    """The slip "images mirrored left-right": figure :func:`corner_distance` with the corners flipped back."""

    def mirrored() -> float:
        c2 = np.array(corners, copy=True)
        c2[..., 0] = (model.camera.width - 1) - c2[..., 0]  # pixel centres at integers: column i <-> W - 1 - i
        return corner_distance(model, theta, feet, c2, relabel=True)

    return Slip("images_mirrored", "the images look mirrored left-right", "with the images flipped back", mirrored)


def check_data(model: HumanoidModel, data, *, declared: dict | None = None, consistency_px: float = 60.0,
               accept_implausible: bool = False, implausible_answer: str | None = None) -> list[Diagnostic]:
    """The three checks of this module on detected ``data``; raise
    :class:`~robocal.errors.ImplausibleInputError` naming the slip (or, when none explains it, what is
    wrong), or with ``accept_implausible`` return ``implausible_input`` warnings.

    Parameters
    ----------
    declared : dict, optional
        Units the fields were read in (``{"board.square": "mm", "board.centre": "mm", "joints":
        "deg"}``, the loader's ``info["declared"]``); default :data:`DECLARED_SI`.
    implausible_answer : str, optional
        Set after a solve whose answer is implausible (:func:`calibrate`: offsets beyond 5 deg), with
        the reason: the corner-distance slips are then tried whatever the distance (a slip such as
        two swapped joint columns can leave it under the bound and still pull the offsets to tens of
        degrees), and the reason is the message when none explains the data.
    consistency_px : float
        The per-view consistency threshold [px] (``calibrate(consistency_px=)``); the median view is
        implausible beyond :data:`DISTANCE_FACTOR` times it, or times 60 px (the default) when it is
        lower: a tighter per-view check does not make small offsets a slip.

    Returns the warnings (empty for a plausible data set). A correct data set costs one projection
    of every corner (the size and distance checks share it) and the handedness of each grid.
    """
    declared = {**DECLARED_SI, **(declared or {})}
    theta, feet, corners = np.asarray(data.theta), np.asarray(data.feet), np.asarray(data.corners)
    rows, cols = model.board.rows, model.board.cols
    consistency_px = max(float(consistency_px), 60.0)
    out: list[Diagnostic] = []

    def run(**kw):
        d = check_slips(accept=accept_implausible, **kw)
        if d is not None:
            out.append(d)
        return d is None

    # the detector found the grid, so every view has a rows x cols labelling; a mirrored one is
    # physically impossible (the board's back would face the camera)
    def transposed() -> float:
        if rows == cols:
            raise InputError("a square grid reads the same transposed")
        m2 = with_board(model, board=Checkerboard(cols, rows, model.board.square, model.board.margin))
        c2 = corners.reshape(len(corners), rows, cols, 2).transpose(0, 2, 1, 3).reshape(corners.shape)
        return corner_distance(m2, theta, feet, c2, relabel=True)

    sign = handedness(corners, rows, cols)
    n_mirror, n_known = int(np.sum(sign < 0)), int(np.sum(sign != 0))
    if implausible_answer is None and n_known and n_mirror > n_known / 2:
        base = corner_distance(model, theta, feet, corners, relabel=True)
        run(what="median corner distance from the joint records' prediction", residual=base, unit="px",
            plausible=False, threshold=consistency_px,
            reason=f"the board appears mirrored in {n_mirror} of {n_known} views (its back would face the "
                   f"camera): check `board.rows` and `board.cols` and whether the images are flipped",
            slips=[Slip("board_transposed", f"`board.rows` and `board.cols` look swapped ({rows} x {cols} "
                                            f"declared, the images show {cols} x {rows})",
                        "with them swapped", transposed),
                   _images_mirrored(model, theta, feet, corners)])
        return out  # the further checks would only repeat the same slip

    pred = _predict(model, theta, feet)
    ratio = size_ratio(model, theta, feet, corners, pred=pred)
    if implausible_answer is None and np.isfinite(ratio) and not (1 / SIZE_LIMIT <= ratio <= SIZE_LIMIT):
        def mismatch(r: float) -> float:
            return max(r, 1 / r) if np.isfinite(r) and r > 0 else float("inf")

        def square_scaled(k: float) -> float:
            b = Checkerboard(rows, cols, model.board.square * k, model.board.margin)
            return mismatch(size_ratio(with_board(model, board=b), theta, feet, corners))

        cam = model.camera
        run(what="board's apparent size mismatch factor (detected / predicted)", residual=mismatch(ratio), unit="",
            plausible=False, threshold=SIZE_LIMIT,
            reason=f"the board appears {ratio:.3g}x the size the model predicts (square "
                   f"{model.board.square * 1e3:g} mm, fx {cam.fx:g} px, fy {cam.fy:g} px, camera-to-foot "
                   f"distance from the robot model): check `board.square` and the camera's fx, fy",
            slips=length_slips("board.square", declared["board.square"], square_scaled))
        return out

    base = corner_distance(model, theta, feet, corners, pred=pred)
    limit = DISTANCE_FACTOR * consistency_px
    if implausible_answer is not None or not base <= limit:
        slips = distance_slips(model, data, declared)
        run(what="median corner distance from the joint records' prediction", residual=base, unit="px",
            plausible=False, threshold=consistency_px,
            reason=implausible_answer or (
                f"the detected corners lie {base:.0f} px (median view) from where the joint records put "
                f"them, expected < {limit:.0f} px for offsets of a few degrees: check the joint records "
                f"and their unit, the feet, the board centre and the camera"),
            slips=slips)
    return out


def distance_slips(model: HumanoidModel, data, declared: dict | None = None) -> list[Slip]:
    """The slips the corner-distance check tries (figure: :func:`corner_distance` with the slip undone).

    Two swapped joint columns are one slip, the pair that fits best (every pair of moving joints is
    projected once when this is called: ~15 ms each for 20 views, only on the failing path)."""
    declared = {**DECLARED_SI, **(declared or {})}
    theta, feet, corners = np.asarray(data.theta), np.asarray(data.feet), np.asarray(data.corners)

    def centre_scaled(k: float) -> float:
        return corner_distance(with_board(model, centre=model.mounts[FEET[0]].centre * k), theta, feet,
                               corners, relabel=True)

    def joints_scaled(k: float) -> float:
        t2 = theta * k
        model.check_limits(t2)  # outside the limits: not this slip (InputError)
        return corner_distance(model, t2, feet, corners, relabel=True)

    def legs_swapped() -> float:
        other = np.array([FEET[1 - FEET.index(f)] for f in feet])
        return corner_distance(model, theta, other, corners, relabel=True)

    names = list(model.joint_names)

    def columns_swapped(pairs) -> float:
        t2 = theta.copy()
        for a, b in pairs:
            t2[:, [a, b]] = t2[:, [b, a]]
        model.check_limits(t2)  # outside the limits: not this slip (InputError)
        return corner_distance(model, t2, feet, corners, relabel=True)

    lr = [(names.index(n), names.index("R" + n[1:])) for n in names
          if n.startswith("L") and "R" + n[1:] in names]
    def order_reversed() -> float:
        return corner_distance(model, theta, feet, corners[::-1], relabel=True)

    slips = (joint_unit_slip(declared["joints"], joints_scaled)
             + length_slips("board.centre", declared["board.centre"], centre_scaled)
             + [Slip("feet_swapped", "`feet` look swapped (left <-> right)", "with left and right swapped",
                     legs_swapped),
                Slip("images_reversed", "`images` look listed in reverse order of the joint records",
                     "with the image list reversed", order_reversed),
                _images_mirrored(model, theta, feet, corners)]
             + ([Slip("joints_left_right_swapped", "the joint records' left and right leg columns look swapped "
                                                  "(joints.names order)", "with L* and R* swapped",
                      lambda: columns_swapped(lr))] if lr else []))
    best_pair, best = None, np.inf
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if np.ptp(theta[:, a]) == 0 and np.ptp(theta[:, b]) == 0:
                continue
            try:
                v = columns_swapped([(a, b)])
            except InputError:
                continue
            if v < best:
                best_pair, best = (a, b), v
    if best_pair is not None:
        a, b = best_pair
        slips.append(Slip("joints_columns_swapped", f"the joint records' columns {names[a]!r} and {names[b]!r} look "
                                                    f"swapped (joints.names order)", "with them swapped",
                          lambda: best))
    return slips


def name_slip(model: HumanoidModel, data, *, declared: dict | None = None, consistency_px: float = 60.0) -> None:
    """Raise :class:`~robocal.errors.ImplausibleInputError` naming the :func:`distance_slips` slip that explains
    ``data`` (the figure drops 5x and under ``max(consistency_px, 60)``); return quietly when none does, so the
    caller raises its own error (a view refused by the consistency check, a diverged fit)."""
    consistency_px = max(float(consistency_px), 60.0)
    theta, feet, corners = np.asarray(data.theta), np.asarray(data.feet), np.asarray(data.corners)
    base = corner_distance(model, theta, feet, corners)
    slips = distance_slips(model, data, declared)
    trial = try_slips(slips, base, threshold=consistency_px)
    if trial.best is None:
        return
    check_slips(what="median corner distance from the joint records' prediction", residual=base, unit="px",
                plausible=False, reason="", trial=trial)
