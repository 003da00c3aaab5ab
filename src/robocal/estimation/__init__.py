"""Least squares with named parameters, uncertainty and diagnostics.

One layer over :func:`scipy.optimize.least_squares` that every rig uses:

- :class:`Problem`: named parameter blocks (free / fixed / tied elements,
  bounds, units), one or more residual terms with optional analytic Jacobians,
  noise weights and block sparsity;
- :func:`solve` -> :class:`LSQResult`: estimate, covariance, per-parameter std
  (``None`` for what the data do not determine), correlations, residuals per
  observation, cost history, and :class:`~robocal.diagnostics.Diagnostic`
  warnings (``rank_deficient``, ``weakly_determined``, ``outliers``,
  ``not_converged``);
- :func:`analyze_jacobian`: the same uncertainty analysis for any Jacobian
  (e.g. to plan measurement poses before taking them);
- :func:`monte_carlo`, :func:`check_coverage`, :func:`fisher_bound`: accuracy
  over simulated trials, compared with the Cramér–Rao bound and with the
  reported standard deviations.
"""

from robocal.estimation._evaluate import *  # noqa: F401,F403
from robocal.estimation._identifiability import *  # noqa: F401,F403
from robocal.estimation._problem import *  # noqa: F401,F403
from robocal.estimation._result import *  # noqa: F401,F403
from robocal.estimation._solve import *  # noqa: F401,F403
from robocal.estimation._montecarlo import *  # noqa: F401,F403
from robocal.estimation._truth import *  # noqa: F401,F403
from robocal.estimation import _evaluate, _identifiability, _montecarlo, _problem, _result, _solve, _truth

__all__ = [
    *_problem.__all__,
    *_solve.__all__,
    *_result.__all__,
    *_identifiability.__all__,
    *_montecarlo.__all__,
    *_evaluate.__all__,
    *_truth.__all__,
]
