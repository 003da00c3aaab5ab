"""The projector's figures: one cost axis per method; every report figure fits a ~1000 px column."""

import numpy as np

from robocal.rigs.projector.calibrate import calibrate
from robocal.rigs.projector.simulate import simulate_calibration

SIGMA = 0.005  # world measurement noise (m)


def test_cost_curves_get_one_axis_per_method_so_the_seed_curve_is_visible():
    from robocal.report import new_figure
    from robocal.rigs.projector.plots import iterative_methods, plot_cost_curves

    sc = simulate_calibration(np.random.default_rng(7), n_points=8, sigma=SIGMA)
    run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=SIGMA)
    assert iterative_methods(run.estimates) == ["seed", "nonlinear"]
    fig, ax = new_figure(1, 2)
    plot_cost_curves(run.estimates, ax)
    for a, name in zip(ax, ("seed", "nonlinear")):
        h = run.estimates[name].cost_history
        assert len(a.get_lines()) == 1
        lo, hi = a.get_ylim()  # each axis spans its own curve, not 1e-6 .. 1e3 for both
        assert lo >= 0.5 * h.min() and hi <= 2 * h.max()
    assert run.estimates["seed"].cost_history.max() < 1e-3 < run.estimates["nonlinear"].cost_history.max()


def _images(html: str) -> list[tuple[int, int]]:
    """(width, height) in px of every PNG embedded in a report."""
    import base64
    import re
    import struct

    sizes = []
    for b64 in re.findall(r'src="data:image/png;base64,([^"]+)"', html):
        head = base64.b64decode(b64[:64])
        sizes.append(struct.unpack(">II", head[16:24]))  # the IHDR chunk: width, height
    return sizes


def test_every_report_figure_fits_a_1000_px_column_and_the_path_plot_is_not_a_strip(tmp_path):
    from pathlib import Path

    from robocal.cli.main import main

    ex = Path(__file__).resolve().parents[3] / "examples" / "projector"
    assert main(["projector", "calibrate", str(ex / "room_A.yaml"), "--out", str(tmp_path / "cal")]) == 0
    assert main(["projector", "evaluate", str(ex / "room_A.yaml"), "--out", str(tmp_path / "ev")]) == 0
    assert main(["projector", "path", str(ex / "path_timed.yaml"), "--out", str(tmp_path / "path")]) == 1
    for d in ("cal", "ev", "path"):
        sizes = _images((tmp_path / d / "report.html").read_text())
        assert sizes and all(w <= 1000 for w, _ in sizes), (d, sizes)  # it was 1500 (cost) and 1280 (error map)
    # the timed path is nearly straight: its plot was a 15 px strip (aspect 'equal' shrank the axes box)
    w, h = _images((tmp_path / "path" / "report.html").read_text())[0]
    assert h >= 0.5 * w, (w, h)


def test_the_parameter_table_gives_every_row_a_unit(tmp_path):
    import re
    from pathlib import Path

    from robocal.cli.main import main

    ex = Path(__file__).resolve().parents[3] / "examples" / "projector"
    assert main(["projector", "calibrate", str(ex / "room_A.yaml"), "--out", str(tmp_path)]) == 0
    html = (tmp_path / "report.html").read_text()
    table = next(t for t in re.findall(r"<table>.*?</table>", html) if "<th>unit</th>" in t)
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in re.findall(r"<tr>(.*?)</tr>", table)]
    rows = [(c[0], c[3]) for c in cells if c]  # columns: parameter, value, std, unit
    assert len(rows) >= 10 and all(unit.strip() for _, unit in rows), rows
    names = [n for n, _ in rows]
    assert "T_0_W translation x" in names and "T_0_W rotation vector z" in names and "yaw" in names
