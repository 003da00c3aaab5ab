"""Boundary validators: convert to float64 arrays, check shape and finiteness.

Each ``check_*`` returns the converted array or raises a
:class:`~robocal.errors.RobocalError` subclass whose message names the
argument and shows expected vs got, e.g.
``points must have shape (N, 3), got (4, 2)``. Call them where data enters
the library; internal code may skip re-validation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robocal.errors import InputError, NonFiniteError, ShapeError

__all__ = [
    "check_array",
    "check_points",
    "check_rotation_matrix",
    "check_transform",
    "check_positive",
    "format_shape",
]


def _is_bool(v) -> bool:
    return isinstance(v, (bool, np.bool_))


def _bool_text(v) -> str:
    return "true" if v else "false"


def _is_text(v) -> bool:
    return isinstance(v, (str, bytes))  # np.str_ / np.bytes_ are subclasses


def _text(v) -> str:
    """``v`` as a plain ``str`` (for messages: no ``np.str_(...)`` or ``b'...'`` wrapper)."""
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _first_leaf(x, match) -> tuple[int, ...] | None:
    """Index of the first leaf of nested lists/tuples ``x`` for which ``match(leaf)`` is true.

    Returns ``()`` when ``x`` itself is a matching scalar and ``None`` when
    nothing matches. Each list is walked once, so lists shared or nested in
    themselves (YAML aliases) cannot make the walk loop or blow up.
    """
    if not isinstance(x, (list, tuple)):
        return () if match(x) else None
    seen = {id(x)}
    stack = [iter(enumerate(x))]
    path: list[int] = []
    while stack:
        for i, v in stack[-1]:
            if isinstance(v, (list, tuple)):
                if id(v) not in seen:
                    seen.add(id(v))
                    path.append(i)
                    stack.append(iter(enumerate(v)))
                    break
            elif match(v):
                return (*path, i)
        else:
            stack.pop()
            if path:
                path.pop()
    return None


def format_shape(shape: Sequence[int | str | None]) -> str:
    """Render an expected shape such as ``(None, 3)`` as ``(..., 3)``."""
    parts = ["..." if s is None or s is Ellipsis else str(s) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def _ragged(x, index: tuple = (), seen: frozenset = frozenset()) -> str | None:
    """Where nested lists stop being rectangular, for the error message; None if they don't.

    A list that contains itself (a YAML alias like ``&a [1, *a]``) is not
    called ragged: None, and the caller's generic message stands.
    """
    if not isinstance(x, (list, tuple)):
        return None
    if id(x) in seen or any(isinstance(v, (list, tuple)) and id(v) in seen | {id(x)} for v in x):
        return None
    seen = seen | {id(x)}

    def size(v):
        if not isinstance(v, (list, tuple)):
            return "a single number"
        return f"{len(v)} entr{'y' if len(v) == 1 else 'ies'}"

    sizes = [size(v) for v in x]
    if len(set(sizes)) > 1:
        j = next(i for i, s in enumerate(sizes) if s != sizes[0])
        at = lambda i: f"index {(*index, i)}" if index else f"row {i}"  # noqa: E731
        return f"{at(0)} has {sizes[0]}, {at(j)} has {sizes[j]}"
    for i, v in enumerate(x):
        found = _ragged(v, (*index, i), seen)
        if found is not None:
            return found
    return None


def check_array(
    x,
    name: str,
    *,
    shape: Sequence[int | str | None] | None = None,
    min_ndim: int | None = None,
    finite: bool = True,
    dtype=np.float64,
) -> np.ndarray:
    """Convert ``x`` to an array and check it.

    Parameters
    ----------
    x : array_like
        Value to check.
    name : str
        Name used in error messages.
    shape : sequence of int, str or None, optional
        Expected trailing shape. An ``int`` must match exactly, a ``str``
        (e.g. ``"N"``) or ``None`` matches any size. A leading ``...``-style
        batch is allowed: only the trailing ``len(shape)`` axes are checked,
        unless ``min_ndim`` demands more.
    min_ndim : int, optional
        Minimum number of dimensions.
    finite : bool
        Reject NaN and infinity.
    dtype : numpy dtype
        Target dtype (float64 by default).

    Booleans (``True``, ``np.True_``, or inside lists) are not numbers and are
    rejected when ``dtype`` is numeric: a YAML ``true`` must not become 1.0.
    A boolean *ndarray* is an explicit mask and is converted as numpy does.
    Text is not a number either: ``"2.9"`` (alone, inside lists, or as a
    string ndarray) is rejected rather than parsed.
    """
    if np.issubdtype(dtype, np.number) and (isinstance(x, (list, tuple)) or _is_bool(x) or _is_text(x)):
        where = _first_leaf(x, lambda v: _is_bool(v) or _is_text(v))
        if where is not None:
            leaf = x
            for i in where:
                leaf = leaf[i]
            got = f"a boolean ({_bool_text(leaf)})" if _is_bool(leaf) else f"a string ({_text(leaf)!r})"
            if where == ():
                raise InputError(f"{name} must be a number, got {got}")
            raise InputError(f"{name} must contain numbers only, got {got} at index {where}")
    if np.issubdtype(dtype, np.number) and isinstance(x, np.ndarray) and x.dtype.kind in "US":
        raise InputError(f"{name} must be numeric, got an array of strings (dtype {x.dtype})")
    try:
        arr = np.asarray(x, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        ragged = _ragged(x)
        if ragged is not None:
            raise InputError(f"{name} has rows of different lengths: {ragged}") from None
        raise InputError(f"{name} must be numeric, got {type(x).__name__} ({exc})") from None
    if shape is not None:
        # ``(..., 3)`` and ``(3,)`` both mean "trailing axis of size 3"
        shape = tuple(shape)
        while shape and shape[0] is Ellipsis:
            shape = shape[1:]
        want = len(shape)
        ok = arr.ndim >= want
        if ok:
            for got, exp in zip(arr.shape[arr.ndim - want :], shape):
                if isinstance(exp, int) and got != exp:
                    ok = False
                    break
        if not ok:
            exp_txt = format_shape(shape)
            if want and arr.ndim > want:
                exp_txt = "(..., " + ", ".join(format_shape(shape)[1:-1].rstrip(",").split(", ")) + ")"
            raise ShapeError(f"{name} must have shape {exp_txt}, got {tuple(arr.shape)}")
    if min_ndim is not None and arr.ndim < min_ndim:
        raise ShapeError(f"{name} must have at least {min_ndim} dimensions, got shape {tuple(arr.shape)}")
    if finite and np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))
        where = tuple(int(i) for i in bad[0]) if bad.size else ()
        raise NonFiniteError(f"{name} contains NaN or infinity (first at index {where})")
    return arr


def check_points(x, name: str = "points", *, dim: int = 3, min_count: int = 1) -> np.ndarray:
    """Check an ``(N, dim)`` point array with at least ``min_count`` rows."""
    arr = check_array(x, name, shape=("N", dim))
    if arr.ndim != 2:
        raise ShapeError(f"{name} must have shape (N, {dim}), got {tuple(arr.shape)}")
    if arr.shape[0] < min_count:
        from robocal.errors import NotEnoughDataError

        raise NotEnoughDataError(f"{name} needs at least {min_count} points, got {arr.shape[0]}")
    return arr


def check_rotation_matrix(R, name: str = "R", *, atol: float = 1e-6) -> np.ndarray:
    """Check a (batch of) 3x3 proper rotation matrices (orthonormal, det = +1)."""
    arr = check_array(R, name, shape=(3, 3))
    RtR = np.einsum("...ji,...jk->...ik", arr, arr)
    err = np.abs(RtR - np.eye(3)).max(axis=(-2, -1))
    det = np.linalg.det(arr)
    if np.any(err > atol) or np.any(det < 0):
        worst = float(np.max(err))
        raise InputError(
            f"{name} must be a rotation matrix (R^T R = I, det R = +1), got max |R^T R - I| = {worst:.3g}, "
            f"det = {float(np.min(det)):.6g}"
        )
    return arr


def check_transform(T, name: str = "T", *, atol: float = 1e-6) -> np.ndarray:
    """Check a (batch of) 4x4 homogeneous rigid transforms."""
    arr = check_array(T, name, shape=(4, 4))
    check_rotation_matrix(arr[..., :3, :3], f"{name}[:3, :3]", atol=atol)
    if np.any(np.abs(arr[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])) > atol):
        raise InputError(f"{name} last row must be [0, 0, 0, 1], got {arr[..., 3, :].reshape(-1, 4)[0].tolist()}")
    return arr


def check_positive(x, name: str, *, strict: bool = True) -> np.ndarray:
    """Check that every element is > 0 (or >= 0 with ``strict=False``)."""
    arr = check_array(x, name)
    bad = arr <= 0 if strict else arr < 0
    if np.any(bad):
        rel = "> 0" if strict else ">= 0"
        raise InputError(f"{name} must be {rel}, got {arr[bad].reshape(-1)[0]!r}")
    return arr
