"""The flow kernel's C peer for ``bench/bench_flow.py``: a hand-written SSE2 ``psadbw`` block matcher
with the same texture gate, acceptance tests, equiangular sub-pixel fit, trimmed-mean aggregation and
spread gate as :func:`robocal.rigs.flow.kernel.compute_flow` with its defaults (PX4FLOW's 25 blocks of
8x8, +/-4 px), compiled by the bench where a C compiler is present.

    python bench/bench_flow_psadbw.py     # compiles, checks it against compute_flow, prints the rates
                                          # (the C-peer table of bench_flow.py alone, ~30 s, and the
                                          # C extension's block matching alone against the peer's)

``psadbw`` (``_mm_sad_epu8``) sums the absolute differences of 8 byte pairs in one instruction, so an
8x8 block's SAD at one offset is 4 instructions on two-row registers: the firmware's own trick on its
Cortex-M4 (``USADA8``, 4 pairs an instruction). The C code works frame pair by frame pair in the
frames' natural layout (no transpose) and is compiled ``-O3 -march=native``.

:func:`c_flow` returns the frame flow (NaN where not valid), the used-block count and the spread, which
the bench compares with :func:`compute_flow`'s before timing (identical flow: the same integer SADs,
the same double-precision fit and aggregation).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

C_SOURCE = r"""
#include <emmintrin.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define W 64
#define S 4
#define SIDE (2 * S + 1)
#define NB 25
#define BIG 65535

static const int ORIG[5] = {5, 15, 25, 35, 45};   /* block_origins(FlowConfig()) */

/* SAD of the 8x8 block whose two-row registers are ref[0..3] against curr at c (row stride W) */
static inline int sad8(const __m128i ref[4], const uint8_t *c) {
    __m128i acc = _mm_setzero_si128();
    for (int r = 0; r < 4; r++) {
        __m128i b = _mm_unpacklo_epi64(_mm_loadl_epi64((const __m128i *)(c + 2 * r * W)),
                                       _mm_loadl_epi64((const __m128i *)(c + (2 * r + 1) * W)));
        acc = _mm_add_epi32(acc, _mm_sad_epu8(ref[r], b));
    }
    return _mm_cvtsi128_si32(acc) + _mm_extract_epi16(acc, 4);
}

/* SAD and argmin only (eq. 1): best offset index per block */
void sad_argmin(const uint8_t *prev, const uint8_t *curr, int n, int32_t *best_o) {
    for (int k = 0; k < n; k++) {
        const uint8_t *P = prev + (size_t)k * W * W, *C = curr + (size_t)k * W * W;
        for (int b = 0; b < NB; b++) {
            int y0 = ORIG[b / 5], x0 = ORIG[b % 5];
            __m128i ref[4];
            for (int r = 0; r < 4; r++)
                ref[r] = _mm_unpacklo_epi64(_mm_loadl_epi64((const __m128i *)(P + (y0 + 2 * r) * W + x0)),
                                            _mm_loadl_epi64((const __m128i *)(P + (y0 + 2 * r + 1) * W + x0)));
            int best = 1 << 30, bo = 0, o = 0;
            for (int dy = -S; dy <= S; dy++)
                for (int dx = -S; dx <= S; dx++, o++) {
                    int s = sad8(ref, C + (y0 + dy) * W + x0 + dx);
                    if (s < best) { best = s; bo = o; }
                }
            best_o[k * NB + b] = bo;
        }
    }
}

static double interp_v(double sm, double s0, double sp) {   /* equiangular: a symmetric V */
    double den = (sm > sp ? sm : sp) - s0;
    double d = den > 0 ? 0.5 * (sm - sp) / den : 0.0;
    return d > 0.5 ? 0.5 : (d < -0.5 ? -0.5 : d);
}

static double median(double *a, int m) {        /* insertion sort, as the numba kernel */
    for (int i = 1; i < m; i++) {
        double v = a[i]; int j = i - 1;
        while (j >= 0 && a[j] > v) { a[j + 1] = a[j]; j--; }
        a[j + 1] = v;
    }
    int h = m / 2;
    return m % 2 ? a[h] : 0.5 * (a[h - 1] + a[h]);
}

/* the whole default compute_flow: gate, SAD + argmin, second minimum, tests, equiangular fit,
   trimmed mean (1 px), spread gate (0.45 px), >= 10 blocks */
void flow(const uint8_t *prev, const uint8_t *curr, int n, double *out, int32_t *n_used, double *spread) {
    for (int k = 0; k < n; k++) {
        const uint8_t *P = prev + (size_t)k * W * W, *C = curr + (size_t)k * W * W;
        double fx[NB], fy[NB], sx[NB], sy[NB];
        int m = 0;
        for (int b = 0; b < NB; b++) {
            int y0 = ORIG[b / 5], x0 = ORIG[b % 5];
            int gate = 0;                       /* PX4FLOW compute_diff on the block's 4x4 centre */
            for (int r = 0; r < 3; r++)
                for (int c = 0; c < 4; c++)
                    gate += abs(P[(y0 + 2 + r) * W + x0 + 2 + c] - P[(y0 + 3 + r) * W + x0 + 2 + c])
                          + abs(P[(y0 + 2 + c) * W + x0 + 2 + r] - P[(y0 + 2 + c) * W + x0 + 3 + r]);
            if (gate < 30) continue;
            __m128i ref[4];
            for (int r = 0; r < 4; r++)
                ref[r] = _mm_unpacklo_epi64(_mm_loadl_epi64((const __m128i *)(P + (y0 + 2 * r) * W + x0)),
                                            _mm_loadl_epi64((const __m128i *)(P + (y0 + 2 * r + 1) * W + x0)));
            int sads[SIDE * SIDE], best = 1 << 30, bo = 0, o = 0;
            for (int dy = -S; dy <= S; dy++)
                for (int dx = -S; dx <= S; dx++, o++) {
                    int s = sad8(ref, C + (y0 + dy) * W + x0 + dx);
                    sads[o] = s;
                    if (s < best) { best = s; bo = o; }
                }
            if (best > 5000) continue;
            int oy = bo / SIDE, ox = bo % SIDE, second = BIG;
            for (int q = 0; q < SIDE * SIDE; q++) {
                int qy = q / SIDE, qx = q % SIDE;
                if (abs(qy - oy) <= 1 && abs(qx - ox) <= 1) continue;
                if (sads[q] < second) second = sads[q];
            }
            if (second < 1.25 * best || second == best) continue;
            double x = ox - S, y = oy - S;
            if (abs(ox - S) < S) x += interp_v(sads[bo - 1], best, sads[bo + 1]);
            if (abs(oy - S) < S) y += interp_v(sads[bo - SIDE], best, sads[bo + SIDE]);
            fx[m] = x; fy[m] = y; sx[m] = x; sy[m] = y; m++;
        }
        out[2 * k] = out[2 * k + 1] = NAN;
        n_used[k] = 0;
        spread[k] = NAN;
        if (m == 0) continue;
        double mx = median(sx, m), my = median(sy, m), ax = 0, ay = 0;
        int cnt = 0;
        for (int i = 0; i < m; i++)
            if ((fx[i] - mx) * (fx[i] - mx) + (fy[i] - my) * (fy[i] - my) <= 1.0) { ax += fx[i]; ay += fy[i]; cnt++; }
        if (cnt == 0) continue;
        ax /= cnt; ay /= cnt;
        double ss = 0;
        for (int i = 0; i < m; i++) {
            double d2 = (fx[i] - mx) * (fx[i] - mx) + (fy[i] - my) * (fy[i] - my);
            if (d2 <= 1.0) ss += (fx[i] - ax) * (fx[i] - ax) + (fy[i] - ay) * (fy[i] - ay);
        }
        double sp = sqrt(ss / cnt);
        n_used[k] = cnt;
        spread[k] = sp;
        if (cnt >= 10 && !(sp > 0.45)) { out[2 * k] = ax; out[2 * k + 1] = ay; }
    }
}
"""


def compiler() -> str | None:
    """The C compiler the bench uses (``$CC``, else cc / gcc / clang on the PATH), or None."""
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return cc
    return None


def load() -> ctypes.CDLL | None:
    """Compile :data:`C_SOURCE` into a temporary shared library and load it; None without a compiler."""
    cc = compiler()
    if cc is None:
        return None
    d = Path(tempfile.mkdtemp(prefix="robocal-psadbw-"))
    src, lib = d / "psadbw.c", d / "psadbw.so"
    src.write_text(C_SOURCE)
    subprocess.run([cc, "-O3", "-march=native", "-shared", "-fPIC", "-o", str(lib), str(src), "-lm"], check=True)
    so = ctypes.CDLL(str(lib))
    u8, i32, f64 = (np.ctypeslib.ndpointer(t, flags="C_CONTIGUOUS") for t in (np.uint8, np.int32, np.float64))
    so.sad_argmin.argtypes = [u8, u8, ctypes.c_int, i32]
    so.flow.argtypes = [u8, u8, ctypes.c_int, f64, i32, f64]
    return so


def c_flow(so, prev, curr):
    """The C kernel's frame flow ``(N, 2)`` px (NaN where not valid), used blocks ``(N,)``, spread ``(N,)`` px."""
    n = len(prev)
    out, used, spread = np.empty((n, 2)), np.empty(n, np.int32), np.empty(n)
    so.flow(np.ascontiguousarray(prev), np.ascontiguousarray(curr), n, out, used, spread)
    return out, used, spread


def c_sad_argmin(so, prev, curr, best):
    so.sad_argmin(prev, curr, len(prev), best)


def kernel_alone(prev, curr, rounds=15):
    """The C extension's block matching alone (``_flowc.match``: SAD, best and second minimum, texture gate,
    tests, equiangular fit; no aggregation, no Python per pair), one call on one thread, against the C peer's
    SAD + argmin on the same pairs: interleaved rounds, the least time of each. Issue 16's kernel goal was
    >= ~250k pairs/s on one thread."""
    import time

    import robocal.rigs.flow.kernel as K

    so, mod = load(), K._flowc()
    if so is None or mod is None:
        return "kernel alone: no C compiler or no C extension: not measured"
    cfg = K.FlowConfig()
    o1 = K.block_origins(cfg)
    ys, xs = np.repeat(o1, 5).astype(np.int64), np.tile(o1, 5).astype(np.int64)
    prev, curr = np.ascontiguousarray(prev), np.ascontiguousarray(curr)
    n = len(prev)
    outs = [np.empty((n, 25, 2)), np.empty((n, 25), np.int8), np.empty((n, 25)), np.empty((n, 25)), np.empty((n, 25))]
    best_o = np.empty((n, 25), np.int32)
    args = (64, 8, 4, ys, xs, float(cfg.feature_threshold), float(cfg.sad_limit), float(cfg.min_distinctness),
            K.SUBPIXEL_MODES.index(cfg.subpixel))
    fns = {"ours": lambda: mod.match(prev, curr, 0, 0, n, *args, *outs), "c": lambda: c_sad_argmin(so, prev, curr, best_o)}
    t = dict.fromkeys(fns, np.inf)
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            t[k] = min(t[k], time.perf_counter() - t0)
    return (f"kernel alone, one thread, {n} gravel pairs, least of {rounds} interleaved rounds: "
            f"ours _flowc.match ({mod.SIMD}; SAD, selection, gate, tests, fit) {n / t['ours']:,.0f} pairs/s, "
            f"C SAD + argmin only {n / t['c']:,.0f} pairs/s: ours / C {t['c'] / t['ours']:.2f}")


if __name__ == "__main__":
    from bench_flow import c_peer

    import robocal.rigs.flow.kernel as K
    from robocal.rigs.flow.simulate import load_texture, shifted_pairs

    tex, _ = load_texture("gravel")
    prev, curr, _ = shifted_pairs(tex, 512, np.random.default_rng(0), binning=2)
    prev, curr = np.concatenate([prev] * 4), np.concatenate([curr] * 4)     # bench_flow.py's 2048 pairs
    o1 = K.block_origins(K.FlowConfig())
    ys, xs = np.repeat(o1, 5), np.tile(o1, 5)
    pt = np.ascontiguousarray(prev[:256].transpose(1, 2, 0))
    ct = np.ascontiguousarray(curr[:256].transpose(1, 2, 0))
    sads = np.empty((25, 81, 256), np.uint16)
    keys = np.empty((25, 256), np.int32)
    print(c_peer(prev, curr, (lambda: K._sad8_batch(pt, ct, 0, ys, xs, 4, sads, keys), 256)))
    print()
    print(kernel_alone(prev, curr))

