"""HTML reports with embedded plots (one self-contained file per run)."""

from robocal.report._html import *  # noqa: F401,F403
from robocal.report._diagnostics import *  # noqa: F401,F403
from robocal.report import _diagnostics, _html

__all__ = [*_html.__all__, *_diagnostics.__all__]
