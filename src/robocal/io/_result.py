"""The result file shared by every rig (schema ``robocal.result/2``; ``/1`` is still read).

A result is a JSON (or YAML) mapping a user can load in any language::

    schema: robocal.result/1
    robocal_version: "0.1.0"
    rig: projector                  # which workflow produced it
    method: nonlinear               # solver / variant
    created: 2026-11-22T14:03:11Z   # UTC, ISO 8601
    command: "robocal projector calibrate room.yaml --out out"
    inputs: {room.yaml: <sha256>}   # content hashes of every input file
    estimate: {...}                 # named values, SI units (m, rad); matrices as nested lists
    poses: {T_r_c: {parent: robot, child: camera, rotation_std: left}}   # every pose in `estimate`
    std: {...}                      # same keys; null where a value is not identifiable
    units: {...}                    # unit of each estimate key ("m", "rad", "1", ...)
    residual_rms: 0.0012            # in `residual_unit`
    residual_unit: m
    warnings: [{code, message, params, indices}, ...]
    diagnostics: {...}              # solver details: iterations, cost history, rank, ...

Frames follow ``T_parent_child`` naming (see ``docs/conventions.md``). Every
pose is written by :meth:`CalibrationResult.add_pose`, the one vocabulary of all
rigs: ``T_r_c.rotation`` (3x3), ``T_r_c.rotvec`` (rotation vector, rad) and
``T_r_c.translation`` (m) in ``estimate``; the standard deviations of the
rotation (a small rotation vector, rad, on the side ``poses[name].rotation_std``
names) and of the translation under ``T_r_c.rotvec`` and ``T_r_c.translation``
in ``std``. :meth:`CalibrationResult.pose` reads one back as a 4x4 matrix.

Schema history: ``robocal.result/2`` added ``poses`` (and the pose
vocabulary); a ``/1`` file loads with ``poses`` found from its
``X.rotation`` / ``X.translation`` key pairs.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robocal.diagnostics import Diagnostic
from robocal.errors import FileFormatError
from robocal.io._atomic import atomic_write_text, sha256_file

__all__ = ["SCHEMA", "READABLE_SCHEMAS", "CalibrationResult", "PoseEstimate", "to_jsonable", "write_result",
           "load_result", "hash_inputs", "set_command_line", "json_text"]

SCHEMA = "robocal.result/2"
#: Older schemas :func:`load_result` still reads.
READABLE_SCHEMAS = ("robocal.result/1", SCHEMA)

#: The command line of the running ``robocal`` CLI (set by its ``main``); results
#: made through the Python API record "" rather than the host's ``sys.argv``
#: (which under pytest or Jupyter is not a robocal command at all).
_COMMAND_LINE = ""


def set_command_line(argv) -> None:
    """Record the CLI's arguments for the ``command`` field of results made from now on (None: forget)."""
    global _COMMAND_LINE
    _COMMAND_LINE = "" if argv is None else shlex.join(["robocal", *map(str, argv)])


def to_jsonable(obj: Any) -> Any:
    """Convert numpy arrays/scalars, dataclasses with ``to_dict`` and paths to JSON types.

    Non-finite floats become ``None`` (JSON has no NaN), so a consumer never
    reads a NaN it did not expect.
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        # a flat list of Python numbers (a plotted series) in C loops, not a call per number: when
        # its sum is finite every term is (a finite sum that overflowed takes the general path)
        if obj and all(type(v) is float or type(v) is int for v in obj):
            try:
                if math.isfinite(sum(obj)):
                    return list(obj)
            except OverflowError:  # an int beyond any float beside a float
                pass
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "iub":
            return obj.tolist()
        if obj.dtype.kind == "f":
            finite = np.isfinite(obj)
            if finite.all():
                return obj.tolist()
            out = obj.astype(object)
            out[~finite] = None
            return out.tolist()
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        val = float(obj)
        return val if math.isfinite(val) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "to_dict"):
        return to_jsonable(obj.to_dict())
    return obj


def hash_inputs(paths) -> dict[str, str]:
    """``{path: sha256}`` for each existing input file."""
    return {str(p): sha256_file(p) for p in paths if p is not None and Path(p).is_file()}


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")


@dataclass
class CalibrationResult:
    """A rig's calibration result in the shared schema (see module docstring)."""

    rig: str
    method: str
    estimate: dict
    std: dict = field(default_factory=dict)
    units: dict = field(default_factory=dict)
    residual_rms: float | None = None
    residual_unit: str | None = None
    warnings: list[Diagnostic] = field(default_factory=list)
    inputs: dict[str, str] = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    poses: dict = field(default_factory=dict)
    command: str = field(default_factory=lambda: _COMMAND_LINE)
    created: str = field(default_factory=_now)
    robocal_version: str = field(default_factory=lambda: __import__("robocal").__version__)
    schema: str = SCHEMA

    def add_pose(self, name: str, T, *, std_rotation=None, std_translation=None, parent: str | None = None,
                 child: str | None = None, rotation_std: str = "left") -> "CalibrationResult":
        """Write the pose ``T`` (4x4, metres) under ``name`` in the shared vocabulary (module docstring).

        Parameters
        ----------
        name : str
            ``T_parent_child`` (``docs/conventions.md``), e.g. ``"T_r_c"``.
        T : (4, 4) array_like
            The transform; its rotation block must be a rotation.
        std_rotation, std_translation : (3,) array_like, optional
            Standard deviations of the rotation (a small rotation vector, rad)
            and of the translation (m); left out (no key in ``std``) for a pose
            that has none (an input, a derived frame). ``None`` entries mark
            components the data do not determine.
        parent, child : str, optional
            The frames' names in words (``"robot"``, ``"camera"``).
        rotation_std : {"left", "right"}
            Side of the rotation perturbation: ``R = Exp(d) @ R_hat`` (left,
            world side) or ``R = R_hat @ Exp(d)`` (right, body side).
        """
        from robocal.validation import check_transform
        from scipy.spatial.transform import Rotation

        T = check_transform(T, name=name)
        if rotation_std not in ("left", "right"):
            raise ValueError(f"rotation_std must be 'left' or 'right', got {rotation_std!r}")
        self.estimate[f"{name}.rotation"] = T[:3, :3]
        self.estimate[f"{name}.rotvec"] = Rotation.from_matrix(T[:3, :3]).as_rotvec()
        self.estimate[f"{name}.translation"] = T[:3, 3]
        self.units.update({f"{name}.rotation": "1", f"{name}.rotvec": "rad", f"{name}.translation": "m"})
        if std_rotation is not None:
            self.std[f"{name}.rotvec"] = _std3(std_rotation, f"{name} std_rotation")
        if std_translation is not None:
            self.std[f"{name}.translation"] = _std3(std_translation, f"{name} std_translation")
        info = {"rotation_std": rotation_std}
        if parent:
            info["parent"] = parent
        if child:
            info["child"] = child
        self.poses[name] = info
        return self

    def pose(self, name: str) -> "PoseEstimate":
        """The pose ``name`` as a 4x4 matrix with its standard deviations (``None`` where it has none)."""
        if name not in self.poses and f"{name}.rotation" not in self.estimate:
            have = ", ".join(self.poses) or "none"
            raise KeyError(f"no pose {name!r} in this {self.rig} result (poses: {have})")
        T = np.eye(4)
        T[:3, :3] = np.asarray(self.estimate[f"{name}.rotation"], dtype=float)
        T[:3, 3] = np.asarray(self.estimate[f"{name}.translation"], dtype=float)
        std_r, std_t = self.std.get(f"{name}.rotvec"), self.std.get(f"{name}.translation")
        return PoseEstimate(T, None if std_r is None else _nan_for_none(std_r),
                            None if std_t is None else _nan_for_none(std_t),
                            self.poses.get(name, {}).get("rotation_std", "left"))

    def to_dict(self) -> dict:
        return to_jsonable(
            {
                "schema": self.schema,
                "robocal_version": self.robocal_version,
                "rig": self.rig,
                "method": self.method,
                "created": self.created,
                "command": self.command,
                "inputs": self.inputs,
                "estimate": self.estimate,
                "poses": self.poses,
                "std": self.std,
                "units": self.units,
                "residual_rms": self.residual_rms,
                "residual_unit": self.residual_unit,
                "warnings": [w.to_dict() if isinstance(w, Diagnostic) else w for w in self.warnings],
                "diagnostics": self.diagnostics,
            }
        )

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "<result>") -> "CalibrationResult":
        if not isinstance(d, dict) or d.get("schema") not in READABLE_SCHEMAS:
            got = d.get("schema") if isinstance(d, dict) else type(d).__name__
            raise FileFormatError(f"not a robocal result: schema must be one of {', '.join(READABLE_SCHEMAS)}, "
                                  f"got {got!r}", source=source)
        try:
            return cls(
                rig=d["rig"],
                method=d["method"],
                estimate=d["estimate"],
                std=d.get("std", {}),
                units=d.get("units", {}),
                residual_rms=d.get("residual_rms"),
                residual_unit=d.get("residual_unit"),
                warnings=[Diagnostic.from_dict(w) for w in d.get("warnings", [])],
                inputs=d.get("inputs", {}),
                diagnostics=d.get("diagnostics", {}),
                poses=d["poses"] if "poses" in d else _poses_of_v1(d["estimate"]),
                command=d.get("command", ""),
                created=d.get("created", ""),
                robocal_version=d.get("robocal_version", ""),
            )
        except KeyError as exc:
            raise FileFormatError(f"field {exc.args[0]!r} is missing", source=source) from None


@dataclass(frozen=True)
class PoseEstimate:
    """One pose read from a result: ``T`` (4x4, m) and the std of its rotation (rad) and translation (m).

    A std is ``None`` when the result has none for the pose; NaN marks a
    component the data did not determine.
    """

    T: np.ndarray
    std_rotation: np.ndarray | None
    std_translation: np.ndarray | None
    rotation_std: str = "left"


def _std3(v, what: str):
    arr = [None if x is None else float(x) for x in np.asarray(v, dtype=object).reshape(-1)]
    if len(arr) != 3:
        raise ValueError(f"{what}: expected 3 values, got {len(arr)}")
    return [None if x is None or not math.isfinite(x) else x for x in arr]


def _nan_for_none(v) -> np.ndarray:
    return np.array([np.nan if x is None else float(x) for x in v])


def _poses_of_v1(estimate) -> dict:
    """The poses of a ``robocal.result/1`` file: its ``X.rotation`` + ``X.translation`` pairs."""
    if not isinstance(estimate, dict):
        return {}
    names = [k[: -len(".rotation")] for k in estimate if str(k).endswith(".rotation")]
    return {n: {"rotation_std": "left"} for n in names if f"{n}.translation" in estimate}


def write_result(path, result: CalibrationResult) -> Path:
    """Write ``result`` atomically as JSON (``.json``) or YAML (``.yaml``/``.yml``)."""
    path = Path(path)
    d = result.to_dict()
    if path.suffix.lower() in (".yaml", ".yml"):
        text = yaml.safe_dump(d, sort_keys=False, allow_unicode=True)
    else:
        text = json_text(d)
    return atomic_write_text(path, text)


_SCALARS = (str, int, float, bool, type(None))
_NUMBERS = (int, float, bool, type(None))
_ENCODER = json.JSONEncoder(allow_nan=False)  # one encoder: json.dumps(..., allow_nan=False) builds one per call


def _key_text(k) -> str:
    """A dict key as :func:`json.dumps` writes it (a number, bool or None as the string of its JSON text)."""
    if isinstance(k, str):
        return _ENCODER.encode(k)
    if isinstance(k, _NUMBERS):
        return _ENCODER.encode(_ENCODER.encode(k))
    raise TypeError(f"keys must be str, int, float, bool or None, not {type(k).__name__}")


def json_text(obj, *, indent: int = 2) -> str:
    """``obj`` as JSON text: objects indented, a list of scalars on one line, a matrix one row a line.

    ``json.dumps(obj, indent=2)`` puts every number of an array on its own
    line and, with ``indent``, runs CPython's pure-Python encoder: a flow
    result's plotted series (half a megabyte) took ~30 ms and read as a
    column of numbers. Here each flat list, and each matrix of numbers, is
    handed to the C encoder whole, so the text is half as long, written
    several times faster, and ``json.loads`` gives back exactly what
    ``json.dumps`` would (numbers keep ``repr``'s shortest round-trip digits;
    NaN and infinity are refused as before: ``ValueError``).
    """
    parts: list[str] = []
    _emit(obj, 0, indent, parts)
    return "".join(parts) + "\n"


def _emit(obj, level: int, indent: int, out: list) -> None:
    pad = " " * (indent * (level + 1))
    if isinstance(obj, dict):
        if not obj:
            out.append("{}")
            return
        out.append("{")
        sep = "\n"
        for k, v in obj.items():
            out.append(sep + pad + _key_text(k) + ": ")
            sep = ",\n"
            _emit(v, level + 1, indent, out)
        out.append("\n" + " " * (indent * level) + "}")
    elif isinstance(obj, (list, tuple)):
        if all(isinstance(x, _SCALARS) for x in obj):
            out.append(_ENCODER.encode(obj))  # [] too
        elif all(isinstance(r, (list, tuple)) and all(isinstance(x, _NUMBERS) for x in r) for r in obj):
            # rows of numbers: "], [" occurs only between rows (no strings inside), so the
            # whole matrix goes through the C encoder once and is then cut into lines
            text = _ENCODER.encode(obj)
            out.append("[\n" + pad + text[1:-1].replace("], [", "],\n" + pad + "[")
                       + "\n" + " " * (indent * level) + "]")
        else:
            out.append("[")
            sep = "\n"
            for v in obj:
                out.append(sep + pad)
                sep = ",\n"
                _emit(v, level + 1, indent, out)
            out.append("\n" + " " * (indent * level) + "]")
    else:
        out.append(_ENCODER.encode(obj))


def load_result(path, *, allow_incomplete: bool = False) -> CalibrationResult:
    """Load a result file written by :func:`write_result`.

    A result whose folder holds an ``INCOMPLETE`` marker (the run that wrote
    the folder was interrupted or failed, see :mod:`robocal.io._runs`) is
    refused with :class:`~robocal.errors.FileFormatError`: it is stale or
    half-made, and reading it as new is the error the marker exists to stop.
    ``allow_incomplete=True`` loads it anyway (to inspect a failed run).
    """
    from robocal.io._load import load_document
    from robocal.io._runs import INCOMPLETE, MANIFEST, read_manifest

    folder = Path(path).parent
    if not allow_incomplete and (folder / INCOMPLETE).exists():
        m = read_manifest(folder) or {}
        how = {"running": "is still running or was interrupted", "failed": "failed"}.get(m.get("state"), "did not finish")
        who = f"the `{m['command']}` run started {m.get('started')}" if m.get("command") else "the run that wrote it"
        raise FileFormatError(f"not a finished result: {who} {how} (the folder holds {INCOMPLETE}; see {MANIFEST}); "
                              "run the command again", source=str(path))
    doc = load_document(path)
    return CalibrationResult.from_dict(doc.data, source=str(path))
