"""The flow kernel's compiled loops (numba, ``cache=True``): SAD block matching batched over frame
pairs (eq. 1 of Li, Guan and Chu 2017), sub-pixel refinement (eq. 2), Lucas-Kanade refinement, and
the per-frame aggregation of the blocks.

Frames are laid out pixel-major with the pairs innermost, so each absolute
difference is one SIMD lane and no Python loop touches a pixel or an offset
(see :mod:`.kernel` for the layout and the public API that calls these;
``bench/bench_flow.py`` for the speed). Every function here is private to the
kernel: its arguments are checked by the callers in :mod:`.kernel`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__: list[str] = ["CACHE"]


def _can_cache() -> bool:
    """Whether numba can keep this folder's compiled kernels between runs.

    numba stores them in the package's ``__pycache__``, else (a read-only install) in
    ``$NUMBA_CACHE_DIR`` or the user's cache folder (``~/.cache/numba``); with none of them
    writable, ``cache=True`` would fail on import. Then every process compiles the kernels it
    uses instead (seconds, once per process), which is slow but right. A stale cache cannot serve
    old code: numba's index holds this file's modification time and size, numba's version and
    the CPU, and the compiled functions call only functions of this file (a test checks).
    """
    from numba.core.caching import FunctionCache

    try:
        FunctionCache(_can_cache)       # tries numba's cache locators for this file, in numba's order
    except RuntimeError:
        return False
    return True


#: numba can store this folder's compiled kernels (:func:`_can_cache`)
CACHE = _can_cache()


@njit(cache=CACHE, fastmath=True, nogil=True)
def _sad8_batch(prev_t, curr_t, coff, ys, xs, search, out, keys):  # pragma: no cover - compiled
    """SAD (eq. 1) of every 8x8 block at every integer offset, for N pairs at once.

    prev_t, curr_t : uint8 (H, W, >= N) — pairs innermost (SIMD lanes); pair k is lane k of
    ``prev_t`` and lane ``k + coff`` of ``curr_t`` (a sequence passes one array twice, coff 1).
    The absolute difference of two bytes is taken in 8 bits (``max - min`` cannot wrap) and
    widened once, not both operands: 2 of the 7 vector instructions of a difference.
    out : uint16 (n_blocks, (2 search + 1)^2, N). 8x8x255 = 16320 fits uint16.
    keys : int32 (n_blocks, N) — ``min over offsets of (SAD << 10 | offset)``: the
    best offset and its SAD in one vectorisable min (ties keep the first offset in
    scan order, as the firmware's strict '<').
    Three horizontal offsets share each load of the reference block (10
    loads of ``curr`` serve 24 differences instead of 8).
    """
    n = out.shape[2]
    nb = ys.shape[0]
    side = 2 * search + 1
    n3 = side // 3
    # tells LLVM that k + coff >= 0: without it every lane index carries numba's negative-index
    # wrap-around test and the loop over the pairs is not vectorised (4x slower)
    coff = max(coff, 0)
    a0 = np.empty(n, np.uint16)
    a1 = np.empty(n, np.uint16)
    a2 = np.empty(n, np.uint16)
    for b in range(nb):
        y0 = ys[b]
        x0 = xs[b]
        kb = keys[b]
        for k in range(n):
            kb[k] = 0x7FFFFFFF
        for dy in range(-search, search + 1):
            orow = (dy + search) * side
            for j in range(n3):
                dx = -search + 3 * j
                a0[:] = 0
                a1[:] = 0
                a2[:] = 0
                for r in range(8):
                    pr = prev_t[y0 + r, x0:x0 + 8]
                    cr = curr_t[y0 + r + dy, x0 + dx:x0 + dx + 10]
                    for k in range(n):
                        s0 = np.uint16(0)
                        s1 = np.uint16(0)
                        s2 = np.uint16(0)
                        for c in range(8):
                            p = pr[c, k]
                            q0 = cr[c, k + coff]
                            q1 = cr[c + 1, k + coff]
                            q2 = cr[c + 2, k + coff]
                            s0 += np.uint16(np.uint8(max(p, q0) - min(p, q0)))
                            s1 += np.uint16(np.uint8(max(p, q1) - min(p, q1)))
                            s2 += np.uint16(np.uint8(max(p, q2) - min(p, q2)))
                        a0[k] += s0
                        a1[k] += s1
                        a2[k] += s2
                o = orow + 3 * j
                for k in range(n):
                    out[b, o, k] = a0[k]
                    out[b, o + 1, k] = a1[k]
                    out[b, o + 2, k] = a2[k]
                    m = min((np.int32(a0[k]) << 10) | o, (np.int32(a1[k]) << 10) | (o + 1))
                    kb[k] = min(kb[k], min(m, (np.int32(a2[k]) << 10) | (o + 2)))
            for dx in range(-search + 3 * n3, search + 1):  # the remainder when 3 does not divide 2S+1
                a0[:] = 0
                for r in range(8):
                    pr = prev_t[y0 + r, x0:x0 + 8]
                    cr = curr_t[y0 + r + dy, x0 + dx:x0 + dx + 8]
                    for k in range(n):
                        s0 = np.uint16(0)
                        for c in range(8):
                            p = pr[c, k]
                            q0 = cr[c, k + coff]
                            s0 += np.uint16(np.uint8(max(p, q0) - min(p, q0)))
                        a0[k] += s0
                o = orow + dx + search
                for k in range(n):
                    out[b, o, k] = a0[k]
                    kb[k] = min(kb[k], (np.int32(a0[k]) << 10) | o)


@njit(cache=CACHE, fastmath=True, nogil=True)
def _sad_batch(prev_t, curr_t, coff, ys, xs, block, search, out, keys):  # pragma: no cover - compiled
    """Generic-block-size version of :func:`_sad8_batch` (uint32 sums; the same ``coff``)."""
    n = out.shape[2]
    nb = ys.shape[0]
    coff = max(coff, 0)  # k + coff >= 0: vectorisable (see _sad8_batch)
    acc = np.empty(n, np.uint32)
    for b in range(nb):
        y0 = ys[b]
        x0 = xs[b]
        kb = keys[b]
        for k in range(n):
            kb[k] = 0x7FFFFFFF
        o = 0
        for dy in range(-search, search + 1):
            for dx in range(-search, search + 1):
                acc[:] = 0
                for r in range(block):
                    pr = prev_t[y0 + r]
                    cr = curr_t[y0 + r + dy]
                    for c in range(block):
                        pc = pr[x0 + c]
                        cc = cr[x0 + dx + c]
                        for k in range(n):
                            p = pc[k]
                            q = cc[k + coff]
                            acc[k] += np.uint32(np.uint8(max(p, q) - min(p, q)))
                for k in range(n):
                    out[b, o, k] = acc[k]
                    kb[k] = min(kb[k], (np.int32(acc[k]) << 10) | o)
                o += 1


@njit(cache=CACHE, nogil=True, fastmath=True)
def _sad_frac(prev, curr, y0, x0, block, iy, ix, qy, qx, scale):  # pragma: no cover - compiled
    """SAD of a block against ``curr`` sampled at offset ``(ix + qx/scale, iy + qy/scale)``.

    Bilinear interpolation in exact integer arithmetic (Li, Guan and Chu 2017, eq. 2,
    ``g = A00 + A10 a + A01 b + A11 a b`` with ``a = qx/scale``,
    ``b = qy/scale``); ``qx, qy`` in ``0 .. scale-1``. Returns the SAD in
    grey levels (float).
    """
    wa = np.int32((scale - qx) * (scale - qy))
    wb = np.int32(qx * (scale - qy))
    wc = np.int32((scale - qx) * qy)
    wd = np.int32(qx * qy)
    s2 = np.int32(scale * scale)
    acc = np.int32(0)
    for r in range(block):
        # row views: the inner loop indexes them from 0 up, which lets LLVM vectorise it
        pr = prev[y0 + r, x0:x0 + block]
        c0 = curr[y0 + r + iy, x0 + ix:x0 + ix + block + 1]
        c1 = curr[y0 + r + iy + 1, x0 + ix:x0 + ix + block + 1]
        for c in range(block):
            g = (wa * np.int32(c0[c]) + wb * np.int32(c0[c + 1])
                 + wc * np.int32(c1[c]) + wd * np.int32(c1[c + 1]))
            acc += abs(s2 * np.int32(pr[c]) - g)
    return acc / s2


@njit(cache=CACHE, nogil=True)
def _refine_step(prev, curr, y0, x0, block, bx, by, best, step_q, scale):  # pragma: no cover - compiled
    """Try the 8 neighbours of ``(bx, by)`` (in 1/scale px units) at +/- step_q; keep the best."""
    nbx = bx
    nby = by
    for sy in range(-1, 2):
        for sx in range(-1, 2):
            if sx == 0 and sy == 0:
                continue
            cx = bx + sx * step_q
            cy = by + sy * step_q
            ix = cx // scale
            iy = cy // scale
            v = _sad_frac(prev, curr, y0, x0, block, iy, ix, cy - iy * scale, cx - ix * scale, scale)
            if v < best:
                best = v
                nbx = cx
                nby = cy
    return nbx, nby, best


@njit(cache=CACHE, fastmath=True, nogil=True)
def _select_lanes(prev_t, sads, keys, ys, xs, block, search, best, bo, second, gate, neigh, big):  # pragma: no cover
    """Per block and pair (lanes innermost): decode the best offset and its SAD from
    ``keys``, keep its 4 axis neighbours (for the sub-pixel fit), find the best SAD
    outside its 3x3 neighbourhood, and the texture gate (PX4FLOW compute_diff: row
    and column differences of the block's centre).

    The 3x3 neighbourhood is masked in ``sads`` (overwritten with ``big``) so that
    the second minimum is one plain vectorised min over the offsets.
    """
    n = best.shape[1]
    nb = ys.shape[0]
    side = 2 * search + 1
    q0 = block // 4
    qn = block // 2
    sec = np.empty(n, sads.dtype)
    for b in range(nb):
        kb = keys[b]
        for k in range(n):
            o = kb[k] & 1023
            bo[b, k] = o
            best[b, k] = kb[k] >> 10
            oy = o // side
            ox = o - oy * side
            neigh[b, k, 0] = sads[b, o - 1, k] if ox > 0 else big
            neigh[b, k, 1] = sads[b, o + 1, k] if ox < side - 1 else big
            neigh[b, k, 2] = sads[b, o - side, k] if oy > 0 else big
            neigh[b, k, 3] = sads[b, o + side, k] if oy < side - 1 else big
            for dy in range(max(oy - 1, 0), min(oy + 2, side)):
                for dx in range(max(ox - 1, 0), min(ox + 2, side)):
                    sads[b, dy * side + dx, k] = big
        for k in range(n):
            sec[k] = big
        for o in range(side * side):
            so = sads[b, o]
            for k in range(n):
                sec[k] = min(sec[k], so[k])
        for k in range(n):
            second[b, k] = sec[k]
        for k in range(n):
            gate[b, k] = 0
        y0 = ys[b] + q0
        x0 = xs[b] + q0
        for r in range(qn - 1):
            for c in range(qn):
                for k in range(n):
                    gate[b, k] += (abs(np.int32(prev_t[y0 + r, x0 + c, k]) - np.int32(prev_t[y0 + r + 1, x0 + c, k]))
                                   + abs(np.int32(prev_t[y0 + c, x0 + r, k]) - np.int32(prev_t[y0 + c, x0 + r + 1, k])))


@njit(cache=CACHE, nogil=True)
def _interp3(sm, s0, sp, mode):  # pragma: no cover - compiled
    """Sub-pixel offset of a minimum from three samples at -1, 0, +1 (clipped to +/-0.5)."""
    if mode == 3:
        den = sm - 2.0 * s0 + sp
        d = 0.5 * (sm - sp) / den if den > 0 else 0.0
    else:
        den = max(sm, sp) - s0
        d = 0.5 * (sm - sp) / den if den > 0 else 0.0
    return min(0.5, max(-0.5, d))


@njit(cache=CACHE, nogil=True)
def _refine_blocks(prev, curr, pidx, cidx, neigh, ys, xs, block, search, feat_thr, sad_thr, min_distinct, mode,
                   best, bo, second, gate, flow_b, status_b, sadmin_b, distinct_b):  # pragma: no cover
    """Per pair and block: accept/reject, then sub-pixel refinement of accepted blocks.

    prev/curr frames are ``prev[pidx[k]]``, ``curr[cidx[k]]`` (natural layout).
    status: 0 accepted, 1 no texture (gate), 2 SAD above threshold,
    3 ambiguous (flat SAD surface or a second minimum). mode: 0 none,
    1 half, 2 quarter, 3 parabolic.
    """
    n = pidx.shape[0]
    nb = ys.shape[0]
    side = 2 * search + 1
    for k in range(n):
        P = prev[pidx[k]]
        C = curr[cidx[k]]
        for b in range(nb):
            y0 = ys[b]
            x0 = xs[b]
            bv = best[b, k]
            o = bo[b, k]
            sv = second[b, k]
            bdy = o // side - search
            bdx = o % side - search
            sadmin_b[k, b] = bv
            distinct_b[k, b] = (sv - bv) / max(bv, 1)
            flow_b[k, b, 0] = np.nan
            flow_b[k, b, 1] = np.nan
            if gate[b, k] < feat_thr:
                status_b[k, b] = 1
                continue
            if bv > sad_thr:
                status_b[k, b] = 2
                continue
            if sv < (1.0 + min_distinct) * bv or sv == bv:
                status_b[k, b] = 3
                continue
            status_b[k, b] = 0
            fx = float(bdx)
            fy = float(bdy)
            if mode >= 3:
                # a parabola (mode 3) or a symmetric V (mode 4, "equiangular": the shape of a
                # SAD surface near its minimum) through the SAD values along each axis
                if abs(bdx) < search:
                    fx += _interp3(float(neigh[b, k, 0]), float(bv), float(neigh[b, k, 1]), mode)
                if abs(bdy) < search:
                    fy += _interp3(float(neigh[b, k, 2]), float(bv), float(neigh[b, k, 3]), mode)
            flow_b[k, b, 0] = fx
            flow_b[k, b, 1] = fy


@njit(cache=CACHE, nogil=True)
def _refine_bilinear(prev, curr, pidx, cidx, ys, xs, block, mode, status_b, flow_b):  # pragma: no cover
    """Half-pixel (mode 1, PX4FLOW) or half-then-quarter-pixel (mode 2) refinement of the
    accepted blocks with bilinear interpolation (eq. 2), starting from their integer offsets."""
    n = pidx.shape[0]
    nb = ys.shape[0]
    scale = 4
    for k in range(n):
        P = prev[pidx[k]]
        C = curr[cidx[k]]
        for b in range(nb):
            if status_b[k, b] != 0:
                continue
            y0 = ys[b]
            x0 = xs[b]
            qx = int(flow_b[k, b, 0]) * scale
            qy = int(flow_b[k, b, 1]) * scale
            fv = _sad_frac(P, C, y0, x0, block, qy // scale, qx // scale, 0, 0, scale)
            qx, qy, fv = _refine_step(P, C, y0, x0, block, qx, qy, fv, 2, scale)
            if mode == 2:
                qx, qy, fv = _refine_step(P, C, y0, x0, block, qx, qy, fv, 1, scale)
            flow_b[k, b, 0] = qx / scale
            flow_b[k, b, 1] = qy / scale


@njit(cache=CACHE, nogil=True)  # no fastmath: it would drop the NaN test below
def _lk_refine(prev, curr, ys, xs, block, search, used, flow, iters, max_step, out):  # pragma: no cover - compiled
    """Frame-level inverse-compositional Gauss–Newton refinement of a pure translation.

    Over the pixels of the used blocks, minimise ``sum (C(x + f) - P(x))^2``
    with ``C`` sampled bilinearly (eq. 2); the template gradient and the 2x2
    Hessian are computed once (inverse compositional). Starts at the block-matching flow; a frame
    whose refinement wanders more than ``max_step`` px from it keeps the
    block-matching value.
    """
    n = prev.shape[0]
    nb = ys.shape[0]
    for k in range(n):
        fx0 = flow[k, 0]
        fy0 = flow[k, 1]
        out[k, 0] = fx0
        out[k, 1] = fy0
        if np.isnan(fx0) or np.isnan(fy0):
            continue
        P = prev[k]
        C = curr[k]
        hxx = 0.0
        hxy = 0.0
        hyy = 0.0
        for b in range(nb):
            if not used[k, b]:
                continue
            for r in range(block):
                y = ys[b] + r
                for c in range(block):
                    x = xs[b] + c
                    gx = 0.5 * (float(P[y, x + 1]) - float(P[y, x - 1]))
                    gy = 0.5 * (float(P[y + 1, x]) - float(P[y - 1, x]))
                    hxx += gx * gx
                    hxy += gx * gy
                    hyy += gy * gy
        det = hxx * hyy - hxy * hxy
        if det <= 1e-9 * (hxx + hyy) ** 2 or det <= 0:
            continue
        fx = fx0
        fy = fy0
        ok = True
        for it in range(iters):
            ix = int(math.floor(fx))
            iy = int(math.floor(fy))
            a = fx - ix
            bb = fy - iy
            w00 = (1 - a) * (1 - bb)
            w10 = a * (1 - bb)
            w01 = (1 - a) * bb
            w11 = a * bb
            sx = 0.0
            sy = 0.0
            for b in range(nb):
                if not used[k, b]:
                    continue
                for r in range(block):
                    y = ys[b] + r
                    for c in range(block):
                        x = xs[b] + c
                        g = (w00 * float(C[y + iy, x + ix]) + w10 * float(C[y + iy, x + ix + 1])
                             + w01 * float(C[y + iy + 1, x + ix]) + w11 * float(C[y + iy + 1, x + ix + 1]))
                        e = g - float(P[y, x])
                        gx = 0.5 * (float(P[y, x + 1]) - float(P[y, x - 1]))
                        gy = 0.5 * (float(P[y + 1, x]) - float(P[y - 1, x]))
                        sx += gx * e
                        sy += gy * e
            dx = (hyy * sx - hxy * sy) / det
            dy = (hxx * sy - hxy * sx) / det
            fx -= dx
            fy -= dy
            # the frame margin of search + 1 px bounds where C may be sampled
            if abs(fx - fx0) > max_step or abs(fy - fy0) > max_step or abs(fx) >= search + 0.99 or abs(fy) >= search + 0.99:
                ok = False
                break
            if abs(dx) < 1e-3 and abs(dy) < 1e-3:
                break
        if ok:
            out[k, 0] = fx
            out[k, 1] = fy



@njit(cache=CACHE, nogil=True)
def _small_median(a, m):  # pragma: no cover - compiled
    """Median of ``a[:m]`` (m <= a few dozen) by insertion sort, in place (cheap to compile)."""
    for i in range(1, m):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v
    h = m // 2
    return a[h] if m % 2 == 1 else 0.5 * (a[h - 1] + a[h])


@njit(cache=CACHE, nogil=True)
def _aggregate_frames(flow, status, cen, mode, trim, used, out_flow, agreement, spread, centroid):  # pragma: no cover
    """Per frame: median of the accepted blocks, the blocks within ``trim`` of it, the frame's
    flow (mode 0 mean, 1 median, 2 trimmed mean), scatter and centroid of the used blocks."""
    n, nb = status.shape
    xs = np.empty(nb)
    ys = np.empty(nb)
    for k in range(n):
        m = 0
        for b in range(nb):
            if status[k, b] == 0:
                xs[m] = flow[k, b, 0]
                ys[m] = flow[k, b, 1]
                m += 1
        for b in range(nb):
            used[k, b] = False
        if m == 0:
            out_flow[k, 0] = np.nan
            out_flow[k, 1] = np.nan
            agreement[k] = 0.0
            spread[k] = np.nan
            centroid[k, 0] = 0.0
            centroid[k, 1] = 0.0
            continue
        mx = _small_median(xs, m)
        my = _small_median(ys, m)
        near = 0
        for b in range(nb):
            if status[k, b] == 0:
                d2 = (flow[k, b, 0] - mx) ** 2 + (flow[k, b, 1] - my) ** 2
                if d2 <= trim * trim:
                    near += 1
                    if mode == 2:
                        used[k, b] = True
                if mode != 2:
                    used[k, b] = True
        agreement[k] = near / m
        sx = 0.0
        sy = 0.0
        cx = 0.0
        cy = 0.0
        cnt = 0
        for b in range(nb):
            if used[k, b]:
                sx += flow[k, b, 0]
                sy += flow[k, b, 1]
                cx += cen[b, 0]
                cy += cen[b, 1]
                cnt += 1
        if cnt == 0:
            out_flow[k, 0] = np.nan
            out_flow[k, 1] = np.nan
            spread[k] = np.nan
            centroid[k, 0] = 0.0
            centroid[k, 1] = 0.0
            continue
        if mode == 1:
            fx = mx
            fy = my
        else:
            fx = sx / cnt
            fy = sy / cnt
        out_flow[k, 0] = fx
        out_flow[k, 1] = fy
        centroid[k, 0] = cx / cnt
        centroid[k, 1] = cy / cnt
        ss = 0.0
        for b in range(nb):
            if used[k, b]:
                ss += (flow[k, b, 0] - fx) ** 2 + (flow[k, b, 1] - fy) ** 2
        spread[k] = math.sqrt(ss / cnt)


@njit(cache=CACHE, nogil=True)
def _tensor_combine(prev, used, bflow, ys, xs, block, reg, out):  # pragma: no cover - compiled
    """Per frame: the used blocks' flows weighted by their gradient structure tensors (central
    differences in ``prev``); ``out`` holds the trimmed mean on entry, the pull in the weakly
    determined direction (``reg`` times the mean eigenvalue)."""
    n, nb = used.shape
    for k in range(n):
        if not (out[k, 0] == out[k, 0]):
            continue
        s00 = 0.0
        s01 = 0.0
        s11 = 0.0
        r0 = 0.0
        r1 = 0.0
        for b in range(nb):
            if not used[k, b]:
                continue
            a = 0.0
            c = 0.0
            d = 0.0
            for y in range(ys[b], ys[b] + block):
                for x in range(xs[b], xs[b] + block):
                    gx = 0.5 * (float(prev[k, y, x + 1]) - float(prev[k, y, x - 1]))
                    gy = 0.5 * (float(prev[k, y + 1, x]) - float(prev[k, y - 1, x]))
                    a += gx * gx
                    c += gx * gy
                    d += gy * gy
            s00 += a
            s01 += c
            s11 += d
            r0 += a * bflow[k, b, 0] + c * bflow[k, b, 1]
            r1 += c * bflow[k, b, 0] + d * bflow[k, b, 1]
        lam = reg * 0.5 * (s00 + s11)
        if lam <= 0.0:
            continue
        s00 += lam
        s11 += lam
        r0 += lam * out[k, 0]
        r1 += lam * out[k, 1]
        det = s00 * s11 - s01 * s01
        out[k, 0] = (s11 * r0 - s01 * r1) / det
        out[k, 1] = (s00 * r1 - s01 * r0) / det

