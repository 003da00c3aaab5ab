"""File formats: validated input loading, units, pose lists, atomic writing, the shared result schema."""

from robocal.io._atomic import *  # noqa: F401,F403
from robocal.io._load import *  # noqa: F401,F403
from robocal.io._result import *  # noqa: F401,F403
from robocal.io._units import *  # noqa: F401,F403
from robocal.io._runs import *  # noqa: F401,F403
from robocal.io._poses import *  # noqa: F401,F403
from robocal.io._output import *  # noqa: F401,F403
from robocal.io import _atomic, _load, _output, _poses, _result, _runs, _units

__all__ = [*_atomic.__all__, *_load.__all__, *_result.__all__, *_units.__all__, *_runs.__all__, *_poses.__all__, *_output.__all__]
