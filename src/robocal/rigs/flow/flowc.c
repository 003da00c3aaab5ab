/* robocal.rigs.flow._flowc: the flow kernel's default path in C (built by setuptools at install time,
 * optional: without a compiler the numba kernel of kernel_compiled.py runs instead).
 *
 * SAD block matching (Li, Guan and Chu 2017, eq. 1), the texture gate and acceptance tests, the
 * sub-pixel fit (equiangular / parabolic through the SAD surface, or bilinear half / quarter pixel,
 * eq. 2) and the per-frame aggregation of the blocks: the same arithmetic as the numba functions
 * _sad8_batch/_sad_batch + _select_lanes + _refine_blocks + _refine_bilinear and _aggregate_frames,
 * so the outputs are bit-identical (integer SADs; the fit and the aggregation in double precision,
 * in the same order, without contraction into fused multiply-adds: numba does not contract either).
 *
 * Frames stay in their natural layout (N, W, W) uint8, row-major: no transpose. The default search (8x8
 * blocks, +/-4 px) runs match_pairs8_avx2 where the CPU has AVX2 (mpsadbw: 8 offsets of a row an
 * instruction, the selection and the fit on vectors); otherwise an 8x8 block's SAD at one offset is 4 SSE2
 * psadbw on two-row registers where SSE2 is present (x86-64 always; compiled for AVX2 as well where GCC can
 * dispatch at load time), a plain C loop elsewhere. Every path gives the same bits. The Python side
 * (kernel.py) checks shapes and dtypes; the functions here check that every buffer is large enough for what
 * they read or write, and release the GIL while they compute.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

/* -DFLOWC_PORTABLE: the plain C path on x86 too (tests/rigs/flow/test_flow_kernel_c.py builds it so) */
#if !defined(FLOWC_PORTABLE) && (defined(__SSE2__) || defined(_M_X64) || (defined(_M_IX86_FP) && _M_IX86_FP >= 2))
#include <emmintrin.h>
#define FLOWC_SSE2 1
#define FLOWC_SIMD "sse2"
#else
#define FLOWC_SSE2 0
#define FLOWC_SIMD "portable"
#endif

/* GCC on x86-64 Linux: the pair loop is also compiled for AVX2 (3-operand VEX forms, no register copies;
 * 1.3-1.8x on this kernel) and the loader picks the copy the CPU runs (an ifunc), so the built module stays
 * portable to any x86-64. AVX2 brings no FMA: the arithmetic, and so the flow, is the same. */
#if FLOWC_SSE2 && !defined(FLOWC_NO_AVX2) && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) \
    && defined(__linux__) && defined(__GLIBC__)
#define FLOWC_CLONES __attribute__((target_clones("avx2", "default")))
#define FLOWC_INLINE static inline __attribute__((always_inline))   /* into each clone, compiled for its ISA */
#else
#define FLOWC_CLONES
#define FLOWC_INLINE static inline
#endif

/* The default 8x8 / +/-4 px search has its own AVX2 function (match_pairs8_avx2, mpsadbw), compiled with a
 * target attribute and called when the CPU has AVX2 (checked once at import): GCC or clang on x86-64.
 * -DFLOWC_NO_AVX2 leaves it and the AVX2 clones out (the SSE2 build the tests compare). */
#if FLOWC_SSE2 && !defined(FLOWC_NO_AVX2) && (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
#include <immintrin.h>
#define FLOWC_AVX2 1
#define FLOWC_TARGET_AVX2 __attribute__((target("avx2")))
static int flowc_have_avx2 = 0;       /* set by PyInit__flowc */
#else
#define FLOWC_AVX2 0
#endif

#define MAX_SEARCH 15                 /* FlowConfig allows search <= 15 */
#define MAX_SIDE (2 * MAX_SEARCH + 1)

typedef struct {
    int window, block, search, nb;
    const int64_t *ys, *xs;
    double feat_thr, sad_thr, min_distinct;
    int mode;                         /* 0 none, 1 half, 2 quarter, 3 parabolic, 4 equiangular */
} params_t;

/* ---- SAD of one block at every integer offset (eq. 1) ------------------------------------------ */

FLOWC_INLINE void sad_generic(const uint8_t *P, const uint8_t *C, const params_t *p, int y0, int x0, uint32_t *sads) {
    int W = p->window, B = p->block, S = p->search, o = 0;
    for (int dy = -S; dy <= S; dy++)
        for (int dx = -S; dx <= S; dx++, o++) {
            uint32_t acc = 0;
            for (int r = 0; r < B; r++) {
                const uint8_t *pr = P + (size_t)(y0 + r) * W + x0;
                const uint8_t *cr = C + (size_t)(y0 + r + dy) * W + x0 + dx;
                for (int c = 0; c < B; c++)
                    acc += (uint32_t)(pr[c] > cr[c] ? pr[c] - cr[c] : cr[c] - pr[c]);
            }
            sads[o] = acc;
        }
}

#if FLOWC_SSE2
/* 8x8 blocks: for each horizontal offset the 2S + 8 rows of the search window are loaded once and
 * paired into two-row registers (rows i, i + 1); the block's SAD at vertical offset dy is then 4
 * psadbw of its two-row registers against pairs dy + S, dy + S + 2, ... (no reload per offset). */
FLOWC_INLINE void sad8_sse2(const uint8_t *P, const uint8_t *C, int W, int S, int y0, int x0, uint32_t *sads) {
    int side = 2 * S + 1, nrow = 2 * S + 8;
    __m128i ref[4], rows[2 * MAX_SEARCH + 8], pairs[2 * MAX_SEARCH + 7];
    for (int r = 0; r < 4; r++)
        ref[r] = _mm_unpacklo_epi64(_mm_loadl_epi64((const __m128i *)(P + (size_t)(y0 + 2 * r) * W + x0)),
                                    _mm_loadl_epi64((const __m128i *)(P + (size_t)(y0 + 2 * r + 1) * W + x0)));
    for (int dx = -S; dx <= S; dx++) {
        const uint8_t *c0 = C + (size_t)(y0 - S) * W + x0 + dx;
        for (int i = 0; i < nrow; i++)
            rows[i] = _mm_loadl_epi64((const __m128i *)(c0 + (size_t)i * W));
        for (int i = 0; i < nrow - 1; i++)
            pairs[i] = _mm_unpacklo_epi64(rows[i], rows[i + 1]);
        for (int j = 0; j < side; j++) {  /* j = dy + S */
            __m128i acc = _mm_add_epi32(_mm_add_epi32(_mm_sad_epu8(ref[0], pairs[j]), _mm_sad_epu8(ref[1], pairs[j + 2])),
                                        _mm_add_epi32(_mm_sad_epu8(ref[2], pairs[j + 4]), _mm_sad_epu8(ref[3], pairs[j + 6])));
            /* each 64-bit half holds a sum <= 4 * 8 * 255 = 8160: fits its low 16 bits */
            sads[j * side + dx + S] = (uint32_t)(_mm_cvtsi128_si32(acc) + _mm_extract_epi16(acc, 4));
        }
    }
}
#endif

/* ---- bilinear sub-pixel SAD (eq. 2) and the 8-neighbour step, as kernel_compiled._sad_frac ------ */

FLOWC_INLINE double sad_frac(const uint8_t *P, const uint8_t *C, int W, int y0, int x0, int B, int iy, int ix,
                       int qy, int qx, int scale) {
    int64_t wa = (scale - qx) * (scale - qy), wb = qx * (scale - qy), wc = (scale - qx) * qy, wd = qx * qy;
    int64_t s2 = scale * scale, acc = 0;
    for (int r = 0; r < B; r++) {
        const uint8_t *pr = P + (size_t)(y0 + r) * W + x0;
        const uint8_t *c0 = C + (size_t)(y0 + r + iy) * W + x0 + ix;
        const uint8_t *c1 = c0 + W;
        for (int c = 0; c < B; c++) {
            int64_t g = wa * c0[c] + wb * c0[c + 1] + wc * c1[c] + wd * c1[c + 1];
            int64_t d = s2 * pr[c] - g;
            acc += d < 0 ? -d : d;
        }
    }
    return (double)acc / (double)s2;
}

static int64_t floordiv(int64_t a, int64_t b) {   /* Python's //, for negative offsets */
    int64_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

static void refine_step(const uint8_t *P, const uint8_t *C, int W, int y0, int x0, int B,
                        int64_t *bx, int64_t *by, double *best, int step_q, int scale) {
    int64_t nbx = *bx, nby = *by;
    for (int sy = -1; sy <= 1; sy++)
        for (int sx = -1; sx <= 1; sx++) {
            if (sx == 0 && sy == 0) continue;
            int64_t cx = *bx + sx * step_q, cy = *by + sy * step_q;
            int64_t ix = floordiv(cx, scale), iy = floordiv(cy, scale);
            double v = sad_frac(P, C, W, y0, x0, B, (int)iy, (int)ix, (int)(cy - iy * scale), (int)(cx - ix * scale), scale);
            if (v < *best) { *best = v; nbx = cx; nby = cy; }
        }
    *bx = nbx;
    *by = nby;
}

FLOWC_INLINE double interp3(double sm, double s0, double sp, int mode) {
    double den, d;
    if (mode == 3) {
        den = sm - 2.0 * s0 + sp;
    } else {
        den = (sm > sp ? sm : sp) - s0;
    }
    d = den > 0 ? 0.5 * (sm - sp) / den : 0.0;
    return d > 0.5 ? 0.5 : (d < -0.5 ? -0.5 : d);
}

/* ---- one block's outputs from its SAD surface: the tests (gate, SAD limit, distinctness) and the fit -------- */

/* bv: the least SAD at offset (bdx, bdy); sec: the least outside its 3x3; nl, nr, nu, nd: the SADs left, right,
 * above, below it ("big" outside the window); gate: the texture measure. Shared by both SAD paths. */
FLOWC_INLINE void finish_block(const uint8_t *P, const uint8_t *C, const params_t *p, const int B, const int S, int b,
                               int y0, int x0, uint32_t bv, uint32_t sec, int bdx, int bdy, uint32_t nl, uint32_t nr,
                               uint32_t nu, uint32_t nd, int32_t gate, double *flow, int8_t *status, double *sadmin,
                               double *distinct, double *texture) {
    int W = p->window;
    int32_t bvi = (int32_t)bv, svi = (int32_t)sec;   /* int32 as the numba kernel's arrays */
    texture[b] = (double)gate;
    sadmin[b] = (double)bvi;
    distinct[b] = (double)((int64_t)svi - bvi) / (double)(bvi > 1 ? bvi : 1);
    flow[2 * b] = NAN;
    flow[2 * b + 1] = NAN;
    if ((double)gate < p->feat_thr) { status[b] = 1; return; }
    if ((double)bvi > p->sad_thr) { status[b] = 2; return; }
    if ((double)svi < (1.0 + p->min_distinct) * (double)bvi || svi == bvi) { status[b] = 3; return; }
    status[b] = 0;
    double fx = (double)bdx, fy = (double)bdy;
    if (p->mode >= 3) {
        if (abs(bdx) < S) fx += interp3((double)nl, (double)bvi, (double)nr, p->mode);
        if (abs(bdy) < S) fy += interp3((double)nu, (double)bvi, (double)nd, p->mode);
    } else if (p->mode == 1 || p->mode == 2) {
        const int scale = 4;
        int64_t qx = (int64_t)bdx * scale, qy = (int64_t)bdy * scale;
        double fv = sad_frac(P, C, W, y0, x0, B, bdy, bdx, 0, 0, scale);
        refine_step(P, C, W, y0, x0, B, &qx, &qy, &fv, 2, scale);
        if (p->mode == 2) refine_step(P, C, W, y0, x0, B, &qx, &qy, &fv, 1, scale);
        fx = (double)qx / scale;
        fy = (double)qy / scale;
    }
    flow[2 * b] = fx;
    flow[2 * b + 1] = fy;
}

/* ---- one frame pair: every block's gate, SAD surface, tests and sub-pixel flow ----------------- */

/* B and S are arguments (not read from p) so that the call with the defaults' constants (8, 4) below is
 * compiled as a specialised copy: the search window's loops unrolled, its registers not spilled */
FLOWC_INLINE void match_pair_bs(const uint8_t *P, const uint8_t *C, const params_t *p, const int B, const int S,
                                 double *flow, int8_t *status, double *sadmin, double *distinct, double *texture) {
    int W = p->window, side = 2 * S + 1, no = side * side;
    int q0 = B / 4, qn = B / 2;
    /* the numba kernels' "big" (masked / missing) value: the SAD array's dtype maximum, stored as int32 */
    uint32_t big = B == 8 ? 65535u : 4294967295u;
    uint32_t sads[MAX_SIDE * MAX_SIDE];
    for (int b = 0; b < p->nb; b++) {
        int y0 = (int)p->ys[b], x0 = (int)p->xs[b];
#if FLOWC_SSE2
        if (B == 8)
            sad8_sse2(P, C, W, S, y0, x0, sads);
        else
#endif
            sad_generic(P, C, p, y0, x0, sads);
        /* best: the least SAD, the first in scan order on ties (the firmware's strict '<') */
        uint32_t bv = sads[0];
        int bo = 0;
        for (int o = 1; o < no; o++)
            if (sads[o] < bv) { bv = sads[o]; bo = o; }
        int oy = bo / side, ox = bo - oy * side;
        uint32_t nl = ox > 0 ? sads[bo - 1] : big, nr = ox < side - 1 ? sads[bo + 1] : big;
        uint32_t nu = oy > 0 ? sads[bo - side] : big, nd = oy < side - 1 ? sads[bo + side] : big;
        /* second: the least SAD outside the best's 3x3 neighbourhood */
        uint32_t sec = big;
        for (int qy = 0; qy < side; qy++) {
            if (qy >= oy - 1 && qy <= oy + 1) {
                for (int qx = 0; qx < side; qx++)
                    if ((qx < ox - 1 || qx > ox + 1) && sads[qy * side + qx] < sec) sec = sads[qy * side + qx];
            } else {
                for (int qx = 0; qx < side; qx++)
                    if (sads[qy * side + qx] < sec) sec = sads[qy * side + qx];
            }
        }
        /* PX4FLOW compute_diff: row and column differences of the block's centre */
        int32_t gate = 0;
        int gy = y0 + q0, gx = x0 + q0;
        for (int r = 0; r < qn - 1; r++)
            for (int c = 0; c < qn; c++)
                gate += abs((int)P[(size_t)(gy + r) * W + gx + c] - (int)P[(size_t)(gy + r + 1) * W + gx + c])
                      + abs((int)P[(size_t)(gy + c) * W + gx + r] - (int)P[(size_t)(gy + c) * W + gx + r + 1]);
        finish_block(P, C, p, B, S, b, y0, x0, bv, sec, ox - S, oy - S, nl, nr, nu, nd, gate, flow, status, sadmin,
                     distinct, texture);
    }
}

FLOWC_CLONES
static void match_pairs(const uint8_t *prev, const uint8_t *curr, Py_ssize_t n, const params_t *p, double *flow,
                        int8_t *status, double *sadmin, double *distinct, double *texture) {
    Py_ssize_t ww = (Py_ssize_t)p->window * p->window, nb = p->nb;
    for (Py_ssize_t k = 0; k < n; k++) {
        if (p->block == 8 && p->search == 4)      /* PX4FLOW's 8x8 blocks, +/-4 px: the default */
            match_pair_bs(prev + k * ww, curr + k * ww, p, 8, 4, flow + k * nb * 2, status + k * nb,
                          sadmin + k * nb, distinct + k * nb, texture + k * nb);
        else
            match_pair_bs(prev + k * ww, curr + k * ww, p, p->block, p->search, flow + k * nb * 2, status + k * nb,
                          sadmin + k * nb, distinct + k * nb, texture + k * nb);
    }
}

#if FLOWC_AVX2
/* ---- the default 8x8 / +/-4 px search with AVX2 mpsadbw ----------------------------------------------------
 *
 * vmpsadbw (Intel SDM, MPSADBW) gives 8 SADs of one 4-byte group at 8 consecutive byte offsets, per 128-bit lane.
 * With a block row t (8 bytes, in both lanes) against the 16 bytes s of a search row from x0 - 4 (in both lanes),
 * the low lane sums |s[d + k] - t[k]|, k < 4, and the high lane |s[d + 4 + k] - t[4 + k]| (imm 0x28: a offset 4,
 * b group 1), d = 0..7: the two lanes added are the row's SADs at dx = d - 4 = -4..+3. Eight rows summed give the
 * block's SADs at those dx for one dy (at most 8 * 8 * 255 = 16,320: u16, no overflow); dx = +4 by vpsadbw on the
 * rows' high halves. 72 vmpsadbw and 18 vpsadbw a block where sad8_sse2 takes 324 psadbw (and 144 row loads and
 * 135 unpacks), and the 16 search rows are loaded once for every offset. The selection then works on vectors
 * (minpos per row, a masked minimum for the second), without the scalar loops' 81-step chains and branches.
 * Same integer SADs, the same selection rule, the same tests and fit: bit-identical to the other paths. */

#define FLOWC_CHUNK 32                /* blocks a pass (the default grid has 25) */

FLOWC_TARGET_AVX2
static inline uint64_t load64(const uint8_t *a) { uint64_t v; memcpy(&v, a, 8); return v; }

FLOWC_TARGET_AVX2
static inline uint32_t load32(const uint8_t *a) { uint32_t v; memcpy(&v, a, 4); return v; }

/* finish_block for the fits that read only the SAD surface (none, parabolic, equiangular), four blocks a vector:
 * the same operations in the same order on the same doubles (IEEE products and quotients are correctly rounded in
 * either form; no fused multiply-add), selections by compare and blend instead of branches (a block's status is
 * data: the branches mispredict on real frames), so the same bits. iv[i][b]: finish_block's integer inputs. */
FLOWC_TARGET_AVX2
static void finish_blocks_avx2(const params_t *p, int bn, int32_t iv[][FLOWC_CHUNK], double *flow, int8_t *status,
                               double *sadmin, double *distinct, double *texture) {
    const __m256d one = _mm256_set1_pd(1.0), half = _mm256_set1_pd(0.5), mhalf = _mm256_set1_pd(-0.5);
    const __m256d zero = _mm256_setzero_pd(), four = _mm256_set1_pd(4.0), sign = _mm256_set1_pd(-0.0);
    const __m256d feat = _mm256_set1_pd(p->feat_thr), sadt = _mm256_set1_pd(p->sad_thr);
    const __m256d dist = _mm256_set1_pd(1.0 + p->min_distinct);
    _Alignas(32) double out[6][FLOWC_CHUNK];       /* texture, least SAD, distinctness, fx, fy, status */
    for (int b = 0; b < bn; b += 4) {
#define IV(i) _mm256_cvtepi32_pd(_mm_load_si128((const __m128i *)(iv[i] + b)))
        const __m256d bv = IV(0), sv = IV(1), gate = IV(2), bdx = IV(3), bdy = IV(4);
        const __m256d s1 = _mm256_cmp_pd(gate, feat, _CMP_LT_OQ), s2 = _mm256_cmp_pd(bv, sadt, _CMP_GT_OQ);
        const __m256d s3 = _mm256_or_pd(_mm256_cmp_pd(sv, _mm256_mul_pd(dist, bv), _CMP_LT_OQ),
                                        _mm256_cmp_pd(sv, bv, _CMP_EQ_OQ));
        /* status: 1 no texture, else 2 the SAD over its limit, else 3 ambiguous, else 0 (finish_block's order) */
        const __m256d code = _mm256_blendv_pd(
            _mm256_blendv_pd(_mm256_blendv_pd(zero, _mm256_set1_pd(3.0), s3), _mm256_set1_pd(2.0), s2), one, s1);
        __m256d f[2] = {bdx, bdy};
        if (p->mode >= 3) {
            for (int a = 0; a < 2; a++) {         /* interp3 along x (left, right), then y (above, below) */
                const __m256d sm = IV(5 + 2 * a), sp = IV(6 + 2 * a);
                const __m256d den = p->mode == 3
                    ? _mm256_add_pd(_mm256_sub_pd(sm, _mm256_mul_pd(_mm256_set1_pd(2.0), bv)), sp)
                    : _mm256_sub_pd(_mm256_max_pd(sm, sp), bv);          /* max_pd(a, b) is a > b ? a : b */
                __m256d d = _mm256_div_pd(_mm256_mul_pd(half, _mm256_sub_pd(sm, sp)), den);
                d = _mm256_blendv_pd(zero, d, _mm256_cmp_pd(den, zero, _CMP_GT_OQ));
                d = _mm256_blendv_pd(d, half, _mm256_cmp_pd(d, half, _CMP_GT_OQ));
                d = _mm256_blendv_pd(d, mhalf, _mm256_cmp_pd(d, mhalf, _CMP_LT_OQ));
                /* the fit only where |offset| < S (at the window's edge a neighbour is missing): else + 0.0 */
                const __m256d inside = _mm256_cmp_pd(_mm256_andnot_pd(sign, f[a]), four, _CMP_LT_OQ);
                f[a] = _mm256_add_pd(f[a], _mm256_and_pd(d, inside));
            }
        }
        const __m256d rejected = _mm256_or_pd(_mm256_or_pd(s1, s2), s3), nan = _mm256_set1_pd(NAN);
        _mm256_store_pd(out[0] + b, gate);
        _mm256_store_pd(out[1] + b, bv);
        _mm256_store_pd(out[2] + b, _mm256_div_pd(_mm256_sub_pd(sv, bv), _mm256_max_pd(bv, one)));
        _mm256_store_pd(out[3] + b, _mm256_blendv_pd(f[0], nan, rejected));
        _mm256_store_pd(out[4] + b, _mm256_blendv_pd(f[1], nan, rejected));
        _mm256_store_pd(out[5] + b, code);
#undef IV
    }
    for (int b = 0; b < bn; b++) {
        texture[b] = out[0][b];
        sadmin[b] = out[1][b];
        distinct[b] = out[2][b];
        flow[2 * b] = out[3][b];
        flow[2 * b + 1] = out[4][b];
        status[b] = (int8_t)out[5][b];
    }
}

FLOWC_TARGET_AVX2
static void match_pairs8_avx2(const uint8_t *prev, const uint8_t *curr, Py_ssize_t n, const params_t *p,
                              double *flow, int8_t *status, double *sadmin, double *distinct, double *texture) {
    const int W = p->window, nb = p->nb;
    const Py_ssize_t ww = (Py_ssize_t)W * W;
    const __m128i lane = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
    /* per chunk of blocks, two passes: the SAD surfaces of every block (throughput-bound SIMD), then every
     * block's selection, tests and fit (short dependency chains, independent between blocks: the core
     * overlaps them, where one pass per block would wait on each block's chain in turn).
     * sbuf[block][16 * j + d]: the SAD at dy = j - 4, dx = d - 4 (d = 8 the psadbw column) */
    _Alignas(16) uint16_t sbuf[FLOWC_CHUNK * 9 * 16], ebuf[FLOWC_CHUNK * 8];
    uint32_t mpbuf[FLOWC_CHUNK * 9], e8buf[FLOWC_CHUNK];
    /* per block for the third pass: least SAD, second, gate, dx, dy, the SADs left, right, above, below */
    _Alignas(32) int32_t iv[9][FLOWC_CHUNK];
    memset(iv, 0, sizeof iv);   /* lanes past a chunk's last block compute on zeros or stale blocks, never stored */
    for (Py_ssize_t k = 0; k < n; k++) {
        const uint8_t *P = prev + k * ww, *C = curr + k * ww;
        double *fl = flow + k * nb * 2;
        int8_t *st = status + k * nb;
        double *sm = sadmin + k * nb, *di = distinct + k * nb, *tx = texture + k * nb;
        for (int b0 = 0; b0 < nb; b0 += FLOWC_CHUNK) {
            const int bn = nb - b0 < FLOWC_CHUNK ? nb - b0 : FLOWC_CHUNK;
            for (int b = 0; b < bn; b++) {
                const int y0 = (int)p->ys[b0 + b], x0 = (int)p->xs[b0 + b];
                const uint8_t *pb = P + (size_t)y0 * W + x0, *cb = C + (size_t)(y0 - 4) * W + x0 - 4;
                uint64_t tr[8];
                __m256i t[8];
                __m128i srow[16], hp[15];
                for (int r = 0; r < 8; r++) {
                    tr[r] = load64(pb + (size_t)r * W);
                    t[r] = _mm256_set1_epi64x((long long)tr[r]);
                }
                for (int i = 0; i < 16; i++) srow[i] = _mm_loadu_si128((const __m128i *)(cb + (size_t)i * W));
                uint16_t *s16 = sbuf + 16 * 9 * b;
                uint32_t *mp = mpbuf + 9 * b;
                for (int j = 0; j < 9; j++) {
                    /* the search rows broadcast straight from the frame (vbroadcasti128: a load, no shuffle) */
                    __m256i acc = _mm256_mpsadbw_epu8(
                        _mm256_broadcastsi128_si256(_mm_loadu_si128((const __m128i *)(cb + (size_t)j * W))), t[0], 0x28);
                    for (int r = 1; r < 8; r++)
                        acc = _mm256_add_epi16(acc, _mm256_mpsadbw_epu8(_mm256_broadcastsi128_si256(
                            _mm_loadu_si128((const __m128i *)(cb + (size_t)(j + r) * W))), t[r], 0x28));
                    __m128i v = _mm_add_epi16(_mm256_castsi256_si128(acc), _mm256_extracti128_si256(acc, 1));
                    _mm_store_si128((__m128i *)(s16 + 16 * j), v);
                    mp[j] = (uint32_t)_mm_cvtsi128_si32(_mm_minpos_epu16(v));   /* the first least of d = 0..7 */
                }
                /* dx = +4 (d = 8) for every dy at once: vpsadbw of four rows' high halves (H_i .. H_i+3) against
                 * four block rows gives one row's SAD a 64-bit lane (<= 2,040); four dy are packed into the 16-bit
                 * fields of those lanes and the lanes summed by 16-bit adds (a sum <= 16,320 never carries over) */
                for (int i = 0; i < 15; i++) hp[i] = _mm_unpackhi_epi64(srow[i], srow[i + 1]);
                const __m256i rq0 = _mm256_setr_epi64x((long long)tr[0], (long long)tr[1], (long long)tr[2], (long long)tr[3]);
                const __m256i rq1 = _mm256_setr_epi64x((long long)tr[4], (long long)tr[5], (long long)tr[6], (long long)tr[7]);
                __m256i z[9];
                for (int j = 0; j < 9; j++)
                    z[j] = _mm256_add_epi64(
                        _mm256_sad_epu8(_mm256_inserti128_si256(_mm256_castsi128_si256(hp[j]), hp[j + 2], 1), rq0),
                        _mm256_sad_epu8(_mm256_inserti128_si256(_mm256_castsi128_si256(hp[j + 4]), hp[j + 6], 1), rq1));
                __m256i za = _mm256_add_epi64(_mm256_add_epi64(z[0], _mm256_slli_epi64(z[1], 16)),
                                              _mm256_add_epi64(_mm256_slli_epi64(z[2], 32), _mm256_slli_epi64(z[3], 48)));
                __m256i zb = _mm256_add_epi64(_mm256_add_epi64(z[4], _mm256_slli_epi64(z[5], 16)),
                                              _mm256_add_epi64(_mm256_slli_epi64(z[6], 32), _mm256_slli_epi64(z[7], 48)));
                __m128i ea = _mm_add_epi16(_mm256_castsi256_si128(za), _mm256_extracti128_si256(za, 1));
                __m128i eb = _mm_add_epi16(_mm256_castsi256_si128(zb), _mm256_extracti128_si256(zb, 1));
                ea = _mm_add_epi16(ea, _mm_unpackhi_epi64(ea, ea));
                eb = _mm_add_epi16(eb, _mm_unpackhi_epi64(eb, eb));
                const __m128i ecol = _mm_unpacklo_epi64(ea, eb);           /* SADs at d = 8, dy rows 0..7 */
                __m128i e8v = _mm_add_epi64(_mm256_castsi256_si128(z[8]), _mm256_extracti128_si256(z[8], 1));
                e8buf[b] = (uint32_t)_mm_cvtsi128_si32(_mm_add_epi64(e8v, _mm_unpackhi_epi64(e8v, e8v)));
                _mm_store_si128((__m128i *)(ebuf + 8 * b), ecol);
            }
            for (int b = 0; b < bn; b++) {
                const int y0 = (int)p->ys[b0 + b], x0 = (int)p->xs[b0 + b];
                uint16_t *s16 = sbuf + 16 * 9 * b;
                const uint32_t *mp = mpbuf + 9 * b, e8 = e8buf[b];
                const __m128i ecol = _mm_load_si128((const __m128i *)(ebuf + 8 * b));
                /* best as one key: SAD << 8 | j << 4 | d, so the least key is the least SAD, the first in scan
                 * order (row j, then d) on ties: the firmware's strict '<' over the offsets in scan order */
                uint32_t bkey = 0xffffffffu;
                for (int j = 0; j < 9; j++) {
                    uint32_t e = j < 8 ? ebuf[8 * b + j] : e8;
                    s16[16 * j + 8] = (uint16_t)e;
                    uint32_t k1 = (mp[j] & 0xffffu) << 8 | (uint32_t)j << 4 | mp[j] >> 16, k2 = e << 8 | (uint32_t)j << 4 | 8u;
                    k1 = k1 < k2 ? k1 : k2;
                    bkey = k1 < bkey ? k1 : bkey;
                }
                const uint32_t bv = bkey >> 8;
                const int oy = (int)(bkey >> 4 & 15u), ox = (int)(bkey & 15u), bo = 16 * oy + ox;
                const uint32_t big = 65535u;
                uint32_t nl = ox > 0 ? s16[bo - 1] : big, nr = ox < 8 ? s16[bo + 1] : big;
                uint32_t nu = oy > 0 ? s16[bo - 16] : big, nd = oy < 8 ? s16[bo + 16] : big;
                /* second: the least SAD outside the best's 3x3: in rows oy - 1 .. oy + 1 the columns ox - 1 .. ox + 1
                 * are masked to big (the d = 8 column when ox >= 7), then one vector minimum, no branches */
                const __m128i cols = _mm_and_si128(_mm_cmpgt_epi16(lane, _mm_set1_epi16((short)(ox - 2))),
                                                   _mm_cmpgt_epi16(_mm_set1_epi16((short)(ox + 2)), lane));
                const __m128i rows = _mm_and_si128(_mm_cmpgt_epi16(lane, _mm_set1_epi16((short)(oy - 2))),
                                                   _mm_cmpgt_epi16(_mm_set1_epi16((short)(oy + 2)), lane));
                __m128i low = _mm_or_si128(ecol, _mm_and_si128(rows, _mm_set1_epi16((short)-(ox >= 7))));
                for (int j = 0; j < 9; j++) {
                    __m128i near = _mm_set1_epi16((short)-((unsigned)(j - oy + 1) <= 2u));
                    low = _mm_min_epu16(low, _mm_or_si128(_mm_load_si128((const __m128i *)(s16 + 16 * j)),
                                                          _mm_and_si128(cols, near)));
                }
                uint32_t sec = (uint32_t)_mm_cvtsi128_si32(_mm_minpos_epu16(low)) & 0xffffu;
                if (!(oy >= 7 && ox >= 7) && e8 < sec) sec = e8;
                /* PX4FLOW compute_diff on the 4x4 centre (rows gy..gy+3, bytes gx..gx+3): the differences down the
                 * columns (rows 0-2 against 1-3) and along the rows (bytes 0-2 against 1-3, byte 3 zeroed) by psadbw */
                const uint8_t *g = P + (size_t)(y0 + 2) * W + x0 + 2;
                int32_t r0 = (int32_t)load32(g), r1 = (int32_t)load32(g + W), r2 = (int32_t)load32(g + 2 * (size_t)W),
                        r3 = (int32_t)load32(g + 3 * (size_t)W);
                __m128i h = _mm_setr_epi32(r0, r1, r2, r3);
                __m128i gs = _mm_add_epi64(
                    _mm_sad_epu8(_mm_setr_epi32(r0, r1, r2, 0), _mm_setr_epi32(r1, r2, r3, 0)),
                    _mm_sad_epu8(_mm_and_si128(h, _mm_set1_epi32(0x00ffffff)), _mm_srli_epi32(h, 8)));
                int32_t gate = _mm_cvtsi128_si32(gs) + _mm_extract_epi16(gs, 4);
                if (p->mode == 1 || p->mode == 2) {     /* the bilinear fits read the frames: one block at a time */
                    finish_block(P, C, p, 8, 4, b, y0, x0, bv, sec, ox - 4, oy - 4, nl, nr, nu, nd, gate, fl + 2 * b0,
                                 st + b0, sm + b0, di + b0, tx + b0);
                    continue;
                }
                iv[0][b] = (int32_t)bv; iv[1][b] = (int32_t)sec; iv[2][b] = gate; iv[3][b] = ox - 4; iv[4][b] = oy - 4;
                iv[5][b] = (int32_t)nl; iv[6][b] = (int32_t)nr; iv[7][b] = (int32_t)nu; iv[8][b] = (int32_t)nd;
            }
            if (p->mode != 1 && p->mode != 2)
                finish_blocks_avx2(p, bn, iv, fl + 2 * b0, st + b0, sm + b0, di + b0, tx + b0);
        }
    }
}
#endif

static int need(Py_buffer *b, Py_ssize_t nbytes, const char *name) {
    if (b->len < nbytes) {
        PyErr_Format(PyExc_ValueError, "_flowc: %s holds %zd bytes, expected at least %zd", name, b->len, nbytes);
        return 0;
    }
    return 1;
}

PyDoc_STRVAR(match_doc,
"match(prev, curr, p0, c0, n, window, block, search, ys, xs, feat_thr, sad_thr, min_distinct, mode,\n"
"      flow, status, sad_min, distinct, texture)\n\n"
"Block matching of the pairs (prev[p0 + k], curr[c0 + k]), k < n: uint8 frames (.., window, window);\n"
"ys, xs int64 (n_blocks,) block origins; outputs flow f64 (n, nb, 2), status int8 (n, nb), sad_min,\n"
"distinct, texture f64 (n, nb) (see kernel.BlockMatches).");

static PyObject *flowc_match(PyObject *self, PyObject *args) {
    Py_buffer prev, curr, ys, xs, flow, status, sadmin, distinct, texture;
    Py_ssize_t p0, c0, n;
    params_t p;
    if (!PyArg_ParseTuple(args, "y*y*nnniiiy*y*dddiw*w*w*w*w*", &prev, &curr, &p0, &c0, &n, &p.window, &p.block,
                          &p.search, &ys, &xs, &p.feat_thr, &p.sad_thr, &p.min_distinct, &p.mode,
                          &flow, &status, &sadmin, &distinct, &texture))
        return NULL;
    PyObject *ret = NULL;
    p.nb = (int)(ys.len / (Py_ssize_t)sizeof(int64_t));
    p.ys = (const int64_t *)ys.buf;
    p.xs = (const int64_t *)xs.buf;
    Py_ssize_t ww = (Py_ssize_t)p.window * p.window, nb = p.nb;
    if (p.search < 1 || p.search > MAX_SEARCH || p.block < 4 || p0 < 0 || c0 < 0 || n < 0 || p.window < 1) {
        PyErr_SetString(PyExc_ValueError, "_flowc.match: search must be 1..15, block >= 4, indices >= 0");
        goto done;
    }
    if (!need(&xs, nb * 8, "xs") || !need(&prev, (p0 + n) * ww, "prev") || !need(&curr, (c0 + n) * ww, "curr")
        || !need(&flow, n * nb * 16, "flow") || !need(&status, n * nb, "status") || !need(&sadmin, n * nb * 8, "sad_min")
        || !need(&distinct, n * nb * 8, "distinct") || !need(&texture, n * nb * 8, "texture"))
        goto done;
    for (Py_ssize_t b = 0; b < nb; b++) {   /* every candidate and its bilinear neighbour inside the frame */
        if (p.ys[b] - p.search < 0 || p.xs[b] - p.search < 0 || p.ys[b] + p.block + p.search + 1 > p.window
            || p.xs[b] + p.block + p.search + 1 > p.window) {
            PyErr_Format(PyExc_ValueError, "_flowc.match: block %zd at (%lld, %lld) with search %d leaves the frame",
                         b, (long long)p.ys[b], (long long)p.xs[b], p.search);
            goto done;
        }
    }
    Py_BEGIN_ALLOW_THREADS
#if FLOWC_AVX2
    if (flowc_have_avx2 && p.block == 8 && p.search == 4)
        match_pairs8_avx2((const uint8_t *)prev.buf + p0 * ww, (const uint8_t *)curr.buf + c0 * ww, n, &p,
                          (double *)flow.buf, (int8_t *)status.buf, (double *)sadmin.buf, (double *)distinct.buf,
                          (double *)texture.buf);
    else
#endif
    match_pairs((const uint8_t *)prev.buf + p0 * ww, (const uint8_t *)curr.buf + c0 * ww, n, &p, (double *)flow.buf,
                (int8_t *)status.buf, (double *)sadmin.buf, (double *)distinct.buf, (double *)texture.buf);
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&prev); PyBuffer_Release(&curr); PyBuffer_Release(&ys); PyBuffer_Release(&xs);
    PyBuffer_Release(&flow); PyBuffer_Release(&status); PyBuffer_Release(&sadmin);
    PyBuffer_Release(&distinct); PyBuffer_Release(&texture);
    return ret;
}

/* ---- per frame: the blocks' median, the trimmed set, the frame's flow, spread and centroid ------- */

/* The median of a[:m] as kernel_compiled._small_median computes it: the values an insertion sort (stable: equal
 * values keep their order) leaves at m / 2 and m / 2 - 1, found by rank instead of by sorting. Element i lands
 * at the count of the elements before it that are <= a[i] plus those after it that are < a[i]: the stable
 * sort's position exactly (-0.0 and 0.0 compare equal in both), so the same bits; the counts are branch-free
 * (the sort's moves mispredicted on real flows: it was ~80 % of the aggregation). A NaN (no accepted flow is
 * one) would break the ranks: then the sort itself. */
FLOWC_INLINE double small_median(double *a, int m) {
    int h = m / 2, nan = 0;
    double lo = 0.0, hi = 0.0;
    for (int i = 0; i < m; i++) {
        const double v = a[i];
        int r = 0;
        for (int j = 0; j < i; j++) r += a[j] <= v;
        for (int j = i + 1; j < m; j++) r += a[j] < v;
        nan |= v != v;
        if (r == h) hi = v;
        if (r == h - 1) lo = v;
    }
    if (!nan) return m % 2 == 1 ? hi : 0.5 * (lo + hi);
    for (int i = 1; i < m; i++) {
        double v = a[i];
        int j = i - 1;
        while (j >= 0 && a[j] > v) { a[j + 1] = a[j]; j--; }
        a[j + 1] = v;
    }
    return m % 2 == 1 ? a[h] : 0.5 * (a[h - 1] + a[h]);
}

FLOWC_INLINE void aggregate_frame(const double *flow, const int8_t *status, const double *cen, int nb, int mode,
                            double trim, uint8_t *used, double *out_flow, double *agreement, double *spread,
                            double *centroid, double *xs, double *ys) {
    int m = 0;
    for (int b = 0; b < nb; b++)
        if (status[b] == 0) { xs[m] = flow[2 * b]; ys[m] = flow[2 * b + 1]; m++; }
    for (int b = 0; b < nb; b++) used[b] = 0;
    if (m == 0) {
        out_flow[0] = out_flow[1] = NAN;
        *agreement = 0.0;
        *spread = NAN;
        centroid[0] = centroid[1] = 0.0;
        return;
    }
    double mx = small_median(xs, m), my = small_median(ys, m);
    int near = 0;
    for (int b = 0; b < nb; b++) {
        if (status[b] == 0) {
            double ex = flow[2 * b] - mx, ey = flow[2 * b + 1] - my;
            double d2 = ex * ex + ey * ey;
            if (d2 <= trim * trim) {
                near++;
                if (mode == 2) used[b] = 1;
            }
            if (mode != 2) used[b] = 1;
        }
    }
    *agreement = (double)near / (double)m;
    double sx = 0.0, sy = 0.0, cx = 0.0, cy = 0.0;
    int cnt = 0;
    for (int b = 0; b < nb; b++)
        if (used[b]) { sx += flow[2 * b]; sy += flow[2 * b + 1]; cx += cen[2 * b]; cy += cen[2 * b + 1]; cnt++; }
    if (cnt == 0) {
        out_flow[0] = out_flow[1] = NAN;
        *spread = NAN;
        centroid[0] = centroid[1] = 0.0;
        return;
    }
    double fx, fy;
    if (mode == 1) { fx = mx; fy = my; }
    else { fx = sx / cnt; fy = sy / cnt; }
    out_flow[0] = fx;
    out_flow[1] = fy;
    centroid[0] = cx / cnt;
    centroid[1] = cy / cnt;
    double ss = 0.0;
    for (int b = 0; b < nb; b++)
        if (used[b]) {
            double ex = flow[2 * b] - fx, ey = flow[2 * b + 1] - fy;
            ss += ex * ex + ey * ey;
        }
    *spread = sqrt(ss / cnt);
}

FLOWC_CLONES   /* the median's rank counts vectorise in the AVX2 copy */
static void aggregate_frames(const double *flow, const int8_t *status, const double *cen, Py_ssize_t n, int nb,
                             int mode, double trim, uint8_t *used, double *out_flow, double *agreement,
                             double *spread, double *centroid, double *tmp) {
    for (Py_ssize_t k = 0; k < n; k++)
        aggregate_frame(flow + k * nb * 2, status + k * nb, cen, nb, mode, trim, used + k * nb, out_flow + 2 * k,
                        agreement + k, spread + k, centroid + 2 * k, tmp, tmp + nb);
}

PyDoc_STRVAR(aggregate_doc,
"aggregate(flow, status, cen, n, nb, mode, trim, used, out_flow, agreement, spread, centroid)\n\n"
"Per frame: flow f64 (n, nb, 2), status int8 (n, nb), cen f64 (nb, 2); mode 0 mean, 1 median,\n"
"2 trimmed mean; outputs used bool (n, nb), out_flow f64 (n, 2), agreement, spread f64 (n,),\n"
"centroid f64 (n, 2) (see kernel._aggregate).");

static PyObject *flowc_aggregate(PyObject *self, PyObject *args) {
    Py_buffer flow, status, cen, used, out_flow, agreement, spread, centroid;
    Py_ssize_t n;
    int nb, mode;
    double trim;
    if (!PyArg_ParseTuple(args, "y*y*y*niidw*w*w*w*w*", &flow, &status, &cen, &n, &nb, &mode, &trim, &used,
                          &out_flow, &agreement, &spread, &centroid))
        return NULL;
    PyObject *ret = NULL;
    double *tmp = NULL;
    if (n < 0 || nb < 0) {
        PyErr_SetString(PyExc_ValueError, "_flowc.aggregate: n and nb must be >= 0");
        goto done;
    }
    if (!need(&flow, n * nb * 16, "flow") || !need(&status, n * nb, "status") || !need(&cen, (Py_ssize_t)nb * 16, "cen")
        || !need(&used, n * nb, "used") || !need(&out_flow, n * 16, "out_flow") || !need(&agreement, n * 8, "agreement")
        || !need(&spread, n * 8, "spread") || !need(&centroid, n * 16, "centroid"))
        goto done;
    tmp = (double *)PyMem_Malloc(sizeof(double) * 2 * (size_t)(nb > 0 ? nb : 1));
    if (tmp == NULL) { PyErr_NoMemory(); goto done; }
    Py_BEGIN_ALLOW_THREADS
    aggregate_frames((const double *)flow.buf, (const int8_t *)status.buf, (const double *)cen.buf, n, nb, mode,
                     trim, (uint8_t *)used.buf, (double *)out_flow.buf, (double *)agreement.buf, (double *)spread.buf,
                     (double *)centroid.buf, tmp);
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyMem_Free(tmp);
    PyBuffer_Release(&flow); PyBuffer_Release(&status); PyBuffer_Release(&cen); PyBuffer_Release(&used);
    PyBuffer_Release(&out_flow); PyBuffer_Release(&agreement); PyBuffer_Release(&spread); PyBuffer_Release(&centroid);
    return ret;
}

static PyMethodDef methods[] = {
    {"match", flowc_match, METH_VARARGS, match_doc},
    {"aggregate", flowc_aggregate, METH_VARARGS, aggregate_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_flowc",
    "The flow kernel's default path in C (block matching, sub-pixel fit, aggregation); see kernel.py.", -1, methods,
};

PyMODINIT_FUNC PyInit__flowc(void) {
    PyObject *m = PyModule_Create(&module);
    const char *simd = FLOWC_SIMD;
#if FLOWC_AVX2
    __builtin_cpu_init();
    flowc_have_avx2 = __builtin_cpu_supports("avx2");
    if (flowc_have_avx2) simd = "avx2";    /* match_pairs8_avx2 on the default path, the AVX2 clone elsewhere */
#endif
    if (m != NULL && PyModule_AddStringConstant(m, "SIMD", simd) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
