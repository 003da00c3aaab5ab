"""Lazy package exports (PEP 562), for rig packages whose modules are heavy.

A rig package lists which submodule defines each exported name; the name is
imported on first access and then cached in the package. ``robocal <rig>
--help`` imports the rig's ``cli`` module, hence its package: without this,
the package would import numba, OpenCV, matplotlib and SciPy just to print a
help text (0.6-0.9 s instead of 0.2 s).
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict) -> tuple[Callable, Callable]:
    """Module-level ``__getattr__`` and ``__dir__`` for ``package``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Exported name -> name of the submodule that defines it. No exported
        name may also be a submodule's name: once that submodule is imported,
        Python sets the package attribute to the module and ``__getattr__``
        is no longer asked (the rigs' tests check this).
    namespace : dict
        The package's ``globals()``; resolved names are cached there.

    Usage, in a package ``__init__``::

        __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

    A submodule name not listed in ``exports`` is imported on access as well,
    as it was an attribute of a package that imported everything eagerly.
    """

    def __getattr__(name: str):
        module = exports.get(name)
        if module is not None:
            value = getattr(importlib.import_module(f"{package}.{module}"), name)
            namespace[name] = value
            return value
        if name.isidentifier() and not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}") is not None:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*namespace, *exports})

    return __getattr__, __dir__
