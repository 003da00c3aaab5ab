"""Named warnings attached to results (not Python warnings).

A :class:`Diagnostic` is data: a stable ``code`` that scripts can test for,
a human message, and the parameters or observation indices involved. They
travel inside result objects and result files, so a user reading a result a
month later still sees that, say, ``p_y`` was not identifiable.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

__all__ = ["Diagnostic", "CODES"]

#: The codes in use, with what each means. A new code is added here (tests/test_architecture.py checks that
#: every code the package writes is listed, so a reader of result files finds each one documented).
CODES = {
    "rank_deficient": "the data do not determine some parameters (named in `params`)",
    "weakly_determined": "some parameters are determined only weakly (large standard deviation or condition number)",
    "outliers": "residuals beyond the outlier threshold (robocal.estimation.outlier_sigma: Bonferroni over the "
                "observations, at least 3 sigma; observation indices in `indices`)",
    "degenerate_geometry": "the measurement geometry is close to degenerate",
    "inconsistent_data": "measurements disagree beyond their noise",
    "not_converged": "the solver stopped before convergence",
    "near_singularity": "configuration close to a kinematic singularity",
    "low_quality": "measurements of low quality (indices in `indices`): excluded, or kept at a lower accuracy as the message says",
    "dropped": "inputs were dropped (indices in `indices`)",
    "views_rejected": "images not used (blurred, duplicate, no target found, another size; each named with its reason)",
    "dropped_views": "images without a usable target pose, left out of the calibration (named by index)",
    "ambiguous_views": "views whose planar target pose is ambiguous (the two PnP solutions fit alike): down-weighted",
    "badly_conditioned_views": "views whose target pose is poorly determined (std far above the median view's): "
                               "down-weighted",
    "repeated_stamps": "messages repeating an earlier header stamp: dropped (named by index)",
    "parameter_held": "a parameter the data could not move was held at its nominal value and the fit redone",
    "clock_mismatch": "two streams look like two clocks (receive minus header time differs between them): the "
                      "header stamps pair them only if those clocks agree",
    "tf_gaps": "samples farther from the nearest tf sample than a few tf periods: dropped (named by index)",
    "frames_outside_tf": "samples stamped outside the span of the tf stream: dropped (named by index)",
    "implausible_input": "the answer is physically implausible and was kept only because of --accept-implausible "
                         "(the likely slip, when one explained it, in `params`)",
}


@dataclass(frozen=True)
class Diagnostic:
    """One named warning.

    Attributes
    ----------
    code : str
        Stable identifier, see :data:`CODES`.
    message : str
        One-line explanation for a person.
    params : tuple of str
        Parameter names involved (for rank deficiency, correlations, ...).
    indices : tuple of int
        Observation indices involved (for outliers, dropped inputs, ...).
    """

    code: str
    message: str
    params: tuple[str, ...] = field(default_factory=tuple)
    indices: tuple[int, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["params"] = list(self.params)
        d["indices"] = [int(i) for i in self.indices]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Diagnostic":
        return cls(
            code=str(d["code"]),
            message=str(d["message"]),
            params=tuple(d.get("params", ())),
            indices=tuple(int(i) for i in d.get("indices", ())),
        )

    def __str__(self) -> str:
        return f"[{self.code}] {self.message}"
