"""Lazy package exports (PEP 562), for packages whose modules are heavy (the rigs, ``robocal.geometry``).

A rig package lists which submodule defines each exported name; the name is
imported on first access and then cached in the package. ``robocal <rig>
--help`` imports the rig's ``cli`` module, hence its package: without this,
the package would import numba, OpenCV, matplotlib and SciPy just to print a
help text (0.6-0.9 s instead of 0.2 s).
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable, Collection, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict, *,
                 collisions: Collection[str] = ()) -> tuple[Callable, Callable]:
    """Module-level ``__getattr__`` and ``__dir__`` for ``package``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Exported name -> name of the submodule that defines it. An exported
        name that is also a submodule's name must be listed in ``collisions``:
        otherwise, once that submodule is imported, Python sets the package
        attribute to the module and ``__getattr__`` is no longer asked (the
        rigs' tests check this).
    namespace : dict
        The package's ``globals()``; resolved names are cached there.
    collisions : collection of str, optional
        Exported names that are also submodule names (e.g. a function
        ``calibrate`` defined in the submodule ``calibrate``). The package
        attribute stays the exported object whatever is imported first, as
        with an eager ``from .calibrate import calibrate``; the submodule
        itself stays reachable through ``sys.modules`` and
        ``importlib.import_module``. This changes the class of the package
        module (``sys.modules[package]``) to a :class:`types.ModuleType`
        subclass; call it from the package ``__init__``.

    Usage, in a package ``__init__``::

        __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

    A public submodule name, and any submodule named in ``exports``' values
    (also a private one, ``_so3``), is imported on access as well, as it was
    an attribute of a package that imported everything eagerly.
    """
    collisions = frozenset(collisions)
    unknown = collisions - set(exports)
    if unknown:
        raise ValueError(f"collisions not in exports: {sorted(unknown)}")

    def _resolve(name: str):
        value = getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
        namespace[name] = value
        return value

    defining = frozenset(exports.values())

    def __getattr__(name: str):
        if name in exports:
            return _resolve(name)
        # a defining submodule is an attribute even when private (``robocal.geometry._so3``), as the eager
        # package's ``from package import _so3`` made it
        if name in defining:
            return importlib.import_module(f"{package}.{name}")
        if name.isidentifier() and not name.startswith("_"):
            from importlib.util import find_spec  # here: only this rare path needs it (start-up, issue 16)

            if find_spec(f"{package}.{name}") is not None:
                return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*namespace, *exports, *defining})

    if collisions:
        _install_collision_properties(package, collisions, namespace, _resolve)
    return __getattr__, __dir__


def _install_collision_properties(package: str, names: frozenset[str], namespace: dict,
                                  resolve: Callable[[str], object]) -> None:
    """Make each name of ``names`` a data descriptor of the package module's class.

    Why: after importing a submodule ``package.name``, the import system does
    ``setattr(package_module, name, submodule)``. A plain module stores it in
    its ``__dict__``, which shadows the module-level ``__getattr__``: ``from
    package import name`` would then give the submodule, not the exported
    object. An eager package avoided this only because its ``__init__``
    rebound the name after importing the submodule. Module attribute lookup
    (``object.__getattribute__``) consults data descriptors of the type before
    the instance ``__dict__``, so a property on a ``ModuleType`` subclass wins:
    its getter returns the exported object (resolving it on first access) and
    its setter ignores that one ``setattr`` from the import system while still
    accepting any other assignment (e.g. ``monkeypatch.setattr``).
    Python 3.7+ ``import package.name as m`` does ``getattr(package, "name")``
    first, so, as with the eager package, it gives the exported object.
    """
    submodule_names = {f"{package}.{name}" for name in names}

    def make_property(name: str) -> property:
        def fget(module):
            try:
                return namespace[name]
            except KeyError:
                return resolve(name)

        def fset(module, value):
            if isinstance(value, types.ModuleType) and value.__name__ in submodule_names:
                return  # the import system binding the submodule: keep the exported object
            namespace[name] = value

        def fdel(module):
            try:
                del namespace[name]
            except KeyError:
                raise AttributeError(name) from None

        return property(fget, fset, fdel, doc=f"``{package}.{name}``: the exported object, not the submodule")

    module = sys.modules[package]
    base = getattr(type(module), "_lazy_base", type(module))  # importlib.reload: replace, do not stack
    cls = type(f"_LazyModule_{package.replace('.', '_')}", (base,),
               {"_lazy_base": base, **{n: make_property(n) for n in names}})
    cls.__module__ = __name__
    module.__class__ = cls
