"""Deprecated alias of :mod:`robocal.handeye.workflow` (hand-eye became a core package, issue 13); removed in
robocal 0.3."""

import warnings

from robocal._deprecation import REMOVED_IN
from robocal.handeye.workflow import *  # noqa: F401,F403
from robocal.handeye.workflow import __all__  # noqa: F401
from robocal.handeye.report import build_report  # noqa: F401  (moved out of the workflow module)
from robocal.handeye.commands import run_images, run_simulate_images  # noqa: F401

warnings.warn(f"robocal.rigs.lineprofiler.handeye_workflow is deprecated and will be removed in {REMOVED_IN}; "
              "use robocal.handeye.workflow instead", DeprecationWarning, stacklevel=2)
