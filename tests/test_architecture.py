"""The layering rules: the core never imports a rig; rigs never import each other."""

import ast
from pathlib import Path

import robocal

SRC = Path(robocal.__file__).parent
RIGS = SRC / "rigs"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_core_never_imports_a_rig():
    offenders = []
    for py in SRC.rglob("*.py"):
        if RIGS in py.parents:
            continue
        bad = [m for m in _imports(py) if m == "robocal.rigs" or m.startswith("robocal.rigs.")]
        if bad:
            offenders.append(f"{py.relative_to(SRC)} imports {bad}")
    assert not offenders, offenders


def test_rigs_do_not_import_each_other():
    offenders = []
    for rig in [p for p in RIGS.iterdir() if p.is_dir() and (p / "__init__.py").exists()]:
        for py in rig.rglob("*.py"):
            for m in _imports(py):
                if m.startswith("robocal.rigs.") and not m.startswith(f"robocal.rigs.{rig.name}"):
                    offenders.append(f"{py.relative_to(SRC)} imports {m}")
    assert not offenders, offenders


def test_no_global_numpy_random_state():
    # Randomness only through an np.random.Generator passed in.
    offenders = []
    for py in SRC.rglob("*.py"):
        text = py.read_text(encoding="utf-8")
        for bad in ("np.random.seed(", "np.random.rand(", "np.random.randn(", "np.random.normal(", "np.random.uniform("):
            if bad in text:
                offenders.append(f"{py.relative_to(SRC)}: {bad}")
    assert not offenders, offenders
