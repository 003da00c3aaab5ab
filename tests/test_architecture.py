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


def test_library_code_never_imports_the_cli():
    # progress bars come from robocal.progress, DemoOutcome from robocal.workflow
    offenders = []
    for py in SRC.rglob("*.py"):
        rel = py.relative_to(SRC)
        # the program's entry points (python -m robocal, the launcher's robocal._program) run the CLI
        if rel.parts[0] == "cli" or py.name == "cli.py" or rel.parts in (("__main__.py",), ("_program.py",)):
            continue
        bad = [m for m in _imports(py) if m == "robocal.cli" or m.startswith("robocal.cli.")]
        if bad:
            offenders.append(f"{rel} imports {bad}")
    assert not offenders, offenders


#: What a rig's cli.py (declarations only) may import.
_CLI_ALLOWED = ("__future__", "argparse", "math", "pathlib", "robocal.workflow", "robocal.cli", "robocal.cli._common")


def _declares(fn: ast.FunctionDef) -> bool:
    """Whether a function only builds declarations: it calls Option(...) and nothing but str formatting."""
    calls = [n.func for n in ast.walk(fn) if isinstance(n, ast.Call)]
    names = {c.id for c in calls if isinstance(c, ast.Name)}
    return "Option" in names and names <= {"Option", "Command", "tuple", "str", "int", "float"}


def test_rig_cli_modules_are_declarations_only():
    # no numerical library and no rig library at module level, no long functions: the
    # work is in the rig's library modules, named by the Workflow's "module:attr" steps
    offenders = []
    # the core's hand-eye command (robocal.handeye, issue 13) is declared the way a rig's is
    for cli in [*RIGS.glob("*/cli.py"), SRC / "handeye" / "cli.py"]:
        tree = ast.parse(cli.read_text(encoding="utf-8"))
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                offenders += [f"{cli.parent.name}/cli.py imports {m}" for m in mods if m not in _CLI_ALLOWED]
            elif isinstance(node, ast.FunctionDef) and node.end_lineno - node.lineno > 15 and not _declares(node):
                offenders.append(f"{cli.parent.name}/cli.py: {node.name} is {node.end_lineno - node.lineno} lines "
                                 "(argument parsers only; move work into the rig's library)")
    assert not offenders, offenders


def test_no_module_over_600_lines():
    # cohesive modules (issue 20): a file over ~600 lines mixes concerns; split it along its seams
    long = {str(py.relative_to(SRC)): n for py in SRC.rglob("*.py")
            if (n := len(py.read_text(encoding="utf-8").splitlines())) > 650}
    assert not long, long


def _diagnostic_codes(path: Path) -> set[str]:
    """The literal codes of ``Diagnostic("code", ...)`` / ``Diagnostic(code="...")`` calls in one module."""
    codes = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Call):
            continue
        name = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", None)
        if name != "Diagnostic":
            continue
        args = [a for a in node.args[:1]] + [k.value for k in node.keywords if k.arg == "code"]
        codes.update(a.value for a in args if isinstance(a, ast.Constant) and isinstance(a.value, str))
    return codes


def test_every_warning_code_written_is_documented():
    from robocal.diagnostics import CODES

    used = {}
    for py in SRC.rglob("*.py"):
        for code in _diagnostic_codes(py):
            used.setdefault(code, str(py.relative_to(SRC)))
    assert len(used) >= 10, "the scan found too few Diagnostic(...) calls: it no longer reads the code"
    missing = {c: f for c, f in used.items() if c not in CODES}
    assert not missing, f"codes written but not in robocal.diagnostics.CODES: {missing}"
