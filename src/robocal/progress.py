"""Progress bars for long library steps (> 2 s), shown on a terminal only.

A neutral core module: library code (a rig's detector, a simulator) and the
CLI both use it, so no library code imports the CLI for a progress bar.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

__all__ = ["progress"]


def progress(iterable: Iterable, *, desc: str = "", total: int | None = None, enabled: bool = True):
    """A tqdm progress bar on stderr (a plain iterator when disabled or stderr is not a terminal)."""
    if not enabled or not sys.stderr.isatty():
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False, file=sys.stderr)
