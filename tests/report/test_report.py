import re

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.report import Report, new_figure


def test_report_is_self_contained(tmp_path):
    rep = Report("t", subtitle="s")
    sec = rep.section("Numbers")
    sec.table([{"a": 1, "b": 2.5, "c": None}])
    sec.parameters({"x": 1.0, "v": np.array([1.0, 2.0])}, {"x": 0.1, "v": [0.2, None]}, {"x": "m"})
    sec.diagnostics([Diagnostic("rank_deficient", "p_y undetermined", params=("p_y",))])
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    sec.figure(fig, "a line")
    sec.image(np.zeros((8, 8), np.uint8), "black")
    path = rep.write(tmp_path / "report.html")
    html = path.read_text()
    assert html.count("data:image/png;base64,") == 2
    assert "p_y undetermined" in html and "parameters: p_y" in html
    assert "http://" not in html and "https://" not in html  # opens offline
    assert "<td>—</td>" in html  # None shown as a dash, never 'None' or 'nan'
    assert "nan" not in html.lower().replace("nav", "")


def test_text_is_escaped(tmp_path):
    rep = Report("<script>")
    rep.section("x").text("<b>&")
    html = rep.to_html()
    assert "<script>" not in html.split("<style>")[0]
    assert "&lt;b&gt;&amp;" in html


def test_wide_figures_and_tables_fit_the_column(tmp_path):
    # A 1500 px cost-curve figure used to overflow the 1100 px column (issue 20):
    # images scale down to the column and wide tables scroll inside it. The rules
    # are checked here where no browser is installed; their effect on the page,
    # in Chromium, by test_report_browser.py.
    r = Report("wide")
    fig, _ = new_figure(size=(15.0, 3.0))
    r.section("s").figure(fig, "wide figure").table([{f"c{i}": i for i in range(30)}], [f"c{i}" for i in range(30)])
    css = r.write(tmp_path / "r.html").read_text().split("<style>")[1].split("</style>")[0]
    assert re.search(r"figure img\{[^}]*max-width:100%;height:auto", css)
    assert re.search(r"table\{[^}]*display:block;max-width:100%;overflow-x:auto", css)


def test_table_cells_align_words_left_and_keep_vectors_on_one_line():
    rep = Report("t")
    rep.section("s").table([{"name": "view000", "value": 1.5, "text": "1.3 mm", "why": "both poses coincide",
                             "t [mm]": "[561.6, 21.2, 259.7]", "v": np.array([1.0, 2.0])}])
    page = rep.to_html()
    assert '<td class="t">both poses coincide</td>' in page  # prose reads from the left
    assert "<td>1.5</td>" in page and "<td>1.3 mm</td>" in page  # numbers (also formatted ones) stay right
    assert '<td class="v">[561.6, 21.2, 259.7]</td>' in page and '<td class="v">[1., 2.]</td>' in page
    assert "td.t{text-align:left}" in page.replace("td:first-child,th:first-child,", "")
