"""Issue 16's wall-clock work: the C kernel's pairs on threads (the same bits as one thread, the GIL released
around its loops) and the reading beside the kernel (robocal.rigs.flow.background: the inputs' hashes and
the trajectories, never stale, errors as the synchronous read gives them)."""

import os
import shutil
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.io import hash_inputs
from robocal.rigs.flow import background
from robocal.rigs.flow import kernel as K
from robocal.rigs.flow.kernel import FlowConfig, compute_flow, compute_flow_sequence, match_sequence
from robocal.rigs.flow.log import load_run, read_poses_csv
from robocal.rigs.flow.workflow import evaluation_run, odometry_result, odometry_run, read_reference

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"
BEFORE = Path(__file__).parent / "data" / "odometry_before_issue16.npz"
needs_c = pytest.mark.skipif(K._flowc() is None, reason="the C kernel was not built (no C compiler at install)")


def _threads(mp, n, min_pairs=16):
    """Force ``n`` kernel threads, and chunks of a few pairs so that the small test inputs are split."""
    mp.setenv(K.THREADS_ENV, str(n))
    mp.setattr(K, "MIN_PAIRS_PER_THREAD", min_pairs)


def test_chunks_cover_every_pair_once_on_several_threads(monkeypatch):
    _threads(monkeypatch, 4)
    seen = []
    lock = threading.Lock()

    def run(s, e):
        with lock:
            seen.append((s, e, threading.get_ident()))

    K._chunked(1000, run)
    spans = sorted((s, e) for s, e, _ in seen)
    assert spans[0][0] == 0 and spans[-1][1] == 1000 and len(spans) == 4
    assert all(a[1] == b[0] for a, b in zip(spans, spans[1:]))        # contiguous, no overlap, no gap
    assert len({t for *_, t in seen}) > 1                              # not all in the caller's thread
    seen.clear()
    K._chunked(10, run)                                                 # fewer pairs than a chunk: one call
    assert [(s, e) for s, e, _ in seen] == [(0, 10)] and seen[0][2] == threading.get_ident()


def test_thread_count_from_the_environment_and_the_affinity(monkeypatch):
    monkeypatch.delenv(K.THREADS_ENV, raising=False)
    expected = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert K.kernel_threads() == expected
    monkeypatch.setenv(K.THREADS_ENV, "3")
    assert K.kernel_threads() == 3
    for bad in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv(K.THREADS_ENV, bad)
        with pytest.raises(InputError, match=f"ROBOCAL_FLOW_THREADS must be a positive integer.*{bad}"):
            K.kernel_threads()


@needs_c
def test_threads_give_the_same_bits_as_one(monkeypatch, gravel_pairs):
    """Each pair and each frame's aggregation is computed alone: chunks cannot change a bit."""
    prev, curr, _ = gravel_pairs
    seq = np.stack([prev, curr], axis=1).reshape(-1, *prev.shape[1:])  # p0 c0 p1 c1 ..: 239 consecutive pairs
    config = FlowConfig()
    out = {}
    for n in (1, 4):
        with pytest.MonkeyPatch.context() as mp:
            _threads(mp, n)
            mp.setenv(K.KERNEL_ENV, "c")
            out[n] = (match_sequence(seq, config), compute_flow_sequence(seq, config), compute_flow(prev, curr, config))
    bm1, seq1, pair1 = out[1]
    bm4, seq4, pair4 = out[4]
    for f in ("flow", "status", "sad_min", "distinctness", "texture"):
        assert np.array_equal(getattr(bm1, f), getattr(bm4, f), equal_nan=True), f
    for a, b in ((seq1, seq4), (pair1, pair4)):
        for f in ("flow_px", "quality", "valid", "agreement", "spread_px", "centroid_px", "n_accepted"):
            assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True), f
        assert a.reason == b.reason
    assert np.isfinite(seq1.flow_px).any()              # the comparison saw accepted frames, not only NaN


@needs_c
@pytest.mark.parametrize("threads", [1, 3])
def test_example_odometry_unchanged_with_threads_and_with_one(threads, monkeypatch):
    """examples/flow/frames as recorded before issue 16 (see test_flow_speed_paths for the tolerances)."""
    _threads(monkeypatch, threads)
    monkeypatch.setenv(K.KERNEL_ENV, "c")
    od, flows, _ = odometry_run(load_run(EX / "frames" / "run.yaml"))
    before = np.load(BEFORE)
    assert np.array_equal(np.stack([f.flow_px for f in flows]), before["frames_flow"], equal_nan=True)
    assert np.array_equal(np.stack([f.quality for f in flows]), before["frames_quality"])
    np.testing.assert_allclose(od.poses, before["frames_poses"], rtol=0, atol=1e-9)


@needs_c
def test_the_c_kernel_releases_the_gil():
    """While one thread is inside ``_flowc.match`` another runs Python. With a switch interval of 100 s the
    interpreter never takes the GIL from a thread that holds it, so the main thread resumes during the
    match only if the match let go of it; if it did not, the main thread would resume after the match
    and see it finished, every time. The match (4000 pairs, ~30 ms) outlasts the main thread's wake-up;
    three tries, one enough, so that a loaded machine's late wake-up cannot fail the test."""
    frames = np.random.default_rng(0).integers(0, 256, size=(4001, 64, 64), dtype=np.uint8)

    def resumed_during_the_match() -> bool:
        started, state = threading.Event(), {"done": False}

        def work():
            started.set()
            match_sequence(frames)
            state["done"] = True

        t = threading.Thread(target=work)
        t.start()
        started.wait()
        during = not state["done"]
        t.join()
        assert state["done"]
        return during

    old = sys.getswitchinterval()
    sys.setswitchinterval(100.0)
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv(K.THREADS_ENV, "1")
            mp.setenv(K.KERNEL_ENV, "c")
            assert any(resumed_during_the_match() for _ in range(3))
    finally:
        sys.setswitchinterval(old)


@pytest.fixture()
def frames_copy(tmp_path):
    d = tmp_path / "frames"
    shutil.copytree(EX / "frames", d)
    return d


def test_result_hashes_and_trajectories_are_those_of_the_files(frames_copy):
    spec = load_run(frames_copy / "run.yaml")
    od, _, steps = odometry_run(spec)
    curves, errors = evaluation_run(spec, od)
    res = odometry_result(od, spec, errors, curves=curves, steps=steps)
    assert res.inputs == hash_inputs(spec.inputs()) and len(res.inputs) == 4   # run.yaml, frames, truth, wheel
    t, p = read_poses_csv(frames_copy / "truth.csv")
    t2, p2 = read_reference(spec)
    assert np.array_equal(t, t2) and np.array_equal(p, p2)


def test_a_file_written_after_the_start_is_read_and_hashed_afresh(frames_copy):
    spec = load_run(frames_copy / "run.yaml")
    background.start(spec)
    t0, p0 = read_reference(spec)
    old = background.inputs_hash(spec)
    truth = frames_copy / "truth.csv"
    lines = truth.read_text().splitlines(True)
    # the last pose 1 m further (a longer line: the size changes even where mtime's clock is coarse)
    *head, last = lines
    f = last.strip().split(",")
    truth.write_text("".join(head) + f"{f[0]},{float(f[1]) + 1.0:.6f},{f[2]},{f[3]}\n")
    t1, p1 = read_reference(spec)
    assert np.array_equal(t1, t0) and p1[-1, 0] == pytest.approx(p0[-1, 0] + 1.0, abs=1e-6)
    new = background.inputs_hash(spec)
    assert new == hash_inputs(spec.inputs()) and new[str(truth)] != old[str(truth)]


def test_a_damaged_reference_reads_as_it_would_without_the_thread(frames_copy):
    truth = frames_copy / "truth.csv"
    truth.write_text(truth.read_text().replace("0.005000,", "0.005000,x", 1))
    with pytest.raises(InputError) as direct:
        read_poses_csv(truth)
    with pytest.raises(InputError) as via_thread:
        odometry_run(load_run(frames_copy / "run.yaml"))
    assert type(via_thread.value) is type(direct.value) and str(via_thread.value) == str(direct.value)
