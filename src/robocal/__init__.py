"""robocal: robot geometric calibration and sensor dead reckoning.

The core packages (``geometry``, ``kinematics``, ``camera``, ``estimation``,
``io``, ``report``, ``cli``) know nothing of the rigs in ``robocal.rigs``;
each rig builds on the core and registers its CLI through the
``robocal.rigs`` entry-point group.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from robocal.errors import RobocalError

try:
    __version__ = _version("robocal")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["RobocalError", "__version__"]
