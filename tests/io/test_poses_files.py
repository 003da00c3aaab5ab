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
