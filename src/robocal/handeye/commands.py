"""``robocal handeye calibrate-images`` and ``simulate-images``: the commands that start from images."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.handeye.report import build_report
from robocal.handeye.workflow import PosePair, calibrate, summary, to_result
from robocal.io import hash_inputs

__all__ = ["run_images", "run_simulate_images"]

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def run_images(args) -> int:
    """``robocal handeye calibrate-images --images DIR --robot POSES --camera CAM --target TARGET.yaml --out D``.

    The target's pose in each image with its covariance (:func:`robocal.handeye.images.view_poses`), paired
    with the robot pose of the same rank (images in name order, one robot pose per image; an image without
    a usable pose drops its robot pose, named), then :func:`calibrate` with the per-view stds as weights.
    """
    from robocal.camera import load_camera, load_target
    from robocal.errors import InputError, RobocalError, ShapeError
    from robocal.handeye.images import view_poses
    from robocal.io import load_poses, prepare_out_dir, write_run

    images = sorted(p for p in Path(args.images).iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES) \
        if Path(args.images).is_dir() else []
    if not images:
        raise InputError(f"no images (.png, .jpg, ...) in {args.images}")
    robot = load_poses(args.robot)
    if len(robot) != len(images):
        raise ShapeError(f"{args.robot} has {len(robot)} poses but {args.images} has {len(images)} images: one "
                         "robot pose per image, in the images' name order", source=str(args.robot))
    camera, target = load_camera(args.camera), load_target(args.target)
    try:
        views = view_poses(images, camera, target)
        pair = PosePair(robot.T[views.index], views.T_cam_target, Path(args.robot), Path(args.target),
                        None if robot.t is None else robot.t[views.index],
                        (robot.form, f"{len(views.names)} of {len(images)} images of a {target.kind}"))
        cal = calibrate(pair, method=args.method, no_refine=args.no_refine, pairs=args.pairs, setup=args.setup,
                        accept_implausible=args.accept_implausible, pose_sigmas=views.sigmas,
                        pose_covariances=_view_covariances(views))
        res = cal[0]
        res.warnings = list(views.warnings) + list(res.warnings)
        result = to_result(cal, pair)
        result.inputs = hash_inputs([Path(args.robot), Path(args.camera), Path(args.target), *images])
        result.diagnostics["views"] = [
            {"image": n, "pose": int(i), "rms_px": float(r), "ambiguity": float(a), "rotation_std_rad": float(s[0]),
             "translation_std_m": float(s[1])}
            for n, i, r, a, s in zip(views.names, views.index, views.rms_px, views.ambiguity, views.sigmas)]
        report = build_report(result)
    except RobocalError as exc:
        raise exc if exc.source is not None else exc.with_source(f"{args.images} + {args.robot}") from None
    out = prepare_out_dir(args.out, "handeye-calibrate-images")
    write_run(out, result, report)
    print(summary(result))
    return 0


def _view_covariances(views):
    """Each view's pose covariance (N, 6, 6) as the refinement takes it: an ambiguous view's inflated as its
    stds are (:data:`robocal.handeye.images.AMBIGUOUS_INFLATION`)."""
    from robocal.handeye.images import AMBIGUITY_LIMIT, AMBIGUOUS_INFLATION

    C = np.array(views.cov, float)
    C[np.asarray(views.ambiguity) > AMBIGUITY_LIMIT] *= AMBIGUOUS_INFLATION ** 2
    return C


def run_simulate_images(args) -> int:
    """``robocal handeye simulate-images --out DIR``: rendered views, robot poses, camera, target, truth."""
    from robocal.handeye.images import simulate_image_files
    from robocal.io import prepare_out_dir

    out = prepare_out_dir(args.out, "handeye-simulate-images")
    for p in simulate_image_files(out, np.random.default_rng(args.seed), poses=args.poses, setup=args.setup):
        print(f"wrote {p}")
    return 0
