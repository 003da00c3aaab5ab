"""``robocal._lazy.lazy_exports``: lazy names, submodule attributes, and exported names that are submodule names.

Each test builds a small package in ``tmp_path`` and runs in a fresh interpreter, so that import order is
under control: ``pkg.calibrate`` is both a submodule and the function ``calibrate`` defined in it, like the
humanoid rig.
"""

import json
import subprocess
import sys
import textwrap

import pytest

from robocal._lazy import lazy_exports

INIT = '''
from robocal._lazy import lazy_exports

_EXPORTS = {"calibrate": "calibrate", "Result": "calibrate", "helper": "tools"}
__all__ = [*_EXPORTS]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals(), collisions=%s)
'''
CALIBRATE = '''
import sys
sys.modules[__package__].LOADED = sys.modules[__package__].__dict__.get("LOADED", ()) + ("calibrate",)

class Result:
    pass

def calibrate():
    return Result()
'''
TOOLS = '''
def helper():
    return 1
'''


def _make_package(root, name="lazypkg", collisions=("calibrate",)):
    pkg = root / name
    pkg.mkdir()
    (pkg / "__init__.py").write_text(INIT % (tuple(collisions),))
    (pkg / "calibrate.py").write_text(CALIBRATE)
    (pkg / "tools.py").write_text(TOOLS)
    (pkg / "other.py").write_text("VALUE = 3\n")
    return root


def _run(root, code: str):
    code = f"import sys; sys.path.insert(0, {str(root)!r})\n" + textwrap.dedent(code)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_nothing_is_imported_until_a_name_is_used(tmp_path):
    root = _make_package(tmp_path)
    out = _run(root, """
        import json, sys
        import lazypkg
        before = sorted(m for m in sys.modules if m.startswith("lazypkg."))
        f = lazypkg.calibrate
        after = sorted(m for m in sys.modules if m.startswith("lazypkg."))
        print(json.dumps([before, after, callable(f), f is sys.modules["lazypkg.calibrate"].calibrate]))
    """)
    assert out == [[], ["lazypkg.calibrate"], True, True]


@pytest.mark.parametrize("first", [
    "import lazypkg.calibrate",
    "import importlib; importlib.import_module('lazypkg.calibrate')",
    "from lazypkg.calibrate import Result",
    "import lazypkg.calibrate as m",
])
def test_submodule_first_then_name_is_the_function(tmp_path, first):
    root = _make_package(tmp_path)
    out = _run(root, f"""
        import json, sys, types
        {first}
        from lazypkg import calibrate
        import lazypkg
        import lazypkg.calibrate as again
        mod = sys.modules["lazypkg.calibrate"]
        print(json.dumps([
            isinstance(calibrate, types.FunctionType), calibrate is mod.calibrate,
            lazypkg.calibrate is mod.calibrate, again is mod.calibrate, lazypkg.LOADED,
        ]))
    """)
    # ``import pkg.calibrate as m`` does getattr(pkg, "calibrate") first (Python 3.7+): the function, as eagerly
    assert out == [True, True, True, True, ["calibrate"]]


def test_name_first_then_submodule_keeps_the_function(tmp_path):
    root = _make_package(tmp_path)
    out = _run(root, """
        import importlib, json, sys, types
        from lazypkg import calibrate
        import lazypkg.calibrate
        import lazypkg
        mod = importlib.import_module("lazypkg.calibrate")
        from lazypkg import calibrate as again
        print(json.dumps([
            isinstance(mod, types.ModuleType), calibrate is mod.calibrate, again is calibrate,
            lazypkg.calibrate is calibrate, lazypkg.Result is mod.Result, lazypkg.LOADED,
        ]))
    """)
    assert out == [True, True, True, True, True, ["calibrate"]]


def test_star_import_dir_and_other_names(tmp_path):
    root = _make_package(tmp_path)
    out = _run(root, """
        import json, sys, types
        import lazypkg.calibrate, lazypkg.tools
        from lazypkg import *
        import lazypkg
        print(json.dumps([
            calibrate is sys.modules["lazypkg.calibrate"].calibrate, helper is lazypkg.tools.helper,
            Result is lazypkg.calibrate.__globals__["Result"], sorted(set(lazypkg.__all__) - set(dir(lazypkg))),
            lazypkg.other.VALUE, isinstance(lazypkg, types.ModuleType),
        ]))
    """)
    assert out == [True, True, True, [], 3, True]


def test_assignment_and_deletion_still_work(tmp_path):
    """Only the import system's binding of the submodule is ignored; e.g. ``monkeypatch.setattr`` works."""
    root = _make_package(tmp_path)
    out = _run(root, """
        import json, sys
        import lazypkg
        original = lazypkg.calibrate
        lazypkg.calibrate = "patched"
        patched = lazypkg.calibrate
        lazypkg.calibrate = sys.modules["lazypkg.calibrate"]  # ignored, as from the import system
        still = lazypkg.calibrate
        del lazypkg.calibrate
        restored = lazypkg.calibrate is original
        try:
            del lazypkg.calibrate
            del lazypkg.calibrate
        except AttributeError:
            twice = "AttributeError"
        print(json.dumps([patched, still, restored, twice]))
    """)
    assert out == ["patched", "patched", True, "AttributeError"]


def test_unknown_names_raise_attribute_error(tmp_path):
    root = _make_package(tmp_path)
    out = _run(root, """
        import json
        import lazypkg
        print(json.dumps([hasattr(lazypkg, "no_such_name"), hasattr(lazypkg, "_private")]))
    """)
    assert out == [False, False]


def test_without_collisions_the_submodule_replaces_the_name(tmp_path):
    """Why ``collisions`` exists: a plain PEP 562 ``__getattr__`` loses the name once the submodule is imported."""
    root = _make_package(tmp_path, collisions=())
    out = _run(root, """
        import json, types
        import lazypkg.calibrate
        from lazypkg import calibrate
        print(json.dumps(isinstance(calibrate, types.ModuleType)))
    """)
    assert out is True


def test_reload_keeps_one_subclass_level(tmp_path):
    root = _make_package(tmp_path)
    out = _run(root, """
        import importlib, json, types
        import lazypkg
        importlib.reload(lazypkg)
        importlib.reload(lazypkg)
        import lazypkg.calibrate
        from lazypkg import calibrate
        print(json.dumps([type(lazypkg).__mro__[1] is types.ModuleType, isinstance(calibrate, types.FunctionType)]))
    """)
    assert out == [True, True]


def test_collision_must_be_an_export():
    with pytest.raises(ValueError, match="not_exported"):
        lazy_exports("robocal", {}, {}, collisions=("not_exported",))
