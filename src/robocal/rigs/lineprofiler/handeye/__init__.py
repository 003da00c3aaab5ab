"""Deprecated alias of :mod:`robocal.handeye` (hand-eye became a core package, issue 13); removed in robocal 0.3.

``robocal.rigs.lineprofiler.handeye`` and its modules (``.axxb``, ``.axzb``,
``.motions``, ``.plausibility``, ``.refine``) are the core's modules under their
old names, so old imports keep working (with one ``DeprecationWarning``) for
one release.
"""

import sys
import warnings

from robocal._deprecation import REMOVED_IN
from robocal.handeye import *  # noqa: F401,F403
from robocal.handeye import __all__  # noqa: F401
from robocal.handeye import axxb, axzb, motions, plausibility, refine

warnings.warn(f"robocal.rigs.lineprofiler.handeye is deprecated and will be removed in {REMOVED_IN}; "
              "use robocal.handeye instead", DeprecationWarning, stacklevel=2)

for _m in (axxb, axzb, motions, plausibility, refine):
    sys.modules[f"{__name__}.{_m.__name__.rsplit('.', 1)[1]}"] = _m
del _m
