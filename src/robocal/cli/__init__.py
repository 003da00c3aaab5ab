"""Command-line layer: the ``robocal`` program, the rig contract and CLI helpers."""

from robocal.cli._common import *  # noqa: F401,F403
from robocal.cli._rig import *  # noqa: F401,F403
from robocal.cli import _common, _rig

__all__ = [*_common.__all__, *_rig.__all__]
