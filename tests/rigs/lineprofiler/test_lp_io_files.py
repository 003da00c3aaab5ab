"""Profile and pose files: formats, their one-line errors naming file and line, SLERP between streams."""

from pathlib import Path

import numpy as np
import pytest

from robocal.errors import FileFormatError, InputError
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.rigs.lineprofiler.io import (
    interpolate_poses,
    load_block_faces_csv,
    load_poses,
    load_profiles_csv,
    write_poses_csv,
)

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"

def test_pose_files_errors(tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, nan, 0, 0, 0, 1\n")
    with pytest.raises(FileFormatError, match="nan"):
        load_poses(f)
    y = tmp_path / "p.yaml"
    y.write_text("units: {length: mm}\nposes:\n  - {p: [1, 2, 3], R: [[1, 0, 0], [0, 1, 0], [0, 0.1, 1]]}\n")
    with pytest.raises(FileFormatError, match="rotation matrix"):
        load_poses(y)
    y.write_text("units: {length: mm, time: s}\nposes:\n  - {p: [1, 2, 3], q: [0, 0, 0, 1], t: 0.5}\n")
    T, t = load_poses(y)
    assert np.allclose(T[0, :3, 3], [1e-3, 2e-3, 3e-3]) and t[0] == 0.5


def test_profiles_csv_round_trip_and_errors(tmp_path):
    profiles, q, t = load_profiles_csv(EX / "fpdp_profiles.csv", dof=3)
    assert len(profiles) == len(q) == 16 and t is None
    assert 0.15 < profiles[0][:, 1].mean() < 0.4  # z in metres
    f = tmp_path / "x.csv"
    f.write_text("profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n0, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match="differ between its rows"):
        load_profiles_csv(f)
    f.write_text("profile, x [mm], z [mm], q1\n0, 1, 2, 3\n")
    with pytest.raises(FileFormatError, match="needs a unit"):
        load_profiles_csv(f)


def test_csv_errors_name_the_file_line(tmp_path):
    """Comments and blank lines before the data: messages name the file line, not the data row."""
    head = "# exported by the tracker\n\n"
    f = tmp_path / "faces.csv"
    f.write_text(head + "face, x [mm], y [mm], z [mm]\n0, 1, 2, 3\n# probe re-seated\n4, 1, 2, 3\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 6\): column 'face' must be 0, 1 or 2"):
        load_block_faces_csv(f)
    f = tmp_path / "poses.csv"
    f.write_text(head + "x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 1\n0, 0, 0, 0, 0, 0.5, 0.5\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 5\): quaternion"):
        load_poses(f)
    f = tmp_path / "prof.csv"
    f.write_text(head + "profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n\n0, 1, 2, 4\n-1, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match=r"row 3 \(line 7\): column 'profile'"):
        load_profiles_csv(f)
    f.write_text(head + "profile, x [mm], z [mm], q1 [mm]\n0, 1, 2, 3\n\n0, 1, 2, 4\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 6\) against its first, row 1 \(line 4\)"):
        load_profiles_csv(f)


def test_slerp_interpolation_between_streams(tmp_path):
    t = np.array([0.0, 1.0, 2.0])
    T = transform_from(matrix_from_rotvec([[0, 0, 0], [0, 0, 0.4], [0, 0, 0.8]]), [[0, 0, 0], [1, 0, 0], [2, 0, 0]])
    write_poses_csv(tmp_path / "s.csv", T, t)
    T2, t2 = load_poses(tmp_path / "s.csv")
    Ti = interpolate_poses(t2, T2, [0.5, 1.75])
    assert np.allclose(Ti[0], transform_from(matrix_from_rotvec([0, 0, 0.2]), [0.5, 0, 0]), atol=1e-9)
    assert np.allclose(Ti[1, :3, 3], [1.75, 0, 0])
    with pytest.raises(InputError, match="no extrapolation"):
        interpolate_poses(t, T, [2.5])
    with pytest.raises(InputError, match="counts must match"):
        interpolate_poses(t[:2], T, [0.5])
