"""The batch manifest: which data sets a batch calibrates (YAML or CSV; ``docs/batch.md``).

YAML (or JSON)::

    rig: humanoid                  # optional; when given, must be the RIG of the command line
    options: {}                    # optional: calibrate options for every data set (the option's
                                   #   name with '_' for '-', e.g. no_refine: true)
    datasets:
      - id: nao-01                 # letters, digits, '.', '_', '-': the folder DIR/<id>
        input: nao-01/run.yaml     # relative to the manifest's folder
      - id: nao-02
        inputs: [a.yaml, b.yaml]   # a rig with several inputs (handeye: GRIPPER TARGET)
        options: {max_outlier_sigma: 4}

CSV: a header line ``id,input`` (more inputs: ``input2``, ``input3``, ...;
a ``#`` line is a comment), one data set a line. Paths are not checked
here: a missing file fails that data set alone, as one row of the batch.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

from robocal.errors import FileFormatError, InputError

__all__ = ["BatchEntry", "load_manifest", "ID_PATTERN"]

#: What an id may hold: it names a folder on every OS, and never a hidden or parent one.
ID_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,99}")


@dataclass(frozen=True)
class BatchEntry:
    """One data set of a batch.

    Attributes
    ----------
    id : str
        Its name, and its folder ``DIR/<id>``.
    inputs : tuple of Path
        The calibrate inputs, in the order of the rig's ``input_arguments``.
    options : dict
        Calibrate options (the manifest's ``options`` updated by the data set's own).
    where : str
        ``manifest.yaml: datasets[3]`` -- for messages.
    """

    id: str
    inputs: tuple
    options: dict = field(default_factory=dict)
    where: str = ""


def _check_id(value, where: str, seen: dict) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        raise FileFormatError(f"{where}: id must be a string, got {type(value).__name__}")
    text = str(value)
    if not ID_PATTERN.fullmatch(text):
        raise FileFormatError(f"{where}: id {text!r} must be 1-100 letters, digits, '.', '_' or '-', "
                              "not starting with '.' or '-' (it names the folder DIR/<id>)")
    if text.lower() in seen:  # case-insensitive file systems would put two ids in one folder
        raise FileFormatError(f"{where}: id {text!r} is used twice (first at {seen[text.lower()]})")
    seen[text.lower()] = where
    return text


def _yaml_entries(path: Path) -> tuple[list[BatchEntry], str | None]:
    from robocal.io import load_document

    doc = load_document(path)
    doc.require_known_keys(("rig", "options", "datasets"))
    rig = doc.str("rig", default=None) if doc.raw("rig", None) is not None else None
    common = doc.raw("options", None) or {}
    if not isinstance(common, dict):
        raise doc.error("options", f"must be a mapping of option to value, got {type(common).__name__}")
    entries, seen = [], {}
    items = doc.items_list("datasets")
    if not items:
        raise doc.error("datasets", "is empty: list at least one data set (id and input)")
    for item in items:
        where = f"{path}: field '{item.prefix}'"
        item.require_known_keys(("id", "input", "inputs", "options"))
        ident = _check_id(item.raw("id"), where, seen)
        if ("input" in item) == ("inputs" in item):
            raise item.error("input", "give exactly one of 'input' (a path) or 'inputs' (a list of paths)")
        raw = [item.raw("input")] if "input" in item else item.raw("inputs")
        if not isinstance(raw, list) or not raw or not all(isinstance(p, str) and p for p in raw):
            raise item.error("inputs" if "inputs" in item else "input", f"must be a path or a list of paths, got {raw!r}")
        own = item.raw("options", None) or {}
        if not isinstance(own, dict):
            raise item.error("options", f"must be a mapping of option to value, got {type(own).__name__}")
        entries.append(BatchEntry(ident, tuple(_resolve(path, p) for p in raw), {**common, **own}, where))
    return entries, rig


def _resolve(manifest: Path, p: str) -> Path:
    q = Path(p).expanduser()
    return q if q.is_absolute() else manifest.parent / q


def _csv_entries(path: Path) -> list[BatchEntry]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read the manifest ({exc.strerror or exc})", source=str(path)) from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    if not rows:
        raise FileFormatError("the manifest is empty: expected a header 'id,input' and one data set a line",
                              source=str(path))
    head = [h.strip() for h in rows[0]]
    inputs = ["input"] + sorted((h for h in head if re.fullmatch(r"input[2-9]", h)), key=lambda h: int(h[5:]))
    unknown = [h for h in head if h not in ("id", *inputs)]
    if "id" not in head or "input" not in head or unknown:
        raise FileFormatError(f"header must be 'id,input' (more inputs: input2, input3, ...), got {','.join(head)!r}",
                              source=str(path))
    entries, seen = [], {}
    for k, row in enumerate(rows[1:], start=2):
        where = f"{path}: row {k}"
        cells = dict(zip(head, (c.strip() for c in row)))
        if len(row) != len(head):
            raise FileFormatError(f"{where}: {len(row)} cells, the header has {len(head)}")
        ident = _check_id(cells["id"], where, seen)
        paths = [cells[h] for h in inputs if cells.get(h)]
        if not cells.get("input"):
            raise FileFormatError(f"{where}: input is empty")
        entries.append(BatchEntry(ident, tuple(_resolve(path, p) for p in paths), {}, where))
    if not entries:
        raise FileFormatError("the manifest lists no data set (a header and no rows)", source=str(path))
    return entries


def load_manifest(path, *, rig: str | None = None) -> list[BatchEntry]:
    """The data sets of a manifest file (``.yaml``/``.yml``/``.json`` or ``.csv``), in file order.

    ``rig``: the rig the batch runs; a manifest that names another rig is
    refused (a fleet of one rig's files fed to another fails every data set).

    Raises
    ------
    FileFormatError
        A malformed manifest, naming the file and field or row.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        entries, named = _csv_entries(path), None
    elif suffix in (".yaml", ".yml", ".json"):
        entries, named = _yaml_entries(path)
    else:
        raise FileFormatError(f"a manifest is a .yaml, .yml, .json or .csv file, got {suffix or 'no suffix'!r}",
                              source=str(path))
    if rig is not None and named is not None and named != rig:
        raise FileFormatError(f"field 'rig': the manifest is for rig {named!r}, the command runs {rig!r}",
                              source=str(path))
    return entries
