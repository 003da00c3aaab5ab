"""Plausibility checks that name the slip behind an implausible answer.

A wrong unit, an inverted transform, a transposed board or a mirrored order
often still "fits": the solver converges, the residual is finite, and the
answer is garbage (a camera 110 m from the gripper, a joint offset of
190 deg). A rig therefore judges its answer against what the rest of the data
implies (a physical range, the noise it was told) and, when the answer is
implausible, undoes each likely slip in turn and refits. The slip that
explains the data is named in one line::

    `height` looks like mm, not m: with /1000 the residual drops from 38 to 0.4 px

By default that is an :class:`~robocal.errors.ImplausibleInputError` (exit
status 2 in the CLI); with ``accept=True`` (the CLI's
``--accept-implausible``) it becomes an ``implausible_input`` warning on the
result and the run goes on with the data as given.

Usage in a rig::

    diag = check_slips(
        what="reprojection RMS", residual=rms, unit="px",
        plausible=rms < 5 * sigma_px,
        reason=f"reprojection RMS {rms:.3g} px against {sigma_px:.3g} px noise",
        slips=[Slip("square_m_as_mm", "`square` looks like m, not mm", "with x1000",
                    lambda: refit(square=square * 1000).rms)],
        accept=accept_implausible, source="run.yaml: square")
    if diag is not None:
        warnings.append(diag)

Each slip's ``evaluate`` is called only when the answer is implausible, so a
correct run pays nothing for the checks.
"""

from __future__ import annotations

import math
import warnings as _warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from robocal.diagnostics import Diagnostic
from robocal.errors import ImplausibleInputError, RobocalError

__all__ = ["Slip", "SlipTrial", "check_slips", "try_slips", "length_slips", "LENGTH_UNITS", "IMPLAUSIBLE_CODE"]

#: warning code of an implausible answer accepted with ``--accept-implausible``
IMPLAUSIBLE_CODE = "implausible_input"

#: how much smaller the residual must get for a slip to count as the explanation
DEFAULT_FACTOR = 5.0

#: Length units a slip may confuse, in m.
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


@dataclass(frozen=True)
class Slip:
    """One likely slip and how to undo it.

    Attributes
    ----------
    name : str
        Stable identifier a script can test (``"height_mm_as_m"``,
        ``"deg_as_rad"``, ``"board_transposed"``, ``"columns_xy_swapped"``).
    describe : str
        What the slip is, as the user sees it: ``"`height` looks like mm, not m"``.
    fix : str
        The undoing, to be read as "<fix> the residual drops ...":
        ``"with /1000"``, ``"with the board's rows and columns swapped"``.
    evaluate : callable
        ``evaluate() -> float``: the same figure of merit as the baseline
        (same unit) with the slip undone. A :class:`RobocalError`, a
        non-finite value or a floating-point error count as "does not explain".
    """

    name: str
    describe: str
    fix: str
    evaluate: Callable[[], float]


@dataclass(frozen=True)
class SlipTrial:
    """The outcome of trying the slips on one implausible answer."""

    baseline: float
    unit: str
    tried: tuple[tuple[str, float | None], ...]  # (slip name, figure or None if it failed)
    best: Slip | None  # the slip that explains the data, or None
    best_value: float | None


def try_slips(slips: Sequence[Slip], baseline: float, *, unit: str = "",
              factor: float = DEFAULT_FACTOR, threshold: float | None = None) -> SlipTrial:
    """Evaluate each slip; the explaining one lowers ``baseline`` by ``factor`` (and below ``threshold``).

    Parameters
    ----------
    slips : sequence of Slip
        Candidates, each undone on its own.
    baseline : float
        The figure of merit (residual RMS, cost, ...) of the data as given.
    factor : float
        A slip explains the data when its figure is at most ``baseline / factor``.
    threshold : float, optional
        ... and at most this (e.g. a multiple of the stated noise), when given.
    """
    tried = []
    best, best_value = None, math.inf
    for slip in slips:
        try:
            with _warnings.catch_warnings():
                _warnings.simplefilter("ignore", RuntimeWarning)
                value = float(slip.evaluate())
        except (RobocalError, FloatingPointError, ArithmeticError, ValueError):
            value = math.nan
        ok = math.isfinite(value)
        tried.append((slip.name, value if ok else None))
        if ok and value < best_value:
            best, best_value = slip, value
    explains = best is not None and (not math.isfinite(baseline) or best_value <= baseline / factor) \
        and (threshold is None or best_value <= threshold)
    return SlipTrial(baseline=float(baseline), unit=unit, tried=tuple(tried),
                     best=best if explains else None, best_value=best_value if explains else None)


def _fmt(x: float) -> str:
    return "inf" if not math.isfinite(x) else f"{x:.3g}"


def check_slips(*, what: str, residual: float, unit: str, plausible: bool, reason: str,
                slips: Sequence[Slip] = (), accept: bool = False, source: str | None = None,
                factor: float = DEFAULT_FACTOR, threshold: float | None = None,
                trial: SlipTrial | None = None) -> Diagnostic | None:
    """Judge an answer; when implausible, name the slip that explains it.

    Parameters
    ----------
    what : str
        The figure of merit, for the message (``"residual"``, ``"reprojection RMS"``).
    residual : float
        Its value for the data as given (may be inf/NaN when the fit failed).
    unit : str
        Its unit (``"px"``, ``"mm"``); ``""`` for a dimensionless figure.
    plausible : bool
        The rig's verdict on the answer as given. When true nothing else is done.
    reason : str
        Why the answer is implausible, in words (used when no slip explains it).
    slips : sequence of Slip
        The likely slips for this input, tried only when ``plausible`` is false.
    accept : bool
        Go on with the data as given: return a warning instead of raising.
    source : str, optional
        File / field the slip is in, prefixed to the error.
    factor, threshold
        See :func:`try_slips`.
    trial : SlipTrial, optional
        The slips already tried (:func:`try_slips`), for a rig that looks at
        the outcome before judging (e.g. to name a second slip that explains
        the data as well); ``slips``, ``factor`` and ``threshold`` are then
        not used and nothing is evaluated again.

    Returns
    -------
    Diagnostic or None
        ``None`` when plausible; an ``implausible_input`` warning when ``accept``.

    Raises
    ------
    ImplausibleInputError
        When implausible and not ``accept``; ``.slip`` names the slip or is None.
    """
    if plausible:
        return None
    if trial is None:
        trial = try_slips(slips, residual, unit=unit, factor=factor, threshold=threshold)
    u = f" {unit}" if unit else ""
    if trial.best is not None:
        msg = (f"{trial.best.describe}: {trial.best.fix} the {what} drops from "
               f"{_fmt(residual)} to {_fmt(trial.best_value)}{u}")
    else:
        names = ", ".join(name for name, _ in trial.tried)
        msg = f"{reason}" + (f"; none of the likely slips ({names}) explains it" if names else "")
    if accept:
        return Diagnostic(IMPLAUSIBLE_CODE, f"accepted with --accept-implausible: {msg}",
                          params=(trial.best.name,) if trial.best is not None else ())
    hint = "fix the input" + (" as named" if trial.best is not None else "") + \
        ", or pass --accept-implausible to go on with it as given"
    raise ImplausibleInputError(f"{msg} ({hint})", source=source,
                                slip=trial.best.name if trial.best is not None else None)


def length_slips(field: str, declared: str | None, apply: Callable[[float], float], *,
                 undeclared_factors: Sequence[float] = ()) -> list[Slip]:
    """Slips of a length field read in ``declared``: the value was in another unit of :data:`LENGTH_UNITS`.

    ``apply(k)`` returns the figure with the field multiplied by ``k``. Slip names use the last dotted
    part of ``field`` (``"board.square"`` -> ``"square_mm_as_m"``). When ``declared`` is not one of
    :data:`LENGTH_UNITS` (e.g. SI values passed to the library), one slip per factor of
    ``undeclared_factors`` (none by default).
    """
    key = field.split(".")[-1]
    if declared not in LENGTH_UNITS:
        return [Slip(f"{key}_x{k:g}", f"`{field}` looks {max(k, 1 / k):g}x too {'small' if k > 1 else 'large'} "
                                     f"(a unit slip)", f"with x{k:g}" if k > 1 else f"with /{1 / k:g}",
                     lambda k=k: apply(k))
                for k in undeclared_factors]
    out = []
    for true in LENGTH_UNITS:
        if true == declared:
            continue
        k = LENGTH_UNITS[true] / LENGTH_UNITS[declared]
        fix = f"with x{k:g}" if k >= 1 else f"with /{1 / k:g}"
        out.append(Slip(f"{key}_{true}_as_{declared}", f"`{field}` looks like {true}, not {declared}", fix,
                        lambda k=k: apply(k)))
    return out
