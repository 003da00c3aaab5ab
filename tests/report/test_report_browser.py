"""Report pages as a reader sees them: headless Chromium in a 1400 px window (tests/support/browser.py).

Every image loads, nothing reaches beyond the window or the page's column,
no figure is cut off or shrunk past reading. Skipped, with the reason, where
no Chromium is installed (``.ci/run`` installs Debian's ``chromium`` when it
can). One page takes about 1-2 s, almost all of it Chromium starting.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from browser import SKIP_REASON, check_page, chromium_executable

from robocal.cli._rig import discover_rigs, registered_rig_names
from robocal.cli.main import main
from robocal.report import Report, new_figure

pytestmark = pytest.mark.skipif(chromium_executable() is None, reason=SKIP_REASON)


def _wide_report() -> Report:
    """What overflowed before (issue 20): a 1500 px figure, a 30-column table, long unbroken text."""
    rep = Report("wide " + "very_long_report_title_without_spaces_" * 6)
    sec = rep.section("Cost curves and residuals of a section whose title is long enough to wrap in the navigation")
    fig, axes = new_figure(1, 3, size=(15.0, 4.0))  # 1500 x 400 px at the default dpi 100
    for ax in axes:
        ax.plot(np.arange(30), np.exp(-np.arange(30) / 3.0))
    sec.figure(fig, "cost per iteration " + "x" * 300)
    sec.table([{f"parameter column {i}": 1.234567 * i for i in range(30)}], caption="a table wider than the page")
    sec.preformatted("solver log " + "=" * 400)
    sec.text("a path written without spaces: " + "/very/long/folder/name" * 20)
    sec.parameters({"T_w_c.rotation": np.eye(3), "T_w_c.rotvec": np.zeros(3), "T_w_c.translation": np.ones(3)},
                   {"T_w_c.rotvec": [1e-3] * 3, "T_w_c.translation": [1e-3] * 3}, {"T_w_c.translation": "m"})
    sec.image(np.zeros((480, 1280), np.uint8), "a camera frame wider than the column")
    for i in range(12):  # enough sections for the navigation to take several lines
        rep.section(f"section {i}").text("text")
    return rep


def test_wide_figures_tables_and_text_fit_a_1400px_window(tmp_path):
    assert check_page(_wide_report().write(tmp_path / "report.html"), width=1400) == []


def test_the_check_flags_a_page_without_the_report_css(tmp_path):
    # the same page without the rules that fit it to the column: the check is what
    # keeps them (it can fail on exactly what issue 20 saw)
    page = _wide_report().to_html()
    page = re.sub(r"<style>.*?</style>", "<style>body{max-width:1100px;margin:2em auto}</style>", page, flags=re.S)
    (tmp_path / "bare.html").write_text(page)
    found = check_page(tmp_path / "bare.html")
    text = "\n".join(found)
    assert "page:" in text and "horizontal scroll bar" in text, text
    assert re.search(r'img in section "Cost curves.*figure "cost per iteration x+.*beyond the 1\d{3} px window', text), text
    assert re.search(r'table in section "Cost curves.*table "a table wider than the page".*beyond', text), text
    assert re.search(r'p in section "Cost curves.*text "a path written without spaces', text), text


def test_the_check_flags_a_broken_image_and_a_fixed_wide_box(tmp_path):
    (tmp_path / "broken.html").write_text(
        "<!DOCTYPE html><html><head><title>t</title></head><body>"
        "<section><h2>Figures</h2><figure><img src='missing.png' alt='m'><figcaption>cost curve</figcaption></figure>"
        "<div style='width:3000px'>wide</div>"
        "<figure><img src='ok.png' style='width:1200px' alt='o'><figcaption>error map</figcaption></figure>"
        "<figure><img src='ok.png' style='width:200px' alt='s'><figcaption>spot path</figcaption></figure>"
        "</section></body></html>")
    # a 1000 x 100 px PNG next to the page: it loads (relative to the original's folder)
    import cv2
    cv2.imwrite(str(tmp_path / "ok.png"), np.full((100, 1000), 255, np.uint8))
    found = check_page(tmp_path / "broken.html", width=1000)
    text = "\n".join(found)
    assert 'img in section "Figures", figure "cost curve": image did not load (src missing.png)' in found, text
    assert 'div in section "Figures": right edge at 3008 px, beyond the 1000 px window' in found, text
    assert re.search(r'img in section "Figures", figure "error map": right edge at 12\d\d px, beyond', text), text
    assert 'img in section "Figures", figure "spot path": drawn at 20 % of its 1000 px width' in text, text
    assert "page: 3008 px wide" in text


def test_a_page_the_check_could_not_measure_is_an_error_not_a_pass(tmp_path):
    # the page leaves before 'load': no findings were written, which must not read as "no problems"
    (tmp_path / "away.html").write_text("<!DOCTYPE html><html><head><script>location.replace('about:blank')</script>"
                                        "</head><body>x</body></html>")
    with pytest.raises(RuntimeError, match="did not run the page check on away.html"):
        check_page(tmp_path / "away.html")


def _cli(argv, capsys) -> int:
    code = main([str(a) for a in argv])
    capsys.readouterr()
    return code


def test_demo_report_reads_in_a_browser(tmp_path, capsys):
    # the projector's demo is the cheapest (~6 s); its page holds the summary table,
    # the 1500 px cost-curve figure and the error maps of issue 20
    assert _cli(["demo", "--rigs", "projector", "--out", tmp_path / "demo", "--no-progress"], capsys) == 0
    assert check_page(tmp_path / "demo" / "report.html") == []


# every rig's calibrate report is checked in the round trip of tests/test_rig_contract.py


def test_projector_timed_path_report_reads_in_a_browser(tmp_path, capsys):
    # issue 20's collapsed plot: the timed spot path over the floor (its example has an
    # infeasible stretch, which is exit 1 by the command's documented contract; the page
    # is written either way)
    example = Path(__file__).parents[2] / "examples" / "projector" / "path_timed.yaml"
    if "projector" not in registered_rig_names() or not example.is_file():
        pytest.skip("no projector rig or no examples/projector/path_timed.yaml")
    assert _cli(["projector", "path", example, "--out", tmp_path / "path"], capsys) in (0, 1)
    assert check_page(tmp_path / "path" / "report.html") == []
