"""sensor_msgs/PointCloud2 read as arrays (robocal.bags.read_point_clouds): layouts, byte orders, padding, errors."""

import numpy as np
import pytest

from robocal.bags import RECORDING_FORMATS, read_point_clouds
from robocal.bags._simulate import T0_NS, _Writer
from robocal.errors import FileFormatError, InputError

FIELD = {"f4": 7, "f8": 8, "u2": 4}


def _cloud(w, stamp, pts, *, dtype="f4", big=False, height=1, pad=0, extra=True):
    """A PointCloud2 of ``pts`` (N, 3): fields x, (intensity u2), y, z; rows padded by ``pad`` bytes."""
    order = ">" if big else "<"
    names, formats = ["x"], [order + dtype]
    if extra:
        names.append("intensity")
        formats.append(order + "u2")
    names += ["y", "z"]
    formats += [order + dtype] * 2
    rec = np.zeros(len(pts), np.dtype({"names": names, "formats": formats}))
    for k, n in enumerate("xyz"):
        rec[n] = pts[:, k]
    width = len(pts) // height
    step = rec.dtype.itemsize
    rows = rec.view(np.uint8).reshape(height, width * step) if len(pts) else np.zeros((height, 0), np.uint8)
    data = np.hstack([rows, np.full((height, pad), 0xAB, np.uint8)]).reshape(-1)
    fields = [w.msg("sensor_msgs/msg/PointField", name=n, offset=rec.dtype.fields[n][1],
                    datatype=FIELD[rec.dtype.fields[n][0].str[1:]], count=1) for n in names]
    return w.msg("sensor_msgs/msg/PointCloud2", header=w.header(stamp, "/profiler"), height=height, width=width,
                 fields=fields, is_bigendian=big, point_step=step, row_step=width * step + pad, data=data,
                 is_dense=False)


@pytest.mark.parametrize("fmt", RECORDING_FORMATS)
def test_clouds_of_every_layout(tmp_path, fmt):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 3)).astype(np.float32).astype(float)  # float32 exactly representable
    b = rng.normal(size=(4, 3))
    a[1] = np.nan  # a dropout in an organised cloud: kept
    path = tmp_path / ("c.bag" if fmt == "rosbag1" else "c")
    with _Writer(path, fmt) as w:
        for k, msg in enumerate([_cloud(w, T0_NS, a, height=2, pad=3),  # organised 2 x 3, padded rows
                                 _cloud(w, T0_NS + 10**8, b, dtype="f8", big=True, extra=False),
                                 _cloud(w, T0_NS + 2 * 10**8, np.zeros((0, 3)))]):
            w.write("/profiles", "sensor_msgs/msg/PointCloud2", T0_NS + k * 10**8 + 10**6, msg)
    pc = read_point_clouds(path, "/profiles", show_progress=False)
    assert pc.frame_id == "profiler" and pc.fields == ("x", "y", "z")
    assert pc.stamps_ns.tolist() == [T0_NS, T0_NS + 10**8, T0_NS + 2 * 10**8]
    assert pc.receive_ns[0] - pc.stamps_ns[0] == 10**6
    np.testing.assert_array_equal(pc.points[0], a)  # exact: float32 values, NaN row in place
    np.testing.assert_array_equal(pc.points[1], b)  # exact: float64 big-endian
    assert pc.points[2].shape == (0, 3)
    xz = read_point_clouds(path, "/profiles", ("x", "z"), show_progress=False).points[1]
    np.testing.assert_array_equal(xz, b[:, [0, 2]])


def test_cloud_errors(tmp_path):
    path = tmp_path / "c.bag"
    with _Writer(path, "rosbag1") as w:
        msg = _cloud(w, T0_NS, np.ones((2, 3)))
        msg.data = msg.data[:-4]  # truncated
        w.write("/cut", "sensor_msgs/msg/PointCloud2", T0_NS, msg)
        w.write("/ok", "sensor_msgs/msg/PointCloud2", T0_NS, _cloud(w, T0_NS, np.ones((2, 3))))
    with pytest.raises(FileFormatError, match=r"topic /cut: a 2x1 PointCloud2 of 14-byte points needs 1 rows"):
        read_point_clouds(path, "/cut", show_progress=False)
    with pytest.raises(InputError, match=r"without field\(s\) rgb; fields: x, intensity, y, z"):
        read_point_clouds(path, "/ok", ("x", "rgb"), show_progress=False)
    with pytest.raises(InputError, match="closest: /ok"):
        read_point_clouds(path, "/okk", show_progress=False)
