"""Cameras: pinhole + Brown–Conrady model (OpenCV's), PnP, targets, renderer, detection.

Conventions: camera frame x right, y down, z forward; pixel (0, 0) is the
centre of the top-left pixel (OpenCV); ``T_cam_obj`` maps object-frame
points into the camera frame; lengths in metres, image coordinates in pixels.
See docs/camera.md.
"""

from robocal.camera._model import *  # noqa: F401,F403
from robocal.camera._pnp import *  # noqa: F401,F403
from robocal.camera._targets import *  # noqa: F401,F403
from robocal.camera._render import *  # noqa: F401,F403
from robocal.camera._detect import *  # noqa: F401,F403
from robocal.camera._files import *  # noqa: F401,F403
from robocal.camera._calibrate import *  # noqa: F401,F403
from robocal.camera import _calibrate
from robocal.camera._fisheye import *  # noqa: F401,F403
from robocal.camera import _fisheye
from robocal.camera._boards import *  # noqa: F401,F403
from robocal.camera._board_detect import *  # noqa: F401,F403
from robocal.camera import _board_detect, _boards
from robocal.camera._camera_files import *  # noqa: F401,F403
from robocal.camera import _camera_files, _detect, _files, _model, _pnp, _render, _targets

__all__ = [*_model.__all__, *_pnp.__all__, *_targets.__all__, *_render.__all__, *_detect.__all__,
           *_files.__all__, *_camera_files.__all__, *_boards.__all__, *_board_detect.__all__, *_calibrate.__all__, *_fisheye.__all__]
