"""``robocal handeye calibrate-images`` and ``simulate-images``: the commands that start from images."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.handeye.bag_input import BagPosePair
from robocal.handeye.report import build_report
from robocal.handeye.workflow import calibrate, summary, to_result

__all__ = ["ImagePosePair", "load_image_pair", "run_images", "run_simulate_images"]

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class ImagePosePair(BagPosePair):
    """A pose pair whose camera poses come from a folder of images: the robot list, the camera, the target
    and the images are its input files (hashed into the result)."""

    @property
    def files(self) -> list[Path]:
        return [self.gripper_path, *self.extra_files]


def load_image_pair(robot_poses, images, camera, target) -> ImagePosePair:
    """The robot poses of ``robot_poses`` and the target's pose in each image of the folder ``images``.

    Images are taken in name order, one robot pose per image; each view's pose with its covariance comes
    from :func:`robocal.handeye.images.view_poses` (an image without a usable pose drops its robot pose,
    named in a warning). The pair carries the views' stds and covariances, so :func:`calibrate` weights
    each pose by its own view (``method+cov``), and their table for the result and report.
    """
    from robocal.camera import load_camera, load_target
    from robocal.errors import InputError, RobocalError, ShapeError
    from robocal.handeye.images import view_poses
    from robocal.io import load_poses

    if robot_poses is None:
        raise InputError("--images DIR needs the robot poses, one per image: robocal handeye calibrate "
                         "ROBOT_POSES.csv --images DIR --camera CAM --target TARGET.yaml", source="--images")
    if camera is None or target is None:
        raise InputError("--images (a folder) needs --camera CAM and --target TARGET.yaml: the camera's "
                         "intrinsics and the target's geometry give each view's pose", source="--images")
    folder = Path(images)
    found = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES) if folder.is_dir() else []
    if not found:
        raise InputError(f"no images (.png, .jpg, ...) in {folder}" + ("" if folder.exists() else
                         " (no such folder; with --bag, --images names an image topic)"), source="--images")
    robot = load_poses(robot_poses)
    if len(robot) != len(found):
        raise ShapeError(f"{robot_poses} has {len(robot)} poses but {folder} has {len(found)} images: one "
                         "robot pose per image, in the images' name order", source=str(robot_poses))
    cam, tgt = load_camera(camera), load_target(target)
    try:
        views = view_poses(found, cam, tgt)
    except RobocalError as exc:
        raise exc if exc.source is not None else exc.with_source(str(folder)) from None
    table = [{"image": n, "pose": int(i), "rms_px": float(r), "ambiguity": float(a), "rotation_std_rad": float(s[0]),
              "translation_std_m": float(s[1])}
             for n, i, r, a, s in zip(views.names, views.index, views.rms_px, views.ambiguity, views.sigmas)]
    return ImagePosePair(robot.T[views.index], views.T_cam_target, Path(robot_poses), Path(target),
                         None if robot.t is None else robot.t[views.index],
                         (robot.form, f"{len(views.names)} of {len(found)} images of a {tgt.kind}"),
                         extra_files=(Path(camera), Path(target), *found), pose_sigmas=views.sigmas,
                         pose_covariances=_view_covariances(views), warnings=list(views.warnings),
                         diagnostics={"views": table})


def run_images(args) -> int:
    """``robocal handeye calibrate-images --images DIR --robot POSES --camera CAM --target TARGET.yaml --out D``:
    the same as ``robocal handeye calibrate POSES --images DIR --camera CAM --target TARGET.yaml``
    (:func:`load_image_pair`, then :func:`calibrate` weighting each pose by its view's covariance)."""
    from robocal.errors import RobocalError
    from robocal.io import prepare_out_dir, write_run

    pair = load_image_pair(args.robot, args.images, args.camera, args.target)
    try:
        cal = calibrate(pair, method=args.method, no_refine=args.no_refine, pairs=args.pairs, setup=args.setup,
                        accept_implausible=args.accept_implausible)
        result = to_result(cal, pair)
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
