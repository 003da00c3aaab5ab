"""Self-contained HTML reports: one file per run, plots embedded as PNG data URIs.

Plot functions elsewhere are pure (take ``ax=None``, return the axes); a
:class:`Report` collects their figures, tables, text and diagnostics and
writes one HTML file that opens offline.

Example
-------
>>> rep = Report("projector calibration")
>>> sec = rep.section("Residuals")
>>> sec.table([{"point": 0, "error [mm]": 1.2}])
>>> rep.write("out/report.html")  # doctest: +SKIP
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.io import atomic_write_text

__all__ = ["Report", "Section", "figure_to_data_uri", "format_value", "new_figure"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em auto;max-width:1100px;color:#222;padding:0 1em;overflow-wrap:break-word}
h1{border-bottom:2px solid #246;padding-bottom:.2em}h2{color:#246;margin-top:1.6em}h3{color:#357}
nav ul.cols{columns:2 22em;column-gap:2em}nav li{break-inside:avoid}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em;display:block;max-width:100%;overflow-x:auto}
caption{caption-side:top;text-align:left;color:#555;padding:.2em 0}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right;font-variant-numeric:tabular-nums}th{background:#eef2f7}
td:first-child,th:first-child,td.t{text-align:left}td.v{white-space:nowrap}
.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em;margin:.3em 0}
.ok{background:#eaf7ea;border-left:4px solid #3a3;padding:.4em .8em;margin:.3em 0}
.fail{background:#fdeaea;border-left:4px solid #c33;padding:.4em .8em;margin:.3em 0}
figure{margin:1em 0}figcaption{color:#555;font-size:.9em;max-width:100%}
figure img{display:block;max-width:100%;height:auto}
pre{background:#f6f6f6;padding:.6em;overflow-x:auto;font-size:.85em;overflow-wrap:normal}
.meta{color:#666;font-size:.85em}
"""


def new_figure(nrows: int = 1, ncols: int = 1, *, size=(6.4, 4.0), **kw):
    """A matplotlib ``Figure`` not attached to pyplot (no display, no backend switch).

    Rendering goes through :func:`figure_to_data_uri` (``savefig`` to memory),
    so the user's own backend (a notebook's, say) is left as it was.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    axes = fig.subplots(nrows, ncols, **kw)
    return fig, axes


def figure_to_data_uri(fig, *, dpi: int = 100) -> str:
    """Render a matplotlib figure to a ``data:image/png;base64,...`` URI."""
    import warnings

    buf = io.BytesIO()
    with warnings.catch_warnings():
        # matplotlib says so when placing a loc="best" legend took over a second of wall time:
        # a busy machine, not a fault in the figure (it failed a loaded CI's no-warning check)
        warnings.filterwarnings("ignore", message='Creating legend with loc="best" can be slow', category=UserWarning)
        fig.savefig(buf, format="png", dpi=dpi)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def format_value(v, digits: int = 6) -> str:
    """Compact text for a table cell (None/NaN -> an em dash)."""
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(float(v)):
            return "—"
        return f"{float(v):.{digits}g}"
    if isinstance(v, np.ndarray):
        return np.array2string(v, precision=digits, separator=", ", max_line_width=60)
    return str(v)


#: Text a rig formatted itself that still reads as a number ("1.3 mm", "-0.2") or a vector ("[1.5, -2]").
_NUMBER_TEXT = re.compile(r"\s*[-+\u2212]?\.?\d")
_VECTOR_TEXT = re.compile(r"\s*\[[-+\u2212\d.,e\s]*\]\s*")


def _kind(v) -> str:
    """How a cell is set: "v" a vector (one line), "t" words (left-aligned), "" a number (right-aligned)."""
    if isinstance(v, (list, tuple, np.ndarray)) or (isinstance(v, str) and _VECTOR_TEXT.fullmatch(v)):
        return "v"
    if isinstance(v, str) and len(v.strip()) > 1 and not _NUMBER_TEXT.match(v):
        return "t"
    return ""


def _cell(v, digits: int) -> str:
    kind = _kind(v)
    text = html.escape(format_value(v, digits))
    return f'<td class="{kind}">{text}</td>' if kind else f"<td>{text}</td>"


@dataclass
class Section:
    """A titled part of a report; items render in the order they were added."""

    title: str
    items: list[str] = field(default_factory=list)

    def text(self, text: str, *, cls: str | None = None) -> "Section":
        body = html.escape(text).replace("\n", "<br>")
        self.items.append(f'<p class="{cls}">{body}</p>' if cls else f"<p>{body}</p>")
        return self

    def status(self, ok: bool, text: str) -> "Section":
        return self.text(text, cls="ok" if ok else "fail")

    def preformatted(self, text: str) -> "Section":
        self.items.append(f"<pre>{html.escape(text)}</pre>")
        return self

    def table(self, rows, columns=None, *, caption: str | None = None, digits: int = 6) -> "Section":
        """A table from a list of dicts (columns from the first row unless given)."""
        rows = list(rows)
        if not rows:
            return self.text("(no rows)")
        columns = list(columns or rows[0].keys())
        head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
        body = "".join(
            "<tr>" + "".join(_cell(r.get(c), digits) for c in columns) + "</tr>" for r in rows
        )
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self.items.append(f"<table>{cap}<tr>{head}</tr>{body}</table>")
        return self

    def figure(self, fig, caption: str = "", *, dpi: int = 100) -> "Section":
        uri = figure_to_data_uri(fig, dpi=dpi)
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.items.append(f'<figure><img alt="{html.escape(caption)}" src="{uri}">{cap}</figure>')
        return self

    def image(self, image: np.ndarray, caption: str = "") -> "Section":
        """Embed an image array (grey or RGB uint8) as PNG."""
        import cv2

        arr = np.asarray(image)
        if arr.ndim == 3:
            arr = arr[..., ::-1]  # RGB -> BGR for OpenCV's encoder
        ok, png = cv2.imencode(".png", arr)
        uri = "data:image/png;base64," + base64.b64encode(png.tobytes()).decode("ascii")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.items.append(f'<figure><img alt="{html.escape(caption)}" src="{uri}">{cap}</figure>')
        return self

    def diagnostics(self, warnings) -> "Section":
        warnings = list(warnings)
        if not warnings:
            self.items.append('<p class="ok">No warnings.</p>')
        for w in warnings:
            if isinstance(w, Diagnostic):
                extra = ""
                if w.params:
                    extra += " — parameters: " + ", ".join(w.params)
                if w.indices:
                    shown = ", ".join(str(i) for i in w.indices[:30])
                    extra += f" — indices: {shown}" + (" …" if len(w.indices) > 30 else "")
                txt = f"[{w.code}] {w.message}{extra}"
            else:
                txt = str(w)
            self.items.append(f'<p class="warn">{html.escape(txt)}</p>')
        return self

    def parameters(self, estimate: dict, std: dict | None = None, units: dict | None = None) -> "Section":
        """Parameter table: name, value, standard deviation, unit (flattening arrays).

        A pose written in the result vocabulary (``X.rotation``, ``X.rotvec``,
        ``X.translation``; ``robocal.io.CalibrationResult.add_pose``) is shown
        as its translation in mm and rotation vector in deg, each with its std,
        not as nine matrix entries of unit "1".
        """
        std = std or {}
        units = units or {}
        poses = {k[: -len(".rotation")] for k in estimate
                 if k.endswith(".rotation") and np.shape(estimate[k]) == (3, 3) and f"{k[:-9]}.translation" in estimate}
        rows = []
        for name, val in estimate.items():
            base, _, part = name.rpartition(".")
            if base in poses and part in ("rotation", "rotvec", "translation"):
                if part == "rotation":
                    rows.extend(_pose_rows(base, estimate, std, units))
                continue
            s = std.get(name)
            arr = np.asarray(val, dtype=object)
            if arr.ndim == 0 or arr.size == 1:
                rows.append({"parameter": name, "value": val, "std": s, "unit": units.get(name, "")})
            else:
                flat_s = np.asarray(s, dtype=object).reshape(-1) if s is not None else [None] * arr.size
                for i, (v, si) in enumerate(zip(arr.reshape(-1), flat_s)):
                    rows.append({"parameter": f"{name}[{i}]", "value": v, "std": si, "unit": units.get(name, "")})
        return self.table(rows, ["parameter", "value", "std", "unit"])


#: How a pose's parts are shown: SI in the file, mm and deg on the page.
_DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", 180.0 / math.pi)}


def _scaled(v, unit: str):
    shown, k = _DISPLAY.get(unit, (unit, 1.0))
    if v is None:
        return None, shown
    return [None if x is None else float(x) * k for x in np.asarray(v, dtype=object).reshape(-1)], shown


def _pose_rows(name: str, estimate: dict, std: dict, units: dict) -> list[dict]:
    """Rows of one pose: translation x, y, z and rotation vector x, y, z with std, in mm and deg."""
    rotvec = estimate.get(f"{name}.rotvec")
    if rotvec is None:  # a robocal.result/1 file wrote the matrix only
        from scipy.spatial.transform import Rotation

        rotvec = Rotation.from_matrix(np.asarray(estimate[f"{name}.rotation"], dtype=float)).as_rotvec()
    rows = []
    for part, value, unit in (("translation", estimate[f"{name}.translation"], units.get(f"{name}.translation", "m")),
                              ("rotvec", rotvec, "rad")):
        vals, shown = _scaled(value, unit)
        stds, _ = _scaled(std.get(f"{name}.{part}"), unit)
        for i, axis in enumerate("xyz"):
            rows.append({"parameter": f"{name} {'rotation vector' if part == 'rotvec' else 'translation'} {axis}",
                         "value": vals[i], "std": None if stds is None else stds[i], "unit": shown})
    return rows


class Report:
    """A self-contained HTML report made of :class:`Section` objects."""

    def __init__(self, title: str, *, subtitle: str | None = None):
        self.title = title
        self.subtitle = subtitle
        self.sections: list[Section] = []

    def section(self, title: str) -> Section:
        sec = Section(title)
        self.sections.append(sec)
        return sec

    def extend(self, sections, *, prefix: str | None = None) -> None:
        for s in sections:
            self.sections.append(Section(f"{prefix}: {s.title}" if prefix else s.title, list(s.items)))

    def to_html(self) -> str:
        import datetime as _dt

        import robocal

        toc = "".join(f'<li><a href="#s{i}">{html.escape(s.title)}</a></li>' for i, s in enumerate(self.sections))
        body = "".join(
            f'<section id="s{i}"><h2>{html.escape(s.title)}</h2>{"".join(s.items)}</section>'
            for i, s in enumerate(self.sections)
        )
        sub = f"<p>{html.escape(self.subtitle)}</p>" if self.subtitle else ""
        # a long table of contents in two columns, so the first section is not a screen down
        nav_cls = ' class="cols"' if len(self.sections) > 8 else ""
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        return (
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1>{sub}"
            f"<p class='meta'>robocal {html.escape(robocal.__version__)} — {stamp}</p>"
            f"<nav><ul{nav_cls}>{toc}</ul></nav>{body}</body></html>\n"
        )

    def write(self, path) -> Path:
        """Write the report atomically; returns the path."""
        return atomic_write_text(Path(path), self.to_html())
