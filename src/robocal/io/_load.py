"""Validated loading of YAML / JSON / CSV input files.

Every error names the file and the field at fault, e.g.
``room.yaml: field 'points.world': must have shape (N, 2), got (3,)``.
YAML is read with PyYAML's ``SafeLoader`` only (no object construction),
extended so that an unquoted ``1e-3`` is a number as in YAML 1.2 (YAML 1.1
reads a float without a dot as text).

Numbers must be written as numbers: a quoted ``"2.9"`` is text, and reading it
where a number is expected is an error, as is a boolean or ``null``. A
quantity mapping holds exactly ``value`` and ``unit``: any other key (a typo
such as ``units:``, or an unsupported ``sigma:``) is an error, not ignored.

Quantities carry units in the file, in one of two forms::

    height: {value: 2.9, unit: m}        # inline
    units: {length: mm, angle: deg}      # document default per kind
    points: [[0, 0], [1200, 0]]          # read with kind="length" -> mm -> m

The ``units`` mapping is checked the first time a quantity is read: its keys
must be known kinds (``length``, ``angle``, ``time``, ...) and its values
units of that kind, so ``units: cm`` or ``units: {angel: deg}`` is an error,
not a silently ignored line.

CSV files have a header row; a column's unit goes in brackets:
``x [mm], z [mm], profile``. Text is read as UTF-8 with an optional byte-order
mark (Excel's "CSV UTF-8"); errors name the data row and the file line.
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robocal.errors import FileFormatError, RobocalError, UnitError
from robocal.io._units import UNITS, to_si, unit_kind
from robocal.validation import _first_leaf, _is_text, check_array, format_shape

__all__ = ["Document", "load_document", "parse_document", "CsvTable", "load_csv"]

_MISSING = object()

#: kinds a document's ``units`` mapping may name, and the units of each
_KIND_UNITS: dict[str, list[str]] = {}
for _unit, (_kind, _) in UNITS.items():
    _KIND_UNITS.setdefault(_kind, []).append(_unit)


def _read_text(path: Path, source: str) -> str:
    """A file's text as UTF-8, without a leading byte-order mark."""
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FileFormatError("file not found", source=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"cannot read file ({exc})", source=source) from None


class _SafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also resolves YAML 1.2 floats without a dot.

    YAML 1.1 (PyYAML) reads ``1e-3`` and ``2E5`` as *strings*; with the
    string-versus-number check in :meth:`Document.array` that would refuse an
    unquoted number. Quoted scalars never go through implicit resolvers, so
    ``"1e-3"`` stays a string. No other tag is added: this loader constructs
    only plain Python data, like ``yaml.safe_load``.
    """


class _DuplicateKeyError(yaml.YAMLError):
    """A mapping names a key twice; the message names the key and both lines."""


def _duplicate_key_message(key, first: int, second: int) -> str:
    return f"key {key!r} appears twice (lines {first} and {second}); keep one"


def _check_unique_keys(loader: yaml.SafeLoader, node: yaml.MappingNode) -> None:
    # PyYAML keeps the last of two equal keys without a word: `H:` written twice
    # silently took the second value (issue 18). Merge keys (`<<`) are left to
    # PyYAML: overriding a merged key is their purpose.
    seen: dict = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge" or not isinstance(key_node, yaml.ScalarNode):
            continue
        key = loader.construct_object(key_node, deep=True)
        line = key_node.start_mark.line + 1
        try:
            first = seen.get(key)
        except TypeError:  # an unhashable key: PyYAML reports it itself
            continue
        if first is not None:
            raise _DuplicateKeyError(_duplicate_key_message(key, first, line))
        seen[key] = line


def _construct_mapping(loader, node, deep=False):
    if isinstance(node, yaml.MappingNode):
        _check_unique_keys(loader, node)
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


# libyaml's parser (PyYAML's C extension, in every PyYAML wheel) reads a file
# ~7x faster than the pure-Python one (10^4 points: 0.5 s instead of 3.6 s);
# construction, and so every check here, stays the same Python code.
_LOADERS = [_SafeLoader]
if hasattr(yaml, "CSafeLoader"):
    class _CSafeLoader(yaml.CSafeLoader):
        """:class:`_SafeLoader` on libyaml's parser."""

    _LOADERS.append(_CSafeLoader)

for _loader in _LOADERS:
    _loader.construct_mapping = _construct_mapping
    _loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
        list("-+.0123456789"),
    )
#: the loader used for input files: the C one where PyYAML was built with libyaml
_YAML_LOADER = _LOADERS[-1]

#: keys allowed in an inline quantity mapping ``{value: ..., unit: ...}``
_QUANTITY_KEYS = ("value", "unit")


def _closest(name: str, allowed) -> str | None:
    """The allowed name closest to a misspelt ``name`` (difflib's default cutoff), or None."""
    import difflib  # here: only a misspelt name needs it (~2 ms of every command's start-up, issue 16)
    close = difflib.get_close_matches(name, list(allowed), n=1)
    return close[0] if close else None


def _describe_text(v) -> str:
    """``"a quoted string ('2.9')"`` for number-like text, ``"a string ('abc')"`` otherwise.

    ``nan`` / ``inf`` are text even unquoted in YAML (which spells them
    ``.nan`` / ``.inf``), so they get that hint instead of "quoted".
    """
    text = v.decode("utf-8", "replace") if isinstance(v, bytes) else v
    if text.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
        return f"a string ({text!r}; YAML spells these .nan, .inf, -.inf)"
    try:
        float(text)
    except ValueError:
        return f"a string ({text!r})"
    return f"a quoted string ({text!r})"


def _unique_json_object(pairs):
    d = {}
    for k, v in pairs:
        if k in d:
            raise _DuplicateKeyError(k)
        d[k] = v
    return d


def _json_duplicate_lines(text: str, key: str) -> tuple[int, int] | None:
    """Lines of a duplicated JSON key: JSON is YAML-readable, and the YAML check has the marks."""
    try:
        yaml.load(text, Loader=_SafeLoader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKeyError as exc:
        m = re.search(r"lines (\d+) and (\d+)", str(exc))
        return (int(m.group(1)), int(m.group(2))) if m else None
    except yaml.YAMLError:
        return None
    return None


def _parse_text(text: str, suffix: str, source: str) -> Any:
    text = text.removeprefix("\ufeff")
    try:
        if suffix == ".json":
            try:
                return json.loads(text, object_pairs_hook=_unique_json_object)
            except _DuplicateKeyError as exc:
                key = exc.args[0]
                lines = _json_duplicate_lines(text, key)
                msg = (_duplicate_key_message(key, *lines) if lines else f"key {key!r} appears twice in one object; keep one")
                raise FileFormatError(msg, source=source) from None
        return yaml.load(text, Loader=_YAML_LOADER)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKeyError as exc:
        raise FileFormatError(str(exc), source=source) from None
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

    A malformed ``units`` entry is raised by the first read that gives a
    ``kind`` (files that use ``units`` as free text and read no quantities,
    such as result files, still load).
    """

    data: dict
    source: str = "<input>"
    prefix: str = ""
    units: dict = field(default_factory=dict)
    units_error: RobocalError | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.data, dict):
            where = f"field '{self.prefix}'" if self.prefix else "top level"
            raise FileFormatError(f"{where} must be a mapping, got {type(self.data).__name__}", source=self.source)
        if "units" in self.data:
            own = self.data["units"]
            error = self._check_units(own)
            if error is not None:
                self.units_error = error
            else:
                self.units = {**self.units, **{kind: str(unit) for kind, unit in own.items()}}

    def _check_units(self, own) -> RobocalError | None:
        """The error in a ``units`` mapping (kind -> unit of that kind), or None."""
        kinds = ", ".join(sorted(_KIND_UNITS))
        if not isinstance(own, dict):
            got = "null" if own is None else f"{type(own).__name__} ({own!r})"
            return self.error("units", f"must be a mapping of kind to unit, e.g. {{length: mm, angle: deg}}, got {got}")
        for kind, unit in own.items():
            key = f"units.{kind}"
            if kind not in _KIND_UNITS:
                return self.error(key, f"unknown kind {kind!r} (known: {kinds})", UnitError)
            known = ", ".join(_KIND_UNITS[kind])
            if isinstance(unit, bool) or not isinstance(unit, (str, int)):
                return self.error(key, f"must be a unit of {kind} ({known}), got {type(unit).__name__} ({unit!r})", UnitError)
            if str(unit) not in UNITS:
                return self.error(key, f"unknown unit {str(unit)!r} (units of {kind}: {known})", UnitError)
            got_kind = UNITS[str(unit)][0]
            if got_kind != kind:
                return self.error(key, f"must be a unit of {kind} ({known}), got {unit!r} (a unit of {got_kind})", UnitError)
        return None

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

    def require_known_keys(self, allowed) -> None:
        """Raise naming the first key not in ``allowed``, with the closest known key when there is one.

        A misspelt optional key (``tilt_mim:``) would otherwise be ignored and
        its default used without a word.
        """
        allowed = tuple(allowed)
        for key in self.data:
            if key not in allowed:
                close = _closest(str(key), allowed)
                hint = f" (did you mean {close!r}?)" if close else ""
                raise self.error(str(key), f"unknown key{hint}; known keys: {', '.join(allowed)}")

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
        return Document(val, self.source, self._path(key), dict(self.units), self.units_error)

    def items_list(self, key: str) -> list["Document"]:
        """A list of mappings, each as a :class:`Document`."""
        val = self.raw(key)
        if not isinstance(val, list):
            raise self.error(key, f"must be a list, got {type(val).__name__}")
        return [
            Document(v, self.source, f"{self._path(key)}[{i}]", dict(self.units), self.units_error)
            for i, v in enumerate(val)
        ]

    def _unit_for(self, key: str, kind: str | None, value):
        if isinstance(value, dict):
            extra = [k for k in value if k not in _QUANTITY_KEYS]
            if extra:
                names = ", ".join(repr(k) for k in extra)
                close = _closest(extra[0], _QUANTITY_KEYS) if len(extra) == 1 and isinstance(extra[0], str) else None
                hint = f"; did you mean {close!r}?" if close else ""
                raise self.error(
                    key, f"unknown key{'s' if len(extra) > 1 else ''} {names} in a quantity mapping "
                    f"(allowed: {', '.join(_QUANTITY_KEYS)}){hint}"
                )
            if "value" not in value:
                raise self.error(key, "a quantity mapping needs 'value' and 'unit'")
            unit = value.get("unit")
            # `unit: 1` (dimensionless) is a YAML integer: read it as text, as the `units:` mapping does
            if isinstance(unit, int) and not isinstance(unit, bool):
                unit = str(unit)
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
        finite : bool
            Reject NaN, infinity and ``null``; with ``finite=False`` a ``null``
            reads as NaN (JSON has no NaN).

        Booleans are not numbers: ``true`` where a number is expected is an
        error. Nor is text: ``"2.9"`` (a quoted string) is refused with a
        message naming the field and the index of the string.
        An inline quantity mapping may hold only ``value`` and ``unit``.
        """
        if key not in self.data and default is not _MISSING:
            return default
        raw = self.raw(key)
        if kind is not None and self.units_error is not None:
            raise self.units_error
        value, unit = self._unit_for(key, kind, raw)
        if finite:
            where = _first_leaf(value, lambda v: v is None)
            if where == ():
                want = f"an array of shape {format_shape(shape)}" if shape else "a number"
                raise self.error(key, f"is empty (null), expected {want}")
            if where is not None:
                raise self.error(key, f"contains an empty value (null) at index {where}, expected numbers")
        where = _first_leaf(value, _is_text)
        if where == ():
            raise self.error(key, f"is {_describe_text(value)}, expected a number", FileFormatError)
        if where is not None:
            leaf = value
            for i in where:
                leaf = leaf[i]
            raise self.error(key, f"contains {_describe_text(leaf)} at index {where}, expected a number", FileFormatError)
        try:
            arr = check_array(value, "value", shape=shape, finite=finite)
            if shape is not None and arr.ndim != len(shape):
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
        if _is_text(val):
            raise self.error(key, f"is {_describe_text(val)}, expected an integer")
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
    text = _read_text(path, source)
    return parse_document(text, suffix=path.suffix.lower(), source=source)


@dataclass
class CsvTable:
    """Columns of a CSV file as float arrays, with the units from the header.

    ``lines[i]`` is the file line (1-based) of data row ``i``, for messages.
    """

    columns: dict[str, np.ndarray]
    units: dict[str, str | None]
    source: str
    lines: np.ndarray | None = None

    def where(self, i: int) -> str:
        """``"row 3 (line 5)"`` for data row index ``i`` (0-based), as used in messages."""
        if self.lines is None:
            return f"row {i + 1}"
        return f"row {i + 1} (line {int(self.lines[i])})"

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
            example = _KIND_UNITS.get(kind, ["unit"])[0]
            raise UnitError(f"column '{name}' needs a unit of {kind} in its header, e.g. '{name} [{example}]'",
                            source=self.source)
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


def _plain_table(lines):
    """(header cells, data, file line of each record) when every line after the header is a data row (no
    comment or blank line among them: a recorded log's usual shape), else None.

    The careful path tests each of a 12,000-row log's lines in Python (~15 ms, per reading); here the
    lines go to NumPy's reader as they are, and a row count equal to the line count shows that none was a
    comment or blank (the reader skips blank lines and rejects ``#`` text: then the careful path runs).
    """
    h = 0
    while h < len(lines) and (not lines[h].strip() or lines[h].lstrip().startswith("#")):
        h += 1
    body = lines[h + 1:]
    while body and not body[-1].strip():      # trailing blank lines, as an editor leaves them
        body.pop()
    if h == len(lines) or not body:
        return None
    try:
        data = np.loadtxt(body, delimiter=",", comments=None, ndmin=2, dtype=float)
    except ValueError:
        return None
    cells = lines[h].split(",")
    if data.shape != (len(body), len(cells)):
        return None
    return cells, data, np.arange(h + 1, h + 2 + len(body))


def _fast_table(kept):
    """(header cells, data) parsed by NumPy's C reader, or None to take the careful path.

    Only for files without quoted cells, where a record is one line split at
    commas. ``np.loadtxt`` reads 10^6 x 8 numbers in ~2 s where the ``csv``
    module plus a Python conversion take ~7 s. Anything it refuses (a bad
    cell, a short row, ``1_000`` which Python's float() reads but it does
    not) goes to :func:`_csv_table`, which names the cell or reads it.
    """
    cells = kept[0][1].split(",")
    body = [ln for _, ln in kept[1:]]
    if not body:
        return cells, np.empty((0, len(cells)))
    try:
        data = np.loadtxt(body, delimiter=",", comments=None, ndmin=2, dtype=float)
    except ValueError:
        return None
    return (cells, data) if data.shape[1] == len(cells) else None


def _csv_table(kept, source: str):
    """Header, names, data and record lines through the ``csv`` module, naming the first bad cell."""
    reader = csv.reader(ln for _, ln in kept)
    rows, row_lines = [], []
    try:
        for row in reader:
            rows.append(row)
            row_lines.append(kept[reader.line_num - 1][0])  # last physical line of the record
    except csv.Error as exc:
        raise FileFormatError(f"line {kept[reader.line_num - 1][0]}: not valid CSV ({exc})", source=source) from None
    header = [_split_header(c) for c in rows[0]]
    names = [h[0] for h in header]
    if len(set(names)) != len(names):
        raise FileFormatError(f"duplicate column names in header {names}", source=source)
    data = np.empty((len(rows) - 1, len(names)))
    for i, row in enumerate(rows[1:]):
        where = f"row {i + 1} (line {row_lines[i + 1]})"
        if len(row) != len(names):
            raise FileFormatError(f"{where} has {len(row)} values, header has {len(names)}", source=source)
        for j, cell in enumerate(row):
            try:
                data[i, j] = float(cell)
            except ValueError:
                raise FileFormatError(f"{where}, column '{names[j]}': not a number: {cell!r}", source=source) from None
    return header, names, data, row_lines


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
        text = _read_text(Path(path), source)
    text = text.removeprefix("\ufeff")
    lines = text.splitlines()
    fast = _plain_table(lines) if '"' not in text else None
    if fast is None:
        # (file line number, text) of the lines that are neither blank nor comments
        kept = [(n, ln) for n, ln in enumerate(lines, 1) if ln.strip() and not ln.lstrip().startswith("#")]
        if not kept:
            raise FileFormatError("file has no header row", source=source)
        fast = _fast_table(kept) if '"' not in text else None
        if fast is not None:
            fast = (*fast, [n for n, _ in kept])  # without quotes a record is one line
    if fast is not None:
        names_cells, data, row_lines = fast
        header = [_split_header(c) for c in names_cells]
        names = [h[0] for h in header]
        if len(set(names)) != len(names):
            raise FileFormatError(f"duplicate column names in header {names}", source=source)
    else:
        header, names, data, row_lines = _csv_table(kept, source)
    if finite:
        bad = np.argwhere(~np.isfinite(data))
        if bad.size:
            i, j = (int(k) for k in bad[0])  # row-major: the first bad cell in file order
            line = int(row_lines[i + 1])
            cell = lines[line - 1].split(",")[j] if '"' not in text else repr(float(data[i, j]))
            raise FileFormatError(f"row {i + 1} (line {line}), column '{names[j]}': value is "
                                  f"{cell.strip()}", source=source)
    missing = [r for r in required if r not in names]
    if missing:
        raise FileFormatError(f"missing column(s) {', '.join(missing)} (have: {', '.join(names)})", source=source)
    for _, unit in header:
        if unit is not None:
            try:
                unit_kind(unit)
            except UnitError as exc:
                raise UnitError(exc.message, source=source) from None
    return CsvTable(
        {n: data[:, j].copy() for j, n in enumerate(names)}, {n: u for n, u in header}, source,
        np.asarray(row_lines[1:], dtype=int)
    )
