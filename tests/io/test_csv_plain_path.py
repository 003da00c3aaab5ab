"""``load_csv``'s plain path (every line after the header a data row, read by NumPy without Python per line)
gives what the careful path gives: the same columns, the same record lines, the same errors naming the
same line, whatever comments, blank lines and bad cells a file has."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal.errors import FileFormatError
from robocal.io import load_csv, load_poses
from robocal.io import _load


def _careful(text):
    """The same file through the careful path only (the plain path switched off)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_load, "_plain_table", lambda lines: None)
        return _outcome(text)


def _outcome(text):
    try:
        t = load_csv("t.csv", text=text)
    except FileFormatError as exc:
        return ("error", str(exc))
    return ("table", {k: v.tolist() for k, v in t.columns.items()}, t.lines.tolist(), dict(t.units))


_noise = st.sampled_from(["", "   ", "# a comment", "  # indented comment"])


@st.composite
def _files(draw):
    n = draw(st.integers(0, 6))
    rows = [[draw(st.floats(-1e3, 1e3, allow_nan=False)) for _ in range(3)] for _ in range(n)]
    lines = [f"{a!r},{b!r},{c!r}" for a, b, c in rows]
    if rows and draw(st.booleans()):                 # a bad cell somewhere
        i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, 2))
        cells = lines[i].split(",")
        cells[j] = draw(st.sampled_from(["nan", "inf", "abc", ""]))
        lines[i] = ",".join(cells)
    for _ in range(draw(st.integers(0, 3))):         # comments and blank lines anywhere after the header
        lines.insert(draw(st.integers(0, len(lines))), draw(_noise))
    lead = draw(st.lists(_noise, max_size=2))
    tail = draw(st.sampled_from(["", "\n", "\n\n", "\n  \n"]))
    return "\n".join([*lead, "t [s], x [m], y [mm]", *lines]) + tail


@settings(max_examples=150, deadline=None)
@given(_files())
def test_the_plain_path_reads_what_the_careful_path_reads(text):
    assert _outcome(text) == _careful(text)


def test_a_log_with_a_comment_after_the_header_names_the_right_line():
    text = "# log\nt [s], x [m]\n0, 1\n# paused\n1, nan\n"
    with pytest.raises(FileFormatError, match=r"row 2 \(line 5\), column 'x': value is nan"):
        load_csv("t.csv", text=text)
    t = load_csv("t.csv", text="# log\nt [s], x [m]\n0, 1\n1, 2\n\n")
    assert t.lines.tolist() == [3, 4] and t.column("x").tolist() == [1.0, 2.0]


def test_a_pose_table_with_percent_comments(tmp_path):
    """``%`` lines are comments in a pose table (as ``#``), with units in its header or without."""
    f = tmp_path / "poses.csv"
    f.write_text("% recorded 2026-11-27\nt [s], x [m], y [m], theta [rad]\n0, 0, 0, 0\n% a pause\n1, 1, 0, 0.5\n")
    p = load_poses(f)
    assert p.t.tolist() == [0.0, 1.0] and np.allclose(p.xy_theta[1], [1, 0, 0.5])
    f.write_text("% no units\nt, x, y, theta\n0, 0, 0, 0\n% a pause\n1, 1, nan, 0.5\n")
    with pytest.raises(FileFormatError, match=r"line 5\), column 'y'"):
        load_poses(f)
