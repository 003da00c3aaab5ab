"""Frame-quality gates of the flow kernel on the simulator's textures: how many wrong frames
get accepted, and how many good frames get rejected (docs/rigs/flow.md, "spread gate").

    python bench/bench_flow_gate.py       # about 30 s

A frame is *wrong* when its (gyro-compensated) flow is more than 0.5 px from the truth,
*good* when the kernel reads it within 0.5 px (whatever its gates say). Two sets, 4
textures each: rendered 2 s loop drives (3 sensors, 0.4 and 0.8 m/s, seeds 1 and 2,
supersample 1; truth = the simulator's sensor motion) and 600 independently shifted
frame pairs (shifts up to 4 px, seeds 1 and 2). Candidates (the first two measured and not
adopted, the third available as ``FlowConfig(aggregate="tensor")``):

* ``SE gate``: a per-frame limit on the standard error of the used blocks,
  ``spread / sqrt(n_used)``, on top of the default 0.45 px spread gate;
* ``temporal gate``: after fusion, drop a sensor-step whose displacement is more than
  ``k`` sigma from the one predicted by the centred running median (+/-W steps) of the
  fused twist (a speed-aware prediction from the fused velocity), then fuse again;
* ``aggregate="tensor"``: the same blocks, combined by their gradient structure tensors
  (a block that sees only an edge no longer pulls the frame's flow along that edge).

Set ``ROBOCAL_TENSOR_REG`` to try another regularisation of the tensor combination.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import warnings  # noqa: E402

import numpy as np  # noqa: E402

from robocal.rigs.flow.evaluate import evaluate_trajectory  # noqa: E402
from robocal.rigs.flow.kernel import FlowConfig, compute_flow, compute_flow_sequence  # noqa: E402
from robocal.rigs.flow.log import steps_from_frames  # noqa: E402
from robocal.rigs.flow.model import rot2  # noqa: E402
from robocal.rigs.flow.odometry import SensorSteps, dead_reckon  # noqa: E402
from robocal.rigs.flow.simulate import load_texture, shifted_pairs, simulate_run  # noqa: E402
from robocal.rigs.flow.workflow import default_sim  # noqa: E402

TEXTURES = ("brick", "gravel", "grass", "moon")
DRIVES = [(v, s) for v in (0.4, 0.8) for s in (1, 2)]


def drive(texture, speed, seed, duration=2.0):
    """A rendered loop and each sensor's true image flow (px per frame, after gyro compensation)."""
    sim = default_sim("loop", duration, supersample=1, texture=texture, speed=speed)
    run = simulate_run(sim, np.random.default_rng(seed))
    tr, th, f = sim.array_true, run.poses[:, 2], sim.camera.focal_px
    truth = []
    for i in range(tr.n):
        p = run.poses[:, :2] + np.einsum("kab,b->ka", rot2(th), tr.positions[i])
        d = np.einsum("kba,kb->ka", rot2(th[1:] + tr.phi[i]), np.diff(p, axis=0))
        truth.append(np.stack([-d[:, 0] * f / run.true_height[i], d[:, 1] * f / run.true_height[i]], 1))
    return run, sim, truth


def kernel_frames(aggregate="trimmed"):
    """Per frame: texture, set (0 drive, 1 pairs), n_used, spread, error; every gate but the spread one on."""
    cfg = FlowConfig(max_spread_px=np.inf, aggregate=aggregate)
    rows = []
    for ti, tex in enumerate(TEXTURES):
        for speed, seed in DRIVES:
            run, sim, truth = drive(tex, speed, seed)
            dt = np.diff(run.t)
            for i in range(3):
                ff = compute_flow_sequence(run.frames[i], cfg, gyro=run.gyro[i], dt=dt, height=run.height[i],
                                           focal_px=sim.camera.focal_px)
                err = np.where(ff.valid, np.hypot(*(ff.flow_comp_px - truth[i]).T), np.nan)
                rows.append(np.stack([np.full(err.size, ti), np.zeros(err.size), np.round(ff.quality / 255 * 25),
                                      ff.spread_px, err], 1))
        for seed in (1, 2):
            p, c, t = shifted_pairs(load_texture(tex)[0], 300, np.random.default_rng(seed), binning=2, max_shift=4.0)
            r = compute_flow(p, c, cfg)
            err = np.where(r.valid, np.hypot(*(r.flow_px - t).T), np.nan)
            rows.append(np.stack([np.full(err.size, ti), np.ones(err.size), np.round(r.quality / 255 * 25), r.spread_px, err], 1))
    return np.concatenate(rows)


def kernel_table(d, d_tensor):
    tex, kind, nu, spread, err = d.T
    good, wrong = err <= 0.5, err > 0.5
    gates = {"spread <= 0.45 px (default)": (spread <= 0.45, err), "spread <= 0.35 px": (spread <= 0.35, err)}
    for c in (0.09, 0.1, 0.11):
        gates[f"default + SE <= {c} px"] = ((spread <= 0.45) & (spread / np.sqrt(np.maximum(nu, 1)) <= c), err)
    gates["aggregate=tensor, spread <= 0.45 px"] = (d_tensor[:, 3] <= 0.45, d_tensor[:, 4])
    print("Kernel gates: wrong frames among the accepted ones / good frames rejected (drives | shifted pairs); "
          "RMS error of the accepted frames, px\n")
    print("| gate | " + " | ".join(TEXTURES) + " |")
    print("|---|" + "---:|" * len(TEXTURES))
    for name, (acc, e) in gates.items():
        cells = []
        for ti in range(len(TEXTURES)):
            parts = []
            for k in (0, 1):
                m = (tex == ti) & (kind == k)
                a = m & acc & np.isfinite(e)
                rms = np.sqrt(np.mean(e[a] ** 2)) if a.any() else np.nan
                parts.append(f"{100 * (a & (e > 0.5)).sum() / max(a.sum(), 1):.1f} % / "
                             f"{100 * (m & good & ~acc).sum() / max((m & good).sum(), 1):.1f} % ({rms:.3f})")
            cells.append(" \\| ".join(parts))
        print(f"| {name} | " + " | ".join(cells) + " |")


def temporal_gate(steps, array, od, half=20, k=4.0):
    """Drop sensor-steps more than k sigma from the centred running median of the fused twist."""
    u = np.where(od.bridged[:, None], np.nan, od.twists)
    win = np.lib.stride_tricks.sliding_window_view(np.pad(u, ((half, half), (0, 0)), constant_values=np.nan),
                                                   2 * half + 1, axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        pred = np.nanmedian(win, axis=2)
    A = array.design_matrix().reshape(array.n, 2, 3)
    b = np.einsum("nij,kj->nki", A, pred)
    ds = np.einsum("nkji,nkj->nki", rot2(array.phi[:, None] + 0.5 * pred[None, :, 2]), b) / array.scale[:, None, None]
    bad = steps.valid & (np.linalg.norm(steps.disp - ds, axis=2) > k * np.sqrt(2) * steps.sigma)
    return SensorSteps(steps.t, np.where(bad[..., None], np.nan, steps.disp), steps.valid & ~bad, steps.sigma,
                       steps.quality, reasons=steps.reasons, kernel=steps.kernel)


def fusion_table():
    print("\nAfter fusion (sensor-steps used): wrong used / good left out / ATE, summed over the 4 drives per texture\n")
    print("| texture | fusion | used | wrong used | good left out | ATE per drive [mm] |")
    print("|---|---|---:|---:|---:|---|")
    for tex in TEXTURES:
        tot = {}
        for speed, seed in DRIVES:
            run, sim, truth = drive(tex, speed, seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                st, flows = steps_from_frames(run.frames, run.t, run.gyro, run.height, sim.camera.focal_px)
            err = np.stack([np.hypot(*(flows[i].flow_comp_px - truth[i]).T) for i in range(3)])
            arr = sim.array_true.copy(scale=1 / np.asarray(sim.height_scale))
            od = dead_reckon(st, arr)
            variants = {"default (chi-square, >= 3 sensors)": (st, od)}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                st_t, fl_t = steps_from_frames(run.frames, run.t, run.gyro, run.height, sim.camera.focal_px,
                                               FlowConfig(aggregate="tensor"))
            variants["aggregate=tensor"] = (st_t, dead_reckon(st_t, arr))
            err_t = np.stack([np.hypot(*(fl_t[i].flow_comp_px - truth[i]).T) for i in range(3)])
            for half, k in ((10, 4.0), (20, 4.0)):
                st2 = temporal_gate(st, arr, od, half, k)
                variants[f"+ temporal gate W={half} k={k}"] = (st2, dead_reckon(st2, arr))
            for name, (s, o) in variants.items():
                acc = s.valid & ~o.rejected
                e, v0 = (err_t, st_t.valid) if name == "aggregate=tensor" else (err, st.valid)
                t = tot.setdefault(name, [0, 0, 0, []])
                t[0] += int(acc.sum())
                t[1] += int((acc & (e > 0.5)).sum())
                t[2] += int((v0 & ~acc & (e <= 0.5)).sum())
                t[3].append(evaluate_trajectory(o.poses, run.poses).ate_rmse * 1e3)
        for name, (n, w, g, a) in tot.items():
            print(f"| {tex} | {name} | {n} | {w} ({100 * w / max(n, 1):.1f} %) | {g} | {' / '.join(f'{x:.1f}' for x in a)} |")


if __name__ == "__main__":
    if "ROBOCAL_TENSOR_REG" in os.environ:
        from robocal.rigs.flow import kernel as _k

        _k.TENSOR_REGULARISATION = float(os.environ["ROBOCAL_TENSOR_REG"])
    kernel_table(kernel_frames(), kernel_frames("tensor"))
    fusion_table()
