"""Validated loading of YAML / JSON / CSV input files.

Every error names the file and the field at fault, e.g.
``room.yaml: field 'points.world': must have shape (N, 2), got (3,)``.
YAML is read with ``yaml.safe_load`` only (no object construction).

Quantities carry units in the file, in one of two forms::

    height: {value: 2.9, unit: m}        # inline
    units: {length: mm, angle: deg}      # document default per kind
    points: [[0, 0], [1200, 0]]          # read with kind="length" -> mm -> m

CSV files have a header row; a column's unit goes in brackets:
``x [mm], z [mm], profile``.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robocal.errors import FileFormatError, RobocalError, UnitError
from robocal.io._units import to_si, unit_kind
from robocal.validation import check_array

__all__ = ["Document", "load_document", "parse_document", "CsvTable", "load_csv"]

_MISSING = object()


def _parse_text(text: str, suffix: str, source: str) -> Any:
    try:
        if suffix == ".json":
            return json.loads(text)
        return yaml.safe_load(text)
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", source=source) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise FileFormatError(f"invalid YAML{where}: {problem}", source=source) from None


@dataclass
class Document:
    """A parsed mapping with its source, giving validated access to fields.

    Parameters
    ----------
    data : dict
        Parsed content.
    source : str
        File name used in error messages.
    prefix : str
        Dotted path of this mapping inside the file (for nested documents).
    units : dict
        Default unit per kind (``{"length": "mm"}``), inherited by sub-documents.
    """

    data: dict
    source: str = "<input>"
    prefix: str = ""
    units: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.data, dict):
            where = f"field '{self.prefix}'" if self.prefix else "top level"
            raise FileFormatError(f"{where} must be a mapping, got {type(self.data).__name__}", source=self.source)
        own = self.data.get("units")
        if isinstance(own, dict):
            merged = dict(self.units)
            for kind, unit in own.items():
                merged[str(kind)] = str(unit)
            self.units = merged

    # -- helpers -------------------------------------------------------------
    def _path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, message: str, cls=FileFormatError) -> RobocalError:
        """Build an error naming this file and ``key``."""
        return cls(f"field '{self._path(key)}': {message}", source=self.source)

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def keys(self):
        return self.data.keys()

    def raw(self, key: str, default=_MISSING):
        """The raw value of ``key``; a missing key without default is an error."""
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, "is missing")
        return default

    def sub(self, key: str, default=_MISSING) -> "Document":
        """Nested mapping as a :class:`Document` (inherits default units)."""
        val = self.raw(key, default)
        if val is default and default is not _MISSING and not isinstance(val, dict):
            val = {} if val is None else val
        return Document(val, self.source, self._path(key), dict(self.units))

    def items_list(self, key: str) -> list["Document"]:
        """A list of mappings, each as a :class:`Document`."""
        val = self.raw(key)
        if not isinstance(val, list):
            raise self.error(key, f"must be a list, got {type(val).__name__}")
        return [Document(v, self.source, f"{self._path(key)}[{i}]", dict(self.units)) for i, v in enumerate(val)]

    def _unit_for(self, key: str, kind: str | None, value):
        if isinstance(value, dict):
            if "value" not in value:
                raise self.error(key, "a quantity mapping needs 'value' and 'unit'")
            unit = value.get("unit")
            return value["value"], unit
        if kind is None:
            return value, None
        return value, self.units.get(kind)

    def array(self, key: str, *, kind: str | None = None, shape=None, default=_MISSING, finite: bool = True) -> np.ndarray:
        """Read a numeric field, convert it to SI (when ``kind`` is given) and check its shape.

        Parameters
        ----------
        key : str
            Field name.
        kind : str, optional
            Physical kind (``"length"``, ``"angle"``, ``"time"``, ...): the unit
            comes from an inline ``{value, unit}`` or from the document's
            ``units`` mapping; it is an error if neither gives one.
        shape : tuple, optional
            Expected trailing shape, as in :func:`robocal.validation.check_array`.
        """
        if key not in self.data and default is not _MISSING:
            return default
        value, unit = self._unit_for(key, kind, self.raw(key))
        try:
            arr = check_array(value, "value", shape=shape, finite=finite)
            if shape is not None and arr.ndim != len(shape):
                from robocal.validation import format_shape

                raise FileFormatError(f"must have shape {format_shape(shape)}, got {tuple(arr.shape)}")
        except RobocalError as exc:
            msg = exc.message.replace("value must", "must").replace("value contains", "contains")
            raise self.error(key, msg, type(exc)) from None
        if unit is None and kind is not None:
            if kind in ("dimensionless", "pixel"):
                return arr
            raise self.error(
                key,
                f"has no unit: give {{value: ..., unit: ...}} or a document-level 'units: {{{kind}: ...}}'",
                UnitError,
            )
        if unit is not None:
            try:
                if kind is not None:
                    return to_si(arr, unit, kind, name="value")
                unit_kind(unit)
                return to_si(arr, unit)
            except UnitError as exc:
                raise self.error(key, exc.message.replace("value needs", "needs"), UnitError) from None
        return arr

    def float(self, key: str, *, kind: str | None = None, default=_MISSING, positive: bool = False) -> float:
        """Read a scalar (SI when ``kind`` is given)."""
        if key not in self.data and default is not _MISSING:
            return default
        arr = self.array(key, kind=kind)
        if arr.ndim != 0:
            raise self.error(key, f"must be a single number, got shape {tuple(arr.shape)}")
        val = float(arr)
        if positive and not val > 0:
            raise self.error(key, f"must be > 0, got {val:g}")
        return val

    def int(self, key: str, *, default=_MISSING, minimum: int | None = None) -> int:
        val = self.raw(key, default)
        if isinstance(val, bool) or not isinstance(val, int):
            raise self.error(key, f"must be an integer, got {val!r}")
        if minimum is not None and val < minimum:
            raise self.error(key, f"must be >= {minimum}, got {val}")
        return val

    def str(self, key: str, *, default=_MISSING, choices=None) -> str:
        val = self.raw(key, default)
        if not isinstance(val, str):
            raise self.error(key, f"must be a string, got {type(val).__name__}")
        if choices is not None and val not in choices:
            raise self.error(key, f"must be one of {', '.join(map(repr, choices))}, got {val!r}")
        return val

    def bool(self, key: str, *, default=_MISSING) -> bool:
        val = self.raw(key, default)
        if not isinstance(val, bool):
            raise self.error(key, f"must be true or false, got {val!r}")
        return val

    def path(self, key: str, *, must_exist: bool = True, default=_MISSING) -> Path:
        """A file path, resolved relative to the document's directory."""
        val = self.raw(key, default)
        if val is None:
            return None
        if not isinstance(val, str):
            raise self.error(key, f"must be a path string, got {type(val).__name__}")
        base = Path(self.source).parent if self.source not in ("<input>", "") else Path(".")
        p = (base / val) if not Path(val).is_absolute() else Path(val)
        if must_exist and not p.exists():
            raise self.error(key, f"file not found: {p}")
        return p


def parse_document(text: str, *, suffix: str = ".yaml", source: str = "<input>") -> Document:
    """Parse YAML/JSON text into a :class:`Document`."""
    data = _parse_text(text, suffix, source)
    if data is None:
        raise FileFormatError("file is empty", source=source)
    return Document(data, source)


def load_document(path) -> Document:
    """Load a YAML (``.yaml``/``.yml``) or JSON (``.json``) file as a :class:`Document`."""
    path = Path(path)
    source = str(path)
    if path.suffix.lower() not in (".yaml", ".yml", ".json"):
        raise FileFormatError(f"expected a .yaml, .yml or .json file, got {path.suffix or 'no suffix'!r}", source=source)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileFormatError("file not found", source=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"cannot read file ({exc})", source=source) from None
    return parse_document(text, suffix=path.suffix.lower(), source=source)


@dataclass
class CsvTable:
    """Columns of a CSV file as float arrays, with the units from the header."""

    columns: dict[str, np.ndarray]
    units: dict[str, str | None]
    source: str

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def column(self, name: str, *, kind: str | None = None) -> np.ndarray:
        """A column, converted to SI when ``kind`` is given (its header must state a unit)."""
        if name not in self.columns:
            raise FileFormatError(
                f"column '{name}' is missing (have: {', '.join(self.columns)})", source=self.source
            )
        values = self.columns[name]
        unit = self.units.get(name)
        if kind is None:
            return values
        if unit is None:
            if kind in ("dimensionless", "pixel"):
                return values
            raise UnitError(f"column '{name}' needs a unit of {kind} in its header, e.g. '{name} [mm]'", source=self.source)
        try:
            return to_si(values, unit, kind, name=f"column '{name}'")
        except UnitError as exc:
            raise UnitError(exc.message, source=self.source) from None


def _split_header(cell: str) -> tuple[str, str | None]:
    cell = cell.strip()
    if cell.endswith("]") and "[" in cell:
        name, unit = cell[:-1].split("[", 1)
        return name.strip(), unit.strip()
    return cell, None


def load_csv(path, *, required=(), finite: bool = True, text: str | None = None) -> CsvTable:
    """Load a numeric CSV file with a header row (``#`` lines are comments).

    Parameters
    ----------
    path : path-like
        File to read (or a label when ``text`` is given).
    required : sequence of str
        Columns that must be present.
    finite : bool
        Reject NaN/inf values (the error names row and column).
    """
    source = str(path)
    if text is None:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except FileNotFoundError:
            raise FileFormatError("file not found", source=source) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"cannot read file ({exc})", source=source) from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise FileFormatError("file has no header row", source=source)
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    header = [_split_header(c) for c in rows[0]]
    names = [h[0] for h in header]
    if len(set(names)) != len(names):
        raise FileFormatError(f"duplicate column names in header {names}", source=source)
    data = np.empty((len(rows) - 1, len(names)))
    for i, row in enumerate(rows[1:]):
        if len(row) != len(names):
            raise FileFormatError(f"row {i + 1} has {len(row)} values, header has {len(names)}", source=source)
        for j, cell in enumerate(row):
            try:
                data[i, j] = float(cell)
            except ValueError:
                raise FileFormatError(f"row {i + 1}, column '{names[j]}': not a number: {cell!r}", source=source) from None
            if finite and not math.isfinite(data[i, j]):
                raise FileFormatError(f"row {i + 1}, column '{names[j]}': value is {cell.strip()}", source=source)
    missing = [r for r in required if r not in names]
    if missing:
        raise FileFormatError(f"missing column(s) {', '.join(missing)} (have: {', '.join(names)})", source=source)
    for _, unit in header:
        if unit is not None:
            try:
                unit_kind(unit)
            except UnitError as exc:
                raise UnitError(exc.message, source=source) from None
    return CsvTable({n: data[:, j].copy() for j, n in enumerate(names)}, {n: u for n, u in header}, source)
