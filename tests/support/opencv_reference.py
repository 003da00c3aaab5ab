"""OpenCV functions that 5.x dropped, replayed from values recorded with OpenCV 4.

Some tests compare robocal with an OpenCV function (``cv2.calibrateHandEye``,
``cv2.calibrateRobotWorldHandEye``, ``cv2.undistortPointsIter``) that OpenCV 5
no longer has. They call it as ``opencv.NAME(...)`` instead of ``cv2.NAME``:

* where cv2 has ``NAME`` (OpenCV 4), the live function is called;
* where it does not (OpenCV 5), the output recorded from OpenCV 4 for the same
  inputs is returned, found by a fingerprint of the inputs (shape, sum and a
  fixed weighted sum of each argument, matched to 1e-9 relative: the tests'
  inputs come from fixed seeds and differ across CPUs / BLAS builds only in
  the last bits). A call whose inputs were not recorded fails, saying how to
  record them; it is never skipped, and robocal's own checks in the same test
  run on either version.

Recording (needs OpenCV 4 installed; rewrites ``tests/data/opencv4_reference.npz``)::

    python tests/support/opencv_reference.py

which runs the tests in :data:`RECORDED_TESTS` with the live functions wrapped.
"""

from __future__ import annotations

import atexit
import os
import sys
from pathlib import Path

import cv2
import numpy as np

#: The functions OpenCV 5 dropped that the suite compares with.
DROPPED = ("calibrateHandEye", "calibrateRobotWorldHandEye", "undistortPointsIter")
#: The tests whose calls are recorded (every test that calls ``opencv.<one of DROPPED>``).
RECORDED_TESTS = (
    "tests/rigs/lineprofiler/test_lp_handeye.py",
    "tests/camera/test_model.py::test_undistort_agrees_with_opencv_and_round_trips",
)
FIXTURE = Path(__file__).resolve().parents[1] / "data" / "opencv4_reference.npz"
_RECORD_ENV = "ROBOCAL_RECORD_OPENCV_REFERENCE"
_RTOL = 1e-9  # inputs agree to ~1e-15 relative across machines; a different input differs by O(1)


def _fingerprint(args: tuple) -> np.ndarray:
    """Shape, sum and a fixed weighted sum of each argument (None -> NaNs), flattened."""
    out = []
    for a in args:
        if a is None:
            out += [np.nan] * 3
            continue
        a = np.asarray(a, dtype=float).ravel()
        w = np.sin(np.arange(1, a.size + 1))  # fixed weights: a permutation or sign change alters the sum
        out += [float(a.size), float(a.sum()), float(a @ w)]
    return np.array(out)


def _same(fp: np.ndarray, rec: np.ndarray) -> bool:
    if fp.shape != rec.shape:
        return False
    nan = np.isnan(fp)
    if not np.array_equal(nan, np.isnan(rec)):
        return False
    scale = np.max(np.abs(fp[~nan]), initial=1.0)
    return bool(np.all(np.abs(fp[~nan] - rec[~nan]) <= _RTOL * scale))


def _call_args(args, kwargs) -> tuple:
    return (*args, *(kwargs[k] for k in sorted(kwargs)))


class _Recorded:
    def __init__(self, path: Path):
        self.calls: dict[str, list] = {}
        if path.exists():
            with np.load(path) as z:
                for key in z.files:
                    name, i, part = key.split("/")
                    entry = self.calls.setdefault(name, {}).setdefault(int(i), {})
                    entry[part] = z[key]
        self.calls = {n: [e for _, e in sorted(d.items())] for n, d in self.calls.items()}

    def replay(self, name: str):
        def fn(*args, **kwargs):
            fp = _fingerprint(_call_args(args, kwargs))
            for entry in self.calls.get(name, []):
                if _same(fp, entry["in"]):
                    outs = [entry[f"out{j}"] for j in range(int(entry["n_out"]))]
                    return tuple(o.copy() for o in outs) if int(entry["tuple"]) else outs[0].copy()
            raise AssertionError(
                f"OpenCV {cv2.__version__} has no cv2.{name} and {FIXTURE.name} holds no OpenCV 4 output for these "
                f"inputs: re-record with OpenCV 4 installed: python tests/support/opencv_reference.py")
        fn.__name__ = name
        return fn


class _Recorder:
    def __init__(self):
        self.entries: list[tuple[str, dict]] = []

    def wrap(self, name: str):
        live = getattr(cv2, name)

        def fn(*args, **kwargs):
            out = live(*args, **kwargs)
            outs = out if isinstance(out, tuple) else (out,)
            entry = {"in": _fingerprint(_call_args(args, kwargs)), "n_out": np.array(len(outs)),
                     "tuple": np.array(int(isinstance(out, tuple)))}
            entry.update({f"out{j}": np.asarray(o) for j, o in enumerate(outs)})
            self.entries.append((name, entry))
            return out
        return fn

    def save(self, path: Path):
        arrays, count = {}, {}
        for name, entry in self.entries:
            i = count.get(name, 0)
            count[name] = i + 1
            arrays.update({f"{name}/{i}/{k}": v for k, v in entry.items()})
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **arrays)
        print(f"recorded {len(self.entries)} calls {count} with OpenCV {cv2.__version__} to {path}", file=sys.stderr)


class _OpenCV:
    """``cv2`` with the functions of :data:`DROPPED` live (OpenCV 4) or replayed (OpenCV 5)."""

    def __init__(self):
        self._recorder = _Recorder() if os.environ.get(_RECORD_ENV) else None
        if self._recorder is not None:
            atexit.register(self._recorder.save, Path(os.environ[_RECORD_ENV]))
        self._recorded = None

    def __getattr__(self, name):
        if name in DROPPED:
            if self._recorder is not None:
                return self._recorder.wrap(name)
            if hasattr(cv2, name):
                return getattr(cv2, name)
            if self._recorded is None:
                self._recorded = _Recorded(FIXTURE)
            return self._recorded.replay(name)
        return getattr(cv2, name)


opencv = _OpenCV()


def is_live(name: str) -> bool:
    """True where ``cv2.<name>`` itself runs (OpenCV 4), False where its output is replayed."""
    return hasattr(cv2, name)


if __name__ == "__main__":
    import subprocess

    if not all(hasattr(cv2, n) for n in DROPPED):
        sys.exit(f"recording needs OpenCV 4 (cv2.{', cv2.'.join(DROPPED)}); this is OpenCV {cv2.__version__}")
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, _RECORD_ENV: str(FIXTURE), "OPENBLAS_NUM_THREADS": "1"}
    sys.exit(subprocess.call([sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", "-p", "no:cacheprovider",
                              *RECORDED_TESTS], cwd=root, env=env))
