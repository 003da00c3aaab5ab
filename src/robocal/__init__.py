"""robocal: robot geometric calibration and sensor dead reckoning.

The core packages (``geometry``, ``kinematics``, ``camera``, ``estimation``,
``io``, ``report``, ``cli``) know nothing of the rigs in ``robocal.rigs``;
each rig builds on the core and registers its CLI through the
``robocal.rigs`` entry-point group.
"""

from robocal.errors import RobocalError

__all__ = ["RobocalError", "__version__"]


def __getattr__(name):
    # the version is read when asked for (robocal._metadata: cached), not on every import
    if name == "__version__":
        from robocal._metadata import version

        return version()
    raise AttributeError(f"module 'robocal' has no attribute {name!r}")
