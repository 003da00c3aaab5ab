"""Write flow.tlog: the first 0.5 s of examples/flow/loop/flow.csv (simulated, 400 Hz) as 50 Hz
OPTICAL_FLOW_RAD records of three PX4FLOW-class sensors (sensor_id 0, 1, 2), MAVLink 2, with a
HEARTBEAT, a few garbage bytes and one record whose CRC is broken (the reader skips and counts them).

    python examples/flow/mavlink/make_flow_tlog.py
"""

from pathlib import Path

import numpy as np

from robocal.io import load_csv
from robocal.rigs.flow.mavlink import HEARTBEAT, OPTICAL_FLOW_RAD, encode_frame

HERE = Path(__file__).parent
F = 166.6667                      # focal length of the simulated sensors, px
tab = load_csv(HERE.parent / "loop" / "flow.csv", required=["t", "dt", "sensor", "flow_u", "flow_v", "gyro_x",
                                                           "gyro_y", "gyro_z", "height", "quality"])
c = {k: tab.column(k) for k in ("t", "dt", "sensor", "flow_u", "flow_v", "gyro_x", "gyro_y", "gyro_z", "height", "quality")}
T0 = 1_700_000_000_000_000        # log clock, us
out = [T0.to_bytes(8, "big") + encode_frame(HEARTBEAT, {"type": 2, "autopilot": 12, "mavlink_version": 3})]
seq = 0
for k in range(25):                                   # 25 records of 8 intervals (20 ms) per sensor
    for i in range(3):
        rows = np.flatnonzero((c["sensor"] == i) & (c["t"] > k * 0.02 + 1e-9) & (c["t"] <= (k + 1) * 0.02 + 1e-9))
        dt = c["dt"][rows]
        v = {"time_usec": int(round(c["t"][rows[-1]] * 1e6)), "sensor_id": i, "integration_time_us": int(round(dt.sum() * 1e6)),
             # the rig's image flow (px) -> OPTICAL_FLOW_RAD angles (docs/rigs/flow.md, "MAVLink logs")
             "integrated_x": c["flow_v"][rows].sum() / F, "integrated_y": -c["flow_u"][rows].sum() / F,
             "integrated_xgyro": (c["gyro_x"][rows] * dt).sum(), "integrated_ygyro": (c["gyro_y"][rows] * dt).sum(),
             "integrated_zgyro": (c["gyro_z"][rows] * dt).sum(), "distance": c["height"][rows].mean(),
             "quality": int(c["quality"][rows].min()), "temperature": 2500}
        frame = encode_frame(OPTICAL_FLOW_RAD, v, seq=seq, sysid=1, compid=100 + i)
        seq += 1
        out.append((T0 + v["time_usec"]).to_bytes(8, "big") + frame)
    if k == 10:
        out.append(b"\x00\x13garbage\xfe")
bad = bytearray(out[-1])
bad[-1] ^= 0xFF                                        # a broken CRC: a copy of the last record, skipped
out.append(bytes(bad))
(HERE / "flow.tlog").write_bytes(b"".join(out))
print(f"wrote {HERE / 'flow.tlog'} ({sum(map(len, out))} bytes)")
