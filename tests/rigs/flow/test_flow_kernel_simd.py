"""The C kernel's SIMD paths give the numba kernel's outputs to the bit (issue 16): the default 8x8 / +/-4 px
search with AVX2 ``mpsadbw`` (the path a CPU with AVX2 runs), the SSE2 ``psadbw`` build (``-DFLOWC_NO_AVX2``:
what any other x86-64 runs) and the numba fallback, on adversarial frames: uniform noise, constant frames
(every SAD ties: the first offset in scan order wins), periodic patterns (ties between rows, between dx = +3
and +4, between -4 and +4), saturated 0 / 255 frames (the largest SADs, 16,320), few grey levels, and every
sensor of the example log. Every output is compared: flow, status, least SAD, distinctness, texture."""

import importlib.machinery
import importlib.util
import os
import shutil
import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from robocal.rigs.flow import kernel as K
from robocal.rigs.flow.kernel import FlowConfig, match_blocks

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"
FIELDS = ("flow", "status", "sad_min", "distinctness", "texture")
MODES = ("equiangular", "parabolic", "none")     # the fits that read the SAD surface's neighbours


def _cc():
    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()
    if shutil.which(cc[0]) is None or not Path(sysconfig.get_paths()["include"], "Python.h").is_file():
        return None
    return cc


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    """The installed extension (AVX2 on this path where the CPU has it) and the SSE2 build of the same source."""
    if K._flowc() is None:
        pytest.skip("the C kernel was not built (no C compiler at install)")
    out = {"installed": K._flowc()}
    cc = _cc()
    if cc is not None:
        so = tmp_path_factory.mktemp("sse2") / ("_flowc" + importlib.machinery.EXTENSION_SUFFIXES[0])
        subprocess.run([*cc, "-O2", "-shared", "-fPIC", "-DFLOWC_NO_AVX2", f"-I{sysconfig.get_paths()['include']}",
                        "-o", str(so), str(Path(K.__file__).with_name("flowc.c")), "-lm"], check=True,
                       capture_output=True)
        spec = importlib.util.spec_from_file_location("_flowc", so)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        out["sse2"] = mod
    return out


def _c(mod, prev, curr, config):
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(K, "_FLOWC", mod)
        mp.setenv(K.KERNEL_ENV, "c")
        return match_blocks(prev, curr, config)


def _numba(prev, curr, config):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(K.KERNEL_ENV, "numba")
        return match_blocks(prev, curr, config)


def _same(builds, prev, curr, config=FlowConfig()):
    """Every build's outputs equal numba's, field by field (equal, not close: integer SADs, the same fit)."""
    ref = _numba(prev, curr, config)
    for name, mod in builds.items():
        got = _c(mod, prev, curr, config)
        for f in FIELDS:
            assert np.array_equal(getattr(got, f), getattr(ref, f), equal_nan=True), (name, f)
    return ref


def test_the_simd_level_is_the_cpus(builds):
    """Where the CPU has AVX2 the default path must run it (else the speed of issue 16 is silently lost)."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file() and " avx2" in cpuinfo.read_text() and K._flowc().SIMD != "portable":
        assert K._flowc().SIMD == "avx2"
    if "sse2" in builds:
        assert builds["sse2"].SIMD == "sse2"


def _adversarial(rng):
    """(name, prev, curr) frame pairs built to tie or saturate the SAD surface."""
    w = 64
    yield "noise", rng.integers(0, 256, (6, w, w), dtype=np.uint8), rng.integers(0, 256, (6, w, w), dtype=np.uint8)
    const = np.full((3, w, w), 77, np.uint8)
    yield "constant", const, const.copy()                          # all 81 SADs 0: offset (-4, -4) wins
    yield "constant, different levels", np.full((2, w, w), 3, np.uint8), np.full((2, w, w), 250, np.uint8)
    zeros, full = np.zeros((2, w, w), np.uint8), np.full((2, w, w), 255, np.uint8)
    yield "saturated 0 / 255", zeros, full                         # every SAD 8 * 8 * 255 = 16,320
    yield "saturated 255 / 0", full, zeros
    yield "binary 0 / 255", *(rng.choice(np.array([0, 255], np.uint8), (2, 4, w, w)))
    yield "two grey levels", *(rng.integers(0, 2, (2, 4, w, w), dtype=np.uint8))
    for py, px in ((1, 1), (1, 8), (8, 1), (4, 4), (2, 8), (8, 8), (3, 7), (1, 2)):
        tile = rng.integers(0, 256, (py, px), dtype=np.uint8)
        a = np.tile(tile, (w // py + 1, w // px + 1))[:w, :w]
        b = np.roll(a, (1, 2), axis=(0, 1))
        yield f"period {py}x{px}", np.stack([a, a, b]), np.stack([b, a, a])   # ties between rows / columns
    yield "dilated", *_dilated(rng)
    # smooth texture moved by half-integer steps next to the window's corners: the best at dy, dx = +3 or
    # +4 with its 3x3 reaching the last row / the d = 8 column, which the second minimum must leave out
    smooth = rng.integers(0, 256, (w + 16, w + 16)).astype(float)
    smooth = (smooth + np.roll(smooth, 1, 0) + np.roll(smooth, 1, 1) + np.roll(smooth, (1, 1), (0, 1))) / 4
    prev, curr = [], []
    for dy, dx in ((3, 3), (3, -4), (-4, 3), (3, 0), (0, 3)):
        a = smooth[8:8 + w, 8:8 + w]
        moved = (np.roll(smooth, (dy, dx), (0, 1)) + np.roll(smooth, (dy + 1, dx + 1), (0, 1))) / 2
        prev.append(a)
        curr.append(moved[8:8 + w, 8:8 + w])
    yield "half-pixel steps at the corners", np.round(prev).astype(np.uint8), np.round(curr).astype(np.uint8)


def _dilated(rng, shifts=((0, 3), (3, 0), (-4, 3), (3, -4), (1, 1), (0, 0))):
    """Binary blobs against a copy shifted by (dy, dx) and dilated by one pixel along +x (or +y): matching at
    dx and dx + 1 leaves one mismatching edge each, so the least SAD ties between two neighbours in a clear
    valley (the block is accepted): the tie rule decides the integer flow. (0, 3): dx = +3 against +4."""
    w = 64
    blobs = np.kron(rng.integers(0, 2, (len(shifts), w // 4, w // 4)), np.ones((4, 4), np.int64))
    prev = (200 * blobs).astype(np.uint8)
    curr = np.empty_like(prev)
    for i, (dy, dx) in enumerate(shifts):
        c = np.roll(prev[i], (dy, dx), axis=(0, 1))
        axis = 1 if i % 2 == 0 else 0            # along x, then along y
        curr[i] = np.maximum(c, np.roll(c, 1, axis=axis))
    return prev, curr


def _sad_surfaces(prev, curr, config=FlowConfig()):
    """(N, blocks, 9, 9) SADs by NumPy (eq. 1): an independent check of what the frames exercise."""
    from numpy.lib.stride_tricks import sliding_window_view

    o1 = K.block_origins(config)
    s, bk = config.search, config.block
    out = []
    for y0 in o1:
        for x0 in o1:
            p = prev[:, y0:y0 + bk, x0:x0 + bk].astype(np.int32)
            win = curr[:, y0 - s:y0 + bk + s, x0 - s:x0 + bk + s].astype(np.int32)
            v = sliding_window_view(win, (bk, bk), axis=(1, 2))          # (N, 9, 9, 8, 8)
            out.append(np.abs(v - p[:, None, None]).sum(axis=(-2, -1)))
    return np.stack(out, axis=1)


def test_the_adversarial_frames_tie_where_the_tie_rule_decides(builds):
    """The cases above are not vacuous: accepted blocks whose least SAD ties with a neighbour in its 3x3
    (so the first in scan order decides the flow), among them dx = +3 against +4 and a tie between rows."""
    prev, curr = _dilated(np.random.default_rng(16))
    sads = _sad_surfaces(prev, curr)
    # subpixel "none": the flow is the integer offset (the equiangular fit of a two-way tie gives the
    # midpoint from either neighbour, so there the rule shows only in the other outputs)
    r = _c(builds["installed"], prev, curr, FlowConfig(subpixel="none"))
    flat = sads.reshape(*sads.shape[:2], 81)
    best = flat.min(axis=-1)
    assert np.array_equal(best, r.sad_min)                     # NumPy's SADs are the kernel's
    oy, ox = np.divmod(flat.argmin(axis=-1), 9)                # NumPy's argmin: the first in scan order
    acc = r.status == 0
    ties = (flat == best[..., None]).sum(axis=-1) > 1
    tie_x34 = ((sads[..., 7] == best[..., None]) & (sads[..., 8] == best[..., None])).any(axis=-1)
    tie_rows = ((sads == best[..., None, None]).any(axis=-1)).sum(axis=-1) > 1
    assert (ties & acc).sum() >= 10 and (tie_x34 & acc).any() and (tie_rows & acc).any()
    assert np.array_equal(r.flow[..., 0][acc], (ox - 4)[acc].astype(float))
    assert np.array_equal(r.flow[..., 1][acc], (oy - 4)[acc].astype(float))


@pytest.mark.parametrize("subpixel", MODES)
def test_adversarial_frames_give_the_numba_bits(builds, subpixel):
    config = FlowConfig(subpixel=subpixel)
    statuses = set()
    for name, prev, curr in _adversarial(np.random.default_rng(16)):
        ref = _same(builds, prev, curr, config)
        statuses |= set(np.unique(ref.status))
    assert statuses >= {0, 1, 2, 3}         # every outcome of a block is among the compared


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), levels=st.sampled_from([1, 2, 3, 16, 256]),
       period=st.sampled_from([(0, 0), (1, 1), (1, 8), (8, 1), (2, 2), (1, 4), (4, 8)]),
       shift=st.tuples(st.integers(-5, 5), st.integers(-5, 5)), noise=st.integers(0, 3))
def test_random_and_tied_frames_give_the_numba_bits(builds, seed, levels, period, shift, noise):
    """Few grey levels and periodic frames make many SADs equal (between rows, between dx = +3 and +4);
    the shifted copy with a little noise makes the accepted path and its fit run too."""
    rng = np.random.default_rng(seed)
    w = 64
    if period == (0, 0):
        a = rng.integers(0, levels, (2, w, w))
    else:
        tile = rng.integers(0, levels, (2, *period))
        a = np.tile(tile, (1, w // period[0] + 1, w // period[1] + 1))[:, :w, :w]
    scale = 255 // max(levels - 1, 1)
    a = (a * scale).astype(np.uint8)
    b = np.roll(a, shift, axis=(1, 2)).astype(np.int16) + rng.integers(-noise, noise + 1, a.shape)
    b = np.clip(b, 0, 255).astype(np.uint8)
    _same(builds, a, b)


def test_every_sensor_of_the_example_log_gives_the_numba_bits(builds):
    from robocal.rigs.flow.log import read_frames_npz

    frames = read_frames_npz(EX / "frames" / "frames.npz")["frames"]
    for s in range(frames.shape[0]):
        _same(builds, frames[s, :-1], frames[s, 1:])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), values=st.sampled_from(["ties", "signed zeros", "spread"]))
def test_the_aggregation_gives_the_numba_bits(builds, seed, values):
    """The per-frame median (ranks instead of an insertion sort in C) and the trimmed mean: flows with many
    equal values, -0.0 beside 0.0 (equal for '<', different bits: the stable sort's order decides which is
    the median), odd and even accepted counts, every aggregation mode."""
    from robocal.rigs.flow.kernel_compiled import _aggregate_frames

    rng = np.random.default_rng(seed)
    n, nb = 64, 25
    if values == "ties":
        flow = rng.integers(-3, 4, (n, nb, 2)) * 0.25
    elif values == "signed zeros":
        flow = rng.choice(np.array([-0.0, 0.0, 0.5, -0.5]), (n, nb, 2))
    else:
        flow = rng.normal(0, 2, (n, nb, 2))
    status = np.where(rng.random((n, nb)) < 0.7, 0, rng.integers(1, 4, (n, nb))).astype(np.int8)
    cen = rng.normal(0, 10, (nb, 2))
    for mode in (0, 1, 2):
        outs = []
        for impl in ("numba", *builds):
            used, out, agr, spr, c = (np.empty((n, nb), np.bool_), np.empty((n, 2)), np.empty(n), np.empty(n),
                                      np.empty((n, 2)))
            if impl == "numba":
                _aggregate_frames(flow, status, cen, mode, 1.0, used, out, agr, spr, c)
            else:
                builds[impl].aggregate(flow, status, cen, n, nb, mode, 1.0, used, out, agr, spr, c)
            outs.append((used, out, agr, spr, c))
        for got in outs[1:]:
            for a, b in zip(got, outs[0]):
                # bits, not values: np.array_equal calls -0.0 and 0.0 equal
                assert np.array_equal(np.asarray(a).view(np.uint8), np.asarray(b).view(np.uint8)), (values, mode)
