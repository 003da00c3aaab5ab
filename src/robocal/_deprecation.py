"""Deprecated aliases: an old public name kept for one release after a rename."""

from __future__ import annotations

import functools
import warnings

#: The release in which the aliases made by :func:`deprecated_alias` are removed.
REMOVED_IN = "robocal 0.3"


def deprecated_alias(new, old_name: str, *, call: str | None = None):
    """``new`` under ``old_name``, warning ``DeprecationWarning`` (pointing at the caller) on each call.

    ``call``: how to write the call with the new name, when it is not simply
    ``new.__name__`` (e.g. ``"matrix_from_angle('x', angle)"``).
    """

    @functools.wraps(new)
    def alias(*args, **kwargs):
        warnings.warn(f"{old_name} is deprecated and will be removed in {REMOVED_IN}; use "
                      f"{call or new.__name__} instead", DeprecationWarning, stacklevel=2)
        return new(*args, **kwargs)

    alias.__name__ = alias.__qualname__ = old_name
    alias.__doc__ = f"Deprecated alias of :func:`{new.__name__}` (removed in {REMOVED_IN})."
    return alias
