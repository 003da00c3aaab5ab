"""Every example input through ``robocal <rig> calibrate`` and ``robocal report``: a re-structuring's yardstick.

Runs the example calibrations of ``examples/`` as a user runs them, checks that
``robocal report RESULT.json`` rebuilds the page ``calibrate`` wrote (equal but
for the time stamp) and, with ``--browser``, that the page reads in headless
Chromium at 1400 px (``tests/support/browser.py``). ``--save FILE`` writes the
estimates of every case; ``--compare FILE`` compares them with a saved run,
poses by their rotation and translation blocks whatever keys they were written
under (a ``robocal.result/1`` bare 4x4 ``T_a_b`` or ``R_a_b`` / ``t_a_b`` against
``T_a_b.rotation`` / ``T_a_b.translation``), so that a change of the result
vocabulary can be shown to leave every number as it was::

    git worktree add /tmp/old <earlier commit>
    PYTHONPATH=/tmp/old/src python bench/examples_roundtrip.py --save before.json
    python bench/examples_roundtrip.py --compare before.json --browser

Issue 20 (stop 22, against 72c78d7 run with ``PYTHONPATH=<worktree of
72c78d7>/src``): largest difference 0.0 on all 13 cases (keys no longer written:
quaternions ``q_*``, mirror's nuisance ``T_c_m`` now in ``diagnostics``), every
rebuilt report equal, no browser finding.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
E = "examples"
CASES = {
    "projector_room_A": f"projector calibrate {E}/projector/room_A.yaml",
    "projector_seed_A": f"projector calibrate {E}/projector/seed_projector_A.yaml",
    "projector_csv": f"projector calibrate {E}/projector/room_A_csv.yaml",
    "projector_narrow": f"projector calibrate {E}/projector/room_A_narrow_tilt.yaml",
    "humanoid": f"humanoid calibrate {E}/humanoid/run.yaml",
    "mirror_single": f"mirror calibrate {E}/mirror/published_single.yaml",
    "mirror_four": f"mirror calibrate {E}/mirror/four_placements.yaml",
    "mirror_aruco": f"mirror calibrate {E}/mirror/aruco_images.yaml",
    "mirror_own": f"mirror calibrate {E}/mirror/own_camera.yaml",
    "flow_cal": f"flow calibrate {E}/flow/calibration/run.yaml",
    "lp_fpdp": f"lineprofiler calibrate {E}/lineprofiler/fpdp_input.yaml",
    "lp_mct": f"lineprofiler calibrate {E}/lineprofiler/mct_input.yaml",
    "camera_session": f"camera calibrate {E}/camera/camera_input.yaml",
    "camera_folder": f"camera calibrate {E}/camera/images --target {E}/camera/target.yaml",
    "handeye": f"handeye calibrate {E}/lineprofiler/gripper_poses.csv {E}/lineprofiler/target_poses.csv",
}


def _robocal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "robocal", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT)


def _strip_stamp(html: str) -> str:
    return re.sub(r"<p class='meta'>.*?</p>", "", html)


def _blocks(estimate: dict) -> dict[str, np.ndarray]:
    """Every estimate as named float arrays, poses split into ``name.rotation`` / ``name.translation``."""
    out = {}
    for key, value in estimate.items():
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            continue
        if arr.shape == (4, 4):  # a robocal.result/1 bare pose
            out[f"{key}.rotation"], out[f"{key}.translation"] = arr[:3, :3], arr[:3, 3]
        elif re.fullmatch(r"R_[A-Za-z0-9]+_[A-Za-z0-9]+", key):
            out[f"T{key[1:]}.rotation"] = arr
        elif re.fullmatch(r"t_[A-Za-z0-9]+_[A-Za-z0-9]+", key):
            out[f"T{key[1:]}.translation"] = arr
        elif re.fullmatch(r"rotvec_[A-Za-z0-9]+_[A-Za-z0-9]+", key):
            out[f"T{key[6:]}.rotvec"] = arr
        else:
            out[key] = arr
    return out


def run(names, *, browser: bool) -> dict:
    from robocal.io import load_result

    check_page = None
    if browser:
        sys.path.insert(0, str(ROOT / "tests" / "support"))
        import browser as _browser

        if _browser.chromium_executable() is None:
            print("no Chromium: pages not checked in a browser")
        else:
            check_page = _browser.check_page
    tmp = Path(tempfile.mkdtemp(prefix="robocal-examples-"))
    saved = {}
    for name in names:
        cal, rep = tmp / name, tmp / f"{name}-report"
        t0 = time.perf_counter()
        proc = _robocal(*CASES[name].split(), "--out", cal)
        t_cal = time.perf_counter() - t0
        if proc.returncode:
            print(f"{name:18s} calibrate failed: {proc.stderr.strip()[-200:]}")
            continue
        proc = _robocal("report", cal / "result.json", "--out", rep)
        equal = proc.returncode == 0 and (_strip_stamp((rep / "report.html").read_text(encoding="utf-8"))
                                          == _strip_stamp((cal / "report.html").read_text(encoding="utf-8")))
        findings = check_page(cal / "report.html") if check_page else []
        res = load_result(cal / "result.json")
        saved[name] = {k: v.tolist() for k, v in _blocks(res.estimate).items()}
        print(f"{name:18s} calibrate {t_cal:5.1f} s  report rebuilt equal: {equal}  "
              f"browser findings: {len(findings) if check_page else '-'}  {'; '.join(findings[:2])}")
    return saved


def compare(before: dict, after: dict) -> float:
    worst_all = 0.0
    for name, est in before.items():
        if name not in after:
            print(f"{name:18s} not run now")
            continue
        now = after[name]
        common = [k for k in est if k in now]
        gone = sorted(set(est) - set(now))
        worst = max((float(np.max(np.abs(np.asarray(est[k]) - np.asarray(now[k])))) for k in common
                     if np.shape(est[k]) == np.shape(now[k])), default=0.0)
        worst_all = max(worst_all, worst)
        print(f"{name:18s} {len(common)} estimates compared, largest difference {worst:.1e}"
              + (f"; not written now: {', '.join(gone)}" if gone else ""))
    return worst_all


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cases", nargs="*", help=f"cases to run (default all: {', '.join(CASES)})")
    ap.add_argument("--save", type=Path, help="write the estimates of this run to a JSON file")
    ap.add_argument("--compare", type=Path, help="compare with the estimates saved by an earlier --save")
    ap.add_argument("--browser", action="store_true", help="check every report in headless Chromium")
    args = ap.parse_args()
    names = args.cases or list(CASES)
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        ap.error(f"unknown case(s): {', '.join(unknown)}")
    saved = run(names, browser=args.browser)
    if args.save:
        args.save.write_text(json.dumps(saved, indent=1))
    if args.compare:
        worst = compare(json.loads(args.compare.read_text()), saved)
        print(f"largest difference over all cases: {worst:.1e}")


if __name__ == "__main__":
    main()
