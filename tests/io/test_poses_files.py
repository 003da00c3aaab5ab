"""Pose lists (robocal.io.load_poses / write_poses / interpolate_poses): formats, round trip, bad files."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from robocal.errors import FileFormatError, InputError
from robocal.io import interpolate_poses, load_poses, write_poses


def _poses(n, rng):
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=rng.integers(2**31)).as_matrix()
    T[:, :3, 3] = rng.normal(size=(n, 3))
    return T


def test_csv_round_trip_keeps_poses_to_the_written_digits(tmp_path):
    rng = np.random.default_rng(1)
    T = _poses(5, rng)
    t = np.arange(5) * 0.1
    write_poses(tmp_path / "p.csv", T, t)
    got = load_poses(tmp_path / "p.csv")
    # 9 decimals written: translation to 5e-10 m, quaternion to 5e-10 -> rotation ~1e-9
    np.testing.assert_allclose(got.T, T, atol=5e-9)
    np.testing.assert_allclose(got.t, t, atol=1e-6)
    assert not got.planar and len(got) == 5


def test_yaml_in_millimetres_with_matrix_or_quaternion(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("units: {length: mm}\nposes:\n  - {p: [1000, 0, 0], q: [0, 0, 0, 1]}\n"
                 "  - {p: [0, 20, 0], R: [[1, 0, 0], [0, 0, -1], [0, 1, 0]]}\n")
    got = load_poses(f)
    np.testing.assert_allclose(got.T[0, :3, 3], [1.0, 0, 0])
    np.testing.assert_allclose(got.T[1, :3, :3], Rotation.from_euler("x", 90, degrees=True).as_matrix(), atol=1e-12)
    assert got.t is None


def test_planar_csv_gives_rotations_about_z(tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("t [s], x [mm], y [mm], theta [deg]\n0, 0, 0, 0\n1, 100, 0, 90\n")
    got = load_poses(f)
    assert got.planar
    np.testing.assert_allclose(got.xy_theta[1], [0.1, 0.0, np.pi / 2], atol=1e-12)
    f.write_text("t [s], x [m], y [m], theta [rad]\n0, 0, 0, 0\n1, 0, 0, 7.0\n")
    assert load_poses(f).xy_theta[1, 2] == 7.0  # a heading past a full turn is kept as written


@pytest.mark.parametrize("text, match", [
    ("x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 2\n", "norm 2"),
    ("t [s], x [m], y [m], theta [rad]\n1, 0, 0, 0\n1, 0, 0, 0\n", "increase strictly"),
    ("a [m], b [m]\n0, 0\n", "needs the columns"),
])
def test_bad_files_name_the_problem(tmp_path, text, match):
    f = tmp_path / "p.csv"
    f.write_text(text)
    with pytest.raises(FileFormatError, match=match):
        load_poses(f)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 1.0))
def test_interpolation_hits_the_samples_and_stays_a_rotation(s):
    rng = np.random.default_rng(3)
    T = _poses(3, rng)
    t = np.array([0.0, 1.0, 2.0])
    Q = interpolate_poses(t, T, np.array([s, 1.0]))
    np.testing.assert_allclose(Q[1], T[1], atol=1e-12)
    R = Q[0, :3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    with pytest.raises(InputError, match="no extrapolation"):
        interpolate_poses(t, T, np.array([2.5]))


# ----------------------------------------------------------------------------- the forms users have (issue 13)
def _fmt_rows(rows):
    return "\n".join(" ".join(f"{v:.12g}" for v in r) for r in rows) + "\n"


@pytest.mark.parametrize("form", ["tum", "tum_header", "xyzq", "rotvec", "rotvec_header_deg", "4x4", "t4x4",
                                  "3x4", "filestorage", "filestorage_xml", "yaml_list", "yaml_T_mm"])
def test_every_form_reads_the_same_poses_and_says_which(tmp_path, form):
    import cv2

    rng = np.random.default_rng(11)
    T = _poses(4, rng)
    t = 10.0 + 0.1 * np.arange(4)
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    rv = Rotation.from_matrix(T[:, :3, :3]).as_rotvec()
    p = T[:, :3, 3]
    f, timed, says = tmp_path / "p.txt", False, None
    if form == "tum":
        f.write_text("# timestamp tx ty tz qx qy qz qw\n" + _fmt_rows(np.c_[t, p, q]))
        timed, says = True, "TUM t x y z qx qy qz qw"
    elif form == "tum_header":
        f.write_text("t x y z qx qy qz qw\n" + _fmt_rows(np.c_[t, p, q]))
        timed, says = True, "SI assumed"
    elif form == "xyzq":
        f = tmp_path / "p.csv"
        f.write_text(_fmt_rows(np.c_[p, q]).replace(" ", ","))
        says = "7 values a row"
    elif form == "rotvec":
        f.write_text(_fmt_rows(np.c_[p, rv]))
        says = "axis-angle"
    elif form == "rotvec_header_deg":
        f = tmp_path / "p.csv"
        f.write_text("t [s], x [mm], y [mm], z [mm], rx [deg], ry [deg], rz [deg]\n"
                     + _fmt_rows(np.c_[t, 1e3 * p, np.rad2deg(rv)]).replace(" ", ", "))
        timed, says = True, "x y z rx ry rz"
    elif form in ("4x4", "t4x4", "3x4"):
        M = T.reshape(4, 16) if form != "3x4" else T[:, :3].reshape(4, 12)
        f.write_text(_fmt_rows(np.c_[t, M] if form == "t4x4" else M))
        timed, says = form == "t4x4", "row-major"
    elif form.startswith("filestorage"):
        f = tmp_path / ("p.xml" if form.endswith("xml") else "p.yml")
        fs = cv2.FileStorage(str(f), cv2.FILE_STORAGE_WRITE)
        for i, Ti in enumerate(T):
            fs.write(f"pose_{i}", Ti)
        fs.release()
        says = "OpenCV FileStorage: 4 4x4 matrices (pose_0 ... pose_3"
    elif form == "yaml_list":
        f = tmp_path / "p.yaml"
        f.write_text("".join(f"- {Ti.tolist()}\n" for Ti in T))
        says = "a YAML list of poses"
    elif form == "yaml_T_mm":
        f = tmp_path / "p.yaml"
        Tm = T.copy()
        Tm[:, :3, 3] *= 1e3
        f.write_text("units: {length: mm}\nposes:\n" + "".join(f"  - {{T: {Ti.tolist()}}}\n" for Ti in Tm))
        says = "(T)"
    got = load_poses(f)
    # 12 significant digits written: 1e-11 relative; mm and deg conversions keep that
    np.testing.assert_allclose(got.T, T, atol=1e-9)
    assert (got.t is not None) == timed
    if timed:
        np.testing.assert_allclose(got.t, t, atol=1e-9)
    assert says in got.form and "\n" not in got.form, got.form


_GOOD = "# t x y z qx qy qz qw\n" + "".join(f"{0.1 * i:.1f} {i} 0.5 0.25 0 0 0 1\n" for i in range(5))
_JUNK = st.sampled_from(["abc", "nan", "inf", "", "1e999", "0 0", ",", "1.2.3", "\x00", "2", "-", "[1]"])


@settings(max_examples=60, deadline=None)
@given(line=st.integers(1, 5), col=st.integers(0, 7), junk=_JUNK, mode=st.sampled_from(["replace", "insert", "drop"]))
def test_malformed_headerless_files_give_one_line_errors_naming_file_and_line(tmp_path_factory, line, col, junk,
                                                                            mode):
    from robocal.errors import RobocalError

    lines = _GOOD.splitlines()
    toks = lines[line].split()
    if mode == "replace":
        toks[col] = junk
    elif mode == "insert":
        toks.insert(col, junk)
    else:
        del toks[col]
    lines[line] = " ".join(toks)
    f = tmp_path_factory.mktemp("fuzz") / "poses.txt"
    f.write_text("\n".join(lines) + "\n")
    try:
        got = load_poses(f)
    except RobocalError as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith(str(f)), msg
        # an error in the data names its line (file line numbers: the comment is line 1)
        assert f"line {line + 1}" in msg or "line 2" in msg, msg
    else:
        # what still reads is a valid pose list (e.g. "2" written over a timestamp that still increases)
        assert np.all(np.isfinite(got.T)) and len(got) == 5


@settings(max_examples=40, deadline=None)
@given(text=st.text(st.sampled_from("0123456789.,- \n#abcxyzqtT[]:{}e"), max_size=120),
       suffix=st.sampled_from([".csv", ".txt", ".yaml"]))
def test_any_text_reads_or_fails_in_one_line(tmp_path_factory, text, suffix):
    from robocal.errors import RobocalError

    f = tmp_path_factory.mktemp("fuzz") / f"poses{suffix}"
    f.write_text(text)
    try:
        load_poses(f)
    except RobocalError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(f)), str(exc)
