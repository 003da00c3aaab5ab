"""Reading a recording's tf and joint topics without its images: throughput in MB of recording per second.

A simulated recording of each kind (ROS 1 .bag, ROS 2 sqlite3, MCAP) of about
``--mb`` MB, nearly all of it 640x480 mono8 images at 30 Hz, with /tf
(odom -> base_link 50 Hz, base_link -> tool0 100 Hz), /tf_static,
/joint_states (100 Hz, 6 joints) and /odom. Timed: opening it, ``read_tf`` (every tf
message decoded into the tree) and ``read_joint_states``, best of 3, the files
in the page cache (just written): the reader's cost, not the disk's. Wall
time and this process's CPU time are both given: on a shared machine the
CPU time is what the read costs on a core of its own. The
images are not read (only the tf and joint topics' messages are), so the
figure scales with the bag's size, not with the work done (the tf and
joint message count is printed beside it). For scale, decoding every image
frame is timed once too.

Run: ``python bench/bench_bags.py`` (``--mb 200``, ``--formats rosbag1,rosbag2,mcap``).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import robocal.bags as bags
from _timing import best_of  # bench/ is on sys.path when a script runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=200.0, help="approximate recording size [MB]")
    ap.add_argument("--formats", default=",".join(bags.RECORDING_FORMATS))
    args = ap.parse_args()
    image_bytes, rate = 640 * 480, 30.0
    duration = args.mb * 1e6 / (image_bytes * rate)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in args.formats.split(","):
            path = Path(tmp) / ("rec.bag" if fmt == "rosbag1" else f"rec_{fmt}")
            t0 = time.perf_counter()
            bags.simulate_recording(path, format=fmt, duration=duration, tf_rate=50.0, joint_rate=100.0,
                                    image_rate=rate, image_size=(640, 480), distinct_images=4)
            t_write = time.perf_counter() - t0
            with bags.open_recording(path) as rec:
                size, topics = rec.size_bytes, rec.topics
            n_msgs = sum(topics[t].count for t in ("/tf", "/tf_static", "/joint_states"))

            def read():  # one opening for both reads (each opening parses the message definitions)
                with bags.open_recording(path) as rec:
                    bags.read_tf(rec, show_progress=False)
                    bags.read_joint_states(rec, show_progress=False)

            t_read = best_of(read)
            cpu = []  # CPU time of this process: what the read costs on a core of its own (the machine may be shared)
            for _ in range(3):
                c0 = time.process_time()
                read()
                cpu.append(time.process_time() - c0)
            t_cpu = min(cpu)
            t0 = time.perf_counter()
            n_img = sum(1 for _ in bags.images(path, "/camera/image_raw", show_progress=False))
            t_img = time.perf_counter() - t0
            rows.append((fmt, size / 1e6, n_msgs, t_read, t_cpu, size / 1e6 / t_read, size / 1e6 / t_cpu, n_img, t_img,
                         t_write))
    print(f"recording: {duration:.1f} s, 640x480 mono8 images at {rate:g} Hz + tf (150 Hz) + joints (100 Hz) + odom\n")
    print(f"load average before the last read: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs\n")
    print("| format | size [MB] | tf + joint messages | read tf + joints, wall [s] | CPU [s] | MB/s wall | MB/s CPU "
          "| images decoded | all images [s] | write [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for fmt, mb, n, t, tc, mbs, mbc, n_img, t_img, t_w in rows:
        print(f"| {fmt} | {mb:.0f} | {n} | {t:.3f} | {tc:.3f} | {mbs:.0f} | {mbc:.0f} | {n_img} | {t_img:.2f} | {t_w:.1f} |")


if __name__ == "__main__":
    main()
