"""The report's shared estimation sections (robocal.report: plot_cost, plot_residual_histogram, solver_section)."""

import numpy as np

from robocal.estimation import Problem, solve, truth_check
from robocal.report import Report, plot_cost, plot_residual_histogram, solver_section, truth_section


def _fit():
    rng = np.random.default_rng(0)
    x = np.linspace(0, 1, 40)
    y = 2.0 * x + 1.0 + rng.normal(scale=0.01, size=x.size)
    p = Problem()
    p.add_block("ab", [0.0, 0.0])
    p.add_residuals(lambda q: q["ab"][0] * x + q["ab"][1] - y, name="line")
    return solve(p)


def test_solver_section_shows_the_record_and_its_cost_curve():
    lsq = _fit()
    rep = Report("t")
    solver_section(rep.section("Solver"), lsq.to_dict())
    html = rep.to_html()
    assert "accepted steps" in html and "condition number" in html and "data:image/png" in html


def test_solver_section_with_passes_draws_them_all():
    lsq = _fit()
    rec = lsq.to_dict()
    rep = Report("t")
    solver_section(rep.section("Solver"), {k: v for k, v in rec.items() if k != "cost_history"},
                   passes={"pass 1": [5.0, 2.0], "pass 2": rec["cost_history"]})
    html = rep.to_html()
    assert "each solver pass" in html and "<td>5</td>" in html  # initial cost from the first pass


def test_solver_section_without_record_says_so():
    rep = Report("t")
    solver_section(rep.section("Solver"), {})
    assert "closed-form" in rep.to_html()


def test_plots_accept_passes_and_zero_cost():
    ax = plot_cost({"pass 1": [10.0, 1.0], "pass 2": [1.0, 0.0]})
    assert len(ax.lines) == 2 and ax.lines[1].get_xdata()[0] == 1  # pass 2 continues where pass 1 ended
    ax = plot_residual_histogram(np.r_[np.random.default_rng(1).normal(size=500), np.nan], sigma=1.0, unit="px")
    assert ax.get_xlabel() == "residual [px]" and len(ax.lines) == 1


def test_truth_section_verdict():
    rep = Report("t")
    truth_section(rep.section("Truth"), truth_check([0.0, 10.0], [1.0, 1.0], names=["a", "b"]).to_dict())
    assert "NOT consistent" in rep.to_html() and 'class="fail"' in rep.to_html()
