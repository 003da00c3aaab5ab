"""Benchmark of the flow rig: frame pairs per second of the SAD kernel on 64x64 frames
(one core) side by side with OpenCV's pyramidal Lucas-Kanade and a hand-written C ``psadbw``
kernel with the same sub-pixel fit and gates (``bench_flow_psadbw.py``, compiled here when a C
compiler is present) on the same frames, and the log-processing rate relative to real time for 3
sensors at 400 Hz. ``compute_flow`` runs the rig's C extension where it was built (the default) and,
in the C-peer table, the numba fallback too (``ROBOCAL_FLOW_KERNEL``).

    python bench/bench_flow.py            # prints a Markdown table (about 1 min)
    python bench/bench_flow.py --command [DIR] [--repeats N]  # what a user runs: 'robocal flow odometry' on a
                                          # 30 s, 3-sensor, 400 Hz frames log vs real time, the
                                          # command's fixed cost, the library from files (about 3 min;
                                          # DIR keeps the simulated log for the next run)
    python bench/bench_flow.py --fixed DIR [--repeats N]  # the 30 s command and the fixed cost against
                                          # their floors (NumPy + PyYAML, the CLI) in N interleaved
                                          # rounds, least and median (DIR from --command; default 61
                                          # rounds, about 3 min)
    python bench/bench_flow.py --scaling  # do two CPUs run the C kernel side by side (processes, threads)
    python bench/bench_flow.py --seeds    # calibration accuracy and fresh-run ATE/RPE over
                                          # seeds 100-103 (docs/rigs/flow.md; about 2 min)
    python bench/bench_flow.py --s270     # where sensor s270's R bias comes from: ideal vs kernel
                                          # flow, and the kernel's error per speed (seed 100; 15 s)

The kernel tables are per core: CPU seconds of this process (``time.process_time``, best of several
repeats) with the C kernel on one thread (``ROBOCAL_FLOW_THREADS=1``), as OpenCV and numba here. The
``--command`` table gives what the user waits, wall seconds (the kernel on its threads, the hashing
and reading beside it), and the CPU seconds beside them; each the least of 5 round-robin rounds (``--repeats N``).
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from robocal.rigs.flow import kernel as K  # noqa: E402
from robocal.rigs.flow.kernel import FlowConfig, compute_flow, compute_flow_sequence, match_blocks  # noqa: E402
from robocal.rigs.flow.log import steps_from_frames  # noqa: E402
from robocal.rigs.flow.odometry import dead_reckon  # noqa: E402
from robocal.rigs.flow.simulate import load_texture, shifted_pairs, simulate_run  # noqa: E402
from robocal.rigs.flow.workflow import default_sim  # noqa: E402

cv2.setNumThreads(1)


def best_rate(fn, n_items, *, repeats=5, min_time=0.3):
    """Items per CPU second, best of ``repeats`` (each at least ``min_time``)."""
    fn()  # warm-up (numba compile / cache load)
    best = 0.0
    for _ in range(repeats):
        k = 0
        t0 = time.process_time()
        while True:
            fn()
            k += 1
            dt = time.process_time() - t0
            if dt >= min_time:
                break
        best = max(best, k * n_items / dt)
    return best


def numpy_sad(prev, curr, config: FlowConfig):
    """Plain NumPy reference: a Python loop over the 81 shifts, vectorised over pairs and blocks."""
    o = K.block_origins(config)
    S, B = config.search, config.block
    p = prev.astype(np.int16)
    c = curr.astype(np.int16)
    best = np.full((len(prev), len(o), len(o)), 1 << 30)
    ref = np.stack([np.stack([p[:, y:y + B, x:x + B] for x in o], 1) for y in o], 1)
    for dy in range(-S, S + 1):
        for dx in range(-S, S + 1):
            cand = np.stack([np.stack([c[:, y + dy:y + dy + B, x + dx:x + dx + B] for x in o], 1) for y in o], 1)
            best = np.minimum(best, np.abs(ref - cand).sum(axis=(3, 4)))
    return best


def lk_flow(prev, curr, pts):
    for a, b in zip(prev, curr):
        cv2.calcOpticalFlowPyrLK(a, b, pts, None, winSize=(15, 15), maxLevel=1)


def main():
    os.environ[K.THREADS_ENV] = "1"         # per-core rates, as the peers (cv2 and numba on one thread)
    tex, note = load_texture("gravel")
    prev, curr, _ = shifted_pairs(tex, 512, np.random.default_rng(0), binning=2)
    prev = np.concatenate([prev] * 4)
    curr = np.concatenate([curr] * 4)
    n = len(prev)
    cfg = FlowConfig()
    o1 = K.block_origins(cfg)
    ys, xs = np.repeat(o1, 5), np.tile(o1, 5)
    pt = np.ascontiguousarray(prev[:256].transpose(1, 2, 0))
    ct = np.ascontiguousarray(curr[:256].transpose(1, 2, 0))
    sads = np.empty((25, 81, 256), np.uint16)
    keys = np.empty((25, 256), np.int32)
    rows = []
    r_sad = best_rate(lambda: K._sad8_batch(pt, ct, 0, ys, xs, 4, sads, keys), 256)
    rows.append(("SAD kernel alone (eq. 1 + argmin; 25 blocks 8x8, +/-4 px, batches of 256)", r_sad))
    for sp in ("none", "half", "quarter", "parabolic", "equiangular"):
        c = FlowConfig(subpixel=sp)
        rows.append((f"match_blocks, subpixel={sp}", best_rate(lambda c=c: match_blocks(prev, curr, c), n, repeats=3)))
    rows.append(("compute_flow (default: equiangular, trimmed mean, quality)", best_rate(lambda: compute_flow(prev, curr), n, repeats=3)))
    rows.append(("compute_flow, refine=lk", best_rate(lambda: compute_flow(prev, curr, FlowConfig(refine="lk")), n, repeats=3)))
    small = slice(0, 64)
    rows.append(("plain NumPy, loop over the 81 shifts", best_rate(lambda: numpy_sad(prev[small], curr[small], cfg), 64, repeats=2)))
    pts = np.stack(np.meshgrid(np.arange(12, 52, 8), np.arange(12, 52, 8)), -1).reshape(-1, 1, 2).astype(np.float32)
    r_lk = best_rate(lambda: lk_flow(prev[:256], curr[:256], pts), 256, repeats=3)
    rows.append(("cv2.calcOpticalFlowPyrLK (25 points, 15x15, 1 level)", r_lk))
    r_pc = best_rate(lambda: [cv2.phaseCorrelate(a.astype(np.float64), b.astype(np.float64)) for a, b in zip(prev[:256], curr[:256])], 256, repeats=3)
    rows.append(("cv2.phaseCorrelate", r_pc))

    # log processing vs real time: 3 sensors at 400 Hz (rendering excluded)
    sim = default_sim("loop", 5.0, supersample=1)
    run = simulate_run(sim, np.random.default_rng(1))

    def process():
        st, _ = steps_from_frames(run.frames, run.t, run.gyro, run.height, sim.camera.focal_px)
        dead_reckon(st, sim.array_nominal)

    peer = c_peer(prev, curr, (lambda: K._sad8_batch(pt, ct, 0, ys, xs, 4, sads, keys), 256), seq=run.frames[0])
    process()
    per_run = np.inf
    for _ in range(7):
        t0 = time.process_time()
        process()
        per_run = min(per_run, time.process_time() - t0)
    realtime = sim.duration / per_run

    print(f"texture: {note}; {n} pairs of 64x64 frames; CPU time of one process, best of repeats\n")
    print("| method | frame pairs / s | vs cv2 LK |")
    print("|---|---:|---:|")
    for name, r in rows:
        print(f"| {name} | {r:,.0f} | {r / r_lk:.1f}x |")
    print(f"\nlog processing (frames -> flow -> fusion -> trajectory), 3 sensors x 400 Hz x {sim.duration:.0f} s: "
          f"{per_run:.3f} s CPU (best of 7) = {realtime:.0f}x real time ({3 * 400 * realtime:,.0f} pairs/s end to end)")
    if peer:
        print("\n" + peer)


def c_peer(prev, curr, sad_lanes, seq=None):
    """The C ``psadbw`` peer (bench_flow_psadbw.py) on the same pairs, measured interleaved with ours:
    SAD + argmin alone, and the whole default ``compute_flow`` (gate, SAD, second minimum,
    equiangular fit, trimmed mean, spread gate); with ``seq`` (one sensor's frames of a rendered
    drive, a log's content) also ``compute_flow_sequence`` against the C kernel on the same
    consecutive pairs. ``sad_lanes``: ``(fn, pairs)``, our SAD kernel alone on transposed pairs.
    Returns the Markdown lines, or a note without a compiler."""
    import bench_flow_psadbw as P

    so = P.load()
    if so is None:
        return "C psadbw peer: no C compiler (cc, gcc, clang or $CC) on this machine: not measured"
    n = len(prev)
    prev = np.ascontiguousarray(prev)
    curr = np.ascontiguousarray(curr)
    checks = [(compute_flow(prev, curr).flow_px, P.c_flow(so, prev, curr)[0])]
    if seq is not None:
        seq = np.ascontiguousarray(seq)
        sp, sc = np.ascontiguousarray(seq[:-1]), np.ascontiguousarray(seq[1:])
        checks.append((compute_flow_sequence(seq).flow_px, P.c_flow(so, sp, sc)[0]))
    for ours, theirs in checks:
        if not (np.array_equal(np.isnan(ours), np.isnan(theirs)) and np.nanmax(np.abs(ours - theirs)) == 0):
            raise SystemExit("the C peer's flow differs from compute_flow's: the comparison would not be like for like")
    best = np.empty((n, 25), np.int32)
    kernels = ["numba"] + (["c"] if K._flowc() is not None else [])
    fns = {"c_sad": (lambda: P.c_sad_argmin(so, prev, curr, best), n), "sad": sad_lanes,
           "c_flow": (lambda: P.c_flow(so, prev, curr), n)}
    for b in kernels:
        fns[f"flow_{b}"] = (lambda b=b: _on(b, compute_flow, prev, curr), n)
    if seq is not None:
        fns["c_seq"] = (lambda: P.c_flow(so, sp, sc), len(sp))
        for b in kernels:
            fns[f"seq_{b}"] = (lambda b=b: _on(b, compute_flow_sequence, seq), len(sp))
    # interleaved rounds, so that both see the same neighbours on a shared machine
    rates = dict.fromkeys(fns, 0.0)
    for _ in range(5):
        for k, (fn, m) in fns.items():
            rates[k] = max(rates[k], best_rate(fn, m, repeats=1))
    lines = [
        f"C peer: SSE2 psadbw, two block rows a psadbw, compiled '{P.compiler()} -O3 -march=native'; its flow equals "
        f"compute_flow's on every pair; best of 5 interleaved rounds",
        "",
        "| kernel | frame pairs / s | ours / C |",
        "|---|---:|---:|",
        f"| C: SAD + argmin (eq. 1), {n} gravel pairs | {rates['c_sad']:,.0f} | |",
        f"| ours: numba SAD kernel alone (pairs in SIMD lanes, transposed beforehand) | {rates['sad']:,.0f} | "
        f"{rates['sad'] / rates['c_sad']:.2f} |",
        f"| C: the whole default compute_flow (gate, SAD, fit, trimmed mean, spread gate), same pairs | "
        f"{rates['c_flow']:,.0f} | |",
    ]
    name = {"c": "C extension _flowc, the default", "numba": "numba kernel, the fallback"}
    lines += [f"| ours: compute_flow(prev, curr), {name[b]} | {rates[f'flow_{b}']:,.0f} | "
              f"{rates[f'flow_{b}'] / rates['c_flow']:.2f} |" for b in kernels[::-1]]
    if seq is not None:
        lines.append(f"| C: the same, on the {len(sp)} consecutive pairs of one sensor of a rendered drive | "
                     f"{rates['c_seq']:,.0f} | |")
        lines += [f"| ours: compute_flow_sequence(frames) on them (a log's path), {name[b]} | {rates[f'seq_{b}']:,.0f} | "
                  f"{rates[f'seq_{b}'] / rates['c_seq']:.2f} |" for b in kernels[::-1]]
    return "\n".join(lines)


def _on(backend, fn, *args):
    """``fn(*args)`` with the flow kernel ``backend`` (``ROBOCAL_FLOW_KERNEL``, read on every call)."""
    os.environ[K.KERNEL_ENV] = backend
    try:
        return fn(*args)
    finally:
        del os.environ[K.KERNEL_ENV]


def _child_cpu(argv, repeats=3, **kw):
    """The least CPU seconds (user + sys, all threads) and the least wall seconds of ``repeats`` runs of a
    child process."""
    import resource
    import subprocess

    cpus, walls = [], []
    for _ in range(repeats):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, **kw)
        walls.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append((r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
    return min(cpus), min(walls)


#: runs of each --command figure (the least is kept: the machine is shared)
REPEATS = 5


def command(duration=30.0, folder=None):
    """``robocal flow odometry`` on a ``duration`` s, 3-sensor, 400 Hz frames log (the simulator's, written
    in ``folder`` or a temporary one): CPU seconds of the command and real-time factors, the same log
    compressed (the pre-0.2 format), a first run (no caches), the fixed cost (the same command on 0.1 s of that
    log and of its reference and wheel trajectories), the
    floor under it (Python + NumPy + PyYAML + the CLI), and the library from files and from memory, with
    the kernel on its threads and on one. Every figure is the least wall time and the least CPU time
    (user + sys, all threads) of :data:`REPEATS` rounds (``--repeats N``) after a warm-up; the real-time factor is ``duration / wall s``
    (what the user waits), by CPU beside it."""
    import shutil
    import sys as _sys
    import tempfile
    from pathlib import Path

    from robocal.rigs.flow.log import load_run, read_frames_npz, write_frames_npz
    from robocal.rigs.flow.workflow import evaluation_run, odometry_result, odometry_run

    base = Path(folder or tempfile.mkdtemp(prefix="robocal-bench-flow-"))
    run = base / "run30"
    exe = [_sys.executable, "-m", "robocal"]
    if not (run / "run.yaml").is_file():
        import subprocess

        subprocess.run(exe + ["flow", "simulate", "--duration", str(duration), "--supersample", "1", "--no-progress",
                              "--seed", "7", "--out", str(run)], check=True, stdout=subprocess.DEVNULL)
    d = read_frames_npz(run / "frames.npz")
    variants = {"compressed": d, "short": {k: (v[:, :41] if k == "frames" else v[:41] if k == "t" else v[:, :40])
                                           for k, v in d.items()}}
    for name, data in variants.items():
        f = base / name
        f.mkdir(exist_ok=True)
        for fn in ("truth.csv", "wheel.csv"):
            if name == "short":
                # the reference and wheel trajectories over the same 0.1 s (and a row past it): what a call
                # costs whatever the log's length; the 30 s CSVs' reading grows with the log
                lines = (run / fn).read_text().splitlines(True)
                head = [ln for ln in lines if not ln[:1].isdigit()]
                rows = [ln for ln in lines if ln[:1].isdigit()]
                end = float(data["t"][40])
                keep = [ln for ln in rows if float(ln.split(",")[0]) <= end] + [
                    next(ln for ln in rows if float(ln.split(",")[0]) > end)]
                (f / fn).write_text("".join(head + keep))
            else:
                shutil.copy(run / fn, f / fn)
        (f / "run.yaml").write_text("".join(ln for ln in (run / "run.yaml").read_text().splitlines(True)
                                            if not ln.startswith("flow_log:")))     # the frames only
        if name == "compressed":
            np.savez_compressed(f / "frames.npz", frames=data["frames"], t=data["t"], gyro=data["gyro"],
                                height=data["height"])
        else:
            write_frames_npz(f / "frames.npz", data["frames"], data["t"], data["gyro"], data["height"])
    outs = iter(range(10**6))

    def odo(folder, *extra):
        # a fresh --out folder every run (the command refuses one holding another command's files)
        return exe + ["flow", "odometry", str(folder / "run.yaml"), "--no-progress", *extra,
                      "--out", str(base / f"out{next(outs)}")]

    _child_cpu(odo(run, "--no-report"), repeats=1,                 # warm-up: page cache, .pyc files
               env={k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"})
    one = {K.THREADS_ENV: "1"}
    specs = []
    for label, argv, secs, extra in (
            (f"robocal flow odometry --no-report, {duration:g} s log (frames.npz memory-mapped)", odo(run, "--no-report"),
             duration, {}),
            ("the same, the kernel on one thread (ROBOCAL_FLOW_THREADS=1)", odo(run, "--no-report"), duration, one),
            ("the same, a first run (ROBOCAL_NO_CACHE=1: the 149 MB frames hashed, the metadata read)",
             odo(run, "--no-report"), duration, {"ROBOCAL_NO_CACHE": "1"}),
            ("robocal flow odometry --no-report, the same log compressed (np.savez_compressed, the pre-0.2 files)",
             odo(base / "compressed", "--no-report"), duration, {}),
            (f"robocal flow odometry with report.html, {duration:g} s log", odo(run), duration, {}),
            ("robocal flow odometry --no-report, 0.1 s of the same log and its reference and wheel CSVs (the fixed cost)",
             odo(base / "short", "--no-report"),
             0.1, {}),
            ("the same, numba kernel (ROBOCAL_FLOW_KERNEL=numba: an install without a C compiler)",
             odo(base / "short", "--no-report"), 0.1, {K.KERNEL_ENV: "numba"}),
            ("floor: python -c 'import robocal.cli.main' (Python, NumPy, PyYAML, the CLI)",
             [_sys.executable, "-c", "import robocal.cli.main"], None, {}),
            ("python -c pass", [_sys.executable, "-c", "pass"], None, {})):
        # PYTHONDONTWRITEBYTECODE (set in some sandboxes) would recompile every changed module in every run: an
        # install has its .pyc files (the warm-up writes them here)
        env = {k: v for k, v in os.environ.items() if k not in (K.THREADS_ENV, K.KERNEL_ENV, "PYTHONDONTWRITEBYTECODE")}
        env.update(extra)
        if K.KERNEL_ENV in extra:
            _child_cpu(argv, repeats=1, env=env)        # warm-up: numba's cache
        specs.append((label, argv, secs, env))

    # the library, in this process (imports and numba's cache already loaded); a fresh RunSpec each run:
    # odometry_run starts the hashing and the reading beside the kernel (robocal.rigs.flow.background)
    def from_files():
        spec = load_run(run / "run.yaml")
        od, _, steps = odometry_run(spec)
        curves, errors = evaluation_run(spec, od)
        odometry_result(od, spec, errors, curves=curves, steps=steps)

    spec = load_run(run / "run.yaml")
    frames = read_frames_npz(run / "frames.npz")
    frames = {k: np.array(v) for k, v in frames.items()}

    def in_memory():
        st, _ = steps_from_frames(frames["frames"], frames["t"], frames["gyro"], frames["height"], spec.focal_px)
        dead_reckon(st, spec.array)

    def threads(n):
        def call(fn):
            if n:
                os.environ[K.THREADS_ENV] = n
            try:
                return _times(fn, 1)
            finally:
                os.environ.pop(K.THREADS_ENV, None)
        return call

    from_files()
    # round robin: every figure once a round, REPEATS rounds, the least of each kept (on a shared machine the
    # neighbours' load comes and goes; each figure gets its share of the quiet moments)
    best = {}
    for _ in range(REPEATS):
        for label, argv, secs, env in specs:
            best[label] = np.minimum(best.get(label, np.inf), _child_cpu(argv, repeats=1, env=env))
        for n in (None, "1"):
            for what, fn in (("files", from_files), ("memory", in_memory)):
                best[(what, n)] = np.minimum(best.get((what, n), np.inf), threads(n)(fn))
    rows = [(label, *best[label], secs) for label, _, secs, _ in specs]
    lib = {n: (tuple(best[("files", n)]), tuple(best[("memory", n)])) for n in (None, "1")}
    os.environ.pop(K.THREADS_ENV, None)
    print(f"{duration:g} s log, 3 sensors x 400 Hz, 64x64 frames ({(run / 'frames.npz').stat().st_size / 1e6:.0f} MB); "
          f"least of {REPEATS} round-robin runs after a warm-up (wall and CPU separately; CPU = user + sys of all threads); flow kernel: "
          f"{K.kernel_name()} on {K.kernel_threads()} thread(s)\n")
    print("| what | wall s | x real time | CPU s | x real time by CPU |")
    print("|---|---:|---:|---:|---:|")

    def row(label, cpu, wall, secs):
        rt = (lambda t: f"{secs / t:.0f}x") if secs else (lambda t: "")
        print(f"| {label} | {wall:.2f} | {rt(wall)} | {cpu:.2f} | {rt(cpu)} |")

    for r in rows:
        row(*r)
    for threads, (ff, mem) in lib.items():
        one_t = ", the kernel on one thread" if threads else ""
        row(f"library from files (load_run -> odometry_run -> evaluation_run -> odometry_result), in-process{one_t}",
            *ff, duration)
        row(f"library in memory (steps_from_frames -> dead_reckon), in-process{one_t}", *mem, duration)
    fixed = rows[5]
    print(f"\nfixed cost per call: {fixed[2]:.2f} s wall, {fixed[1]:.2f} s CPU (0.1 s log); of it the floor (Python, "
          f"NumPy, PyYAML, the CLI): {rows[7][2]:.2f} s wall; with the numba kernel {rows[6][2]:.2f} s wall")
    if folder is None:
        shutil.rmtree(base, ignore_errors=True)


def fixed(folder, rounds=61):
    """The command and its fixed cost against their floors, in interleaved rounds (least and median of
    ``rounds``): ``robocal flow odometry`` on the 30 s log and on the 0.1 s log (with its 0.1 s reference and
    wheel CSVs) that ``--command DIR`` left in ``DIR/run30`` and ``DIR/short``, ``python -c "import numpy,
    yaml"`` (what robocal cannot avoid),
    ``import robocal.cli.main`` and ``python -c pass``. The median shows what a loaded machine gives; the
    least, what the code costs."""
    import subprocess
    import sys as _sys
    from pathlib import Path

    short = Path(folder) / "short" / "run.yaml"
    if not short.is_file():
        raise SystemExit(f"{short} is missing: run 'python bench/bench_flow.py --command {folder}' first")
    py = _sys.executable
    outs = iter(range(10**6))
    full = Path(folder) / "run30" / "run.yaml"
    cases = {
        "robocal flow odometry --no-report, the 30 s log":
            lambda: [py, "-m", "robocal", "flow", "odometry", str(full), "--no-progress", "--no-report", "--out",
                     str(Path(folder) / f"fixed{next(outs)}")],
        "robocal flow odometry --no-report, 0.1 s log and CSVs (the fixed cost)":
            lambda: [py, "-m", "robocal", "flow", "odometry", str(short), "--no-progress", "--no-report", "--out",
                     str(Path(folder) / f"fixed{next(outs)}")],
        "floor: python -c 'import numpy, yaml'": lambda: [py, "-c", "import numpy, yaml"],
        "python -c 'import robocal.cli.main'": lambda: [py, "-c", "import robocal.cli.main"],
        "python -c pass": lambda: [py, "-c", "pass"],
    }
    env = {k: v for k, v in os.environ.items() if k not in (K.THREADS_ENV, K.KERNEL_ENV, "PYTHONDONTWRITEBYTECODE")}
    for argv in cases.values():         # warm-up: .pyc files, the metadata and digest caches
        subprocess.run(argv(), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    times = {k: [] for k in cases}
    for _ in range(rounds):
        for label, argv in cases.items():
            t0 = time.perf_counter()
            subprocess.run(argv(), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            times[label].append(time.perf_counter() - t0)
    print(f"{rounds} interleaved rounds, wall seconds\n")
    print("| what | least | median |")
    print("|---|---:|---:|")
    for label, t in times.items():
        print(f"| {label} | {min(t):.3f} | {float(np.median(t)):.3f} |")


def scaling(rounds=40):
    """Whether the machine's CPUs run the C kernel side by side: the least time of 3000 pairs alone, of two
    processes doing 3000 pairs each at once, and of 6000 pairs on the kernel's two threads (rounds
    interleaved). Two real cores: both ratios near 1; SMT siblings or a busy neighbour: near 2."""
    os.environ[K.THREADS_ENV] = "1"
    fr = np.random.default_rng(0).integers(0, 256, (6001, 64, 64), dtype=np.uint8)
    K.match_sequence(fr[:300])

    def solo():
        t0 = time.perf_counter()
        K.match_sequence(fr[:3001])
        return time.perf_counter() - t0

    def procs():
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(r)
            t0 = time.perf_counter()
            K.match_sequence(fr[3000:])
            os.write(w, str(time.perf_counter() - t0).encode())
            os._exit(0)
        os.close(w)
        a = solo()
        os.waitpid(pid, 0)
        b = float(os.read(r, 64))
        os.close(r)
        return max(a, b)

    def threads():
        os.environ[K.THREADS_ENV] = "2"
        try:
            t0 = time.perf_counter()
            K.match_sequence(fr)
            return time.perf_counter() - t0
        finally:
            os.environ[K.THREADS_ENV] = "1"

    best = {"solo": np.inf, "procs": np.inf, "threads": np.inf}
    for _ in range(rounds):
        for k, f in (("solo", solo), ("procs", procs), ("threads", threads)):
            best[k] = min(best[k], f())
    print(f"C kernel, least of {rounds} rounds: 3000 pairs alone {best['solo'] * 1e3:.1f} ms; two processes x 3000 "
          f"{best['procs'] * 1e3:.1f} ms ({best['procs'] / best['solo']:.2f}x); 6000 pairs on two threads "
          f"{best['threads'] * 1e3:.1f} ms ({best['threads'] / best['solo']:.2f}x)")


def _times(fn, repeats=3):
    """The least CPU seconds (all threads) and the least wall seconds of ``repeats`` calls of ``fn``."""
    cpus, walls = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(cpus), min(walls)


def _cpu_of(fn):
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def _err(a, b, p, i):
    e = getattr(a, p)[i] - getattr(b, p)[i]
    return np.angle(np.exp(1j * e)) if p in ("psi", "phi") else e


def seeds(seed_list=(100, 101, 102, 103)):
    """Calibration error / total std and fresh-run ATE and RPE (nominal / calibrated / true / wheels)."""
    from robocal.rigs.flow.calibrate import calibrate_array
    from robocal.rigs.flow.evaluate import evaluate_trajectory
    from robocal.rigs.flow.workflow import mounted_array

    print("| seed | max abs(err)/total std | s270.R err [mm] (stat std, sys; debiased err) | ATE nom / cal / true / wheels [mm] "
          "| RPE trans nom / cal / true [%] | RPE rot nom / cal / true [deg/m] |")
    print("|---|---:|---|---|---|---|")
    debiased = []
    for seed in seed_list:
        rng = np.random.default_rng(seed)
        sa = default_sim("calibration", 6.0, supersample=2)
        ra = simulate_run(sa, rng)
        st, _ = steps_from_frames(ra.frames, ra.t, ra.gyro, ra.height, sa.camera.focal_px)
        cal = calibrate_array(st, ra.t, ra.poses, sa.array_nominal)
        tr = mounted_array().copy(scale=1 / np.asarray(sa.height_scale))
        tot = cal.total_std()
        z = []
        for i, nm in enumerate(tr.names):
            for p in ("R", "psi", "phi", "scale"):
                e = getattr(cal.array, p)[i] - getattr(tr, p)[i]
                z.append(abs(np.angle(np.exp(1j * e)) if p in ("psi", "phi") else e) / tot[f"{nm}.{p}"])
        sb = default_sim("loop", 8.0, supersample=2)
        rb = simulate_run(sb, rng)
        stb, _ = steps_from_frames(rb.frames, rb.t, rb.gyro, rb.height, sb.camera.focal_px)
        ev = [evaluate_trajectory(dead_reckon(stb, a).poses, rb.poses) for a in (sb.array_nominal, cal.array, tr)]
        ew = evaluate_trajectory(rb.wheel_poses, rb.poses)
        # both drives with the kernel's bias removed (FlowConfig(debias=True)): docs/rigs/flow.md
        fd = FlowConfig(debias=True)
        st_d, _ = steps_from_frames(ra.frames, ra.t, ra.gyro, ra.height, sa.camera.focal_px, fd)
        cal_d = calibrate_array(st_d, ra.t, ra.poses, sa.array_nominal)
        stb_d, _ = steps_from_frames(rb.frames, rb.t, rb.gyro, rb.height, sb.camera.focal_px, fd)
        e_d = evaluate_trajectory(dead_reckon(stb_d, cal_d.array).poses, rb.poses)
        debiased.append(f"| {seed} | {ev[1].ate_rmse * 1e3:.1f} / {e_d.ate_rmse * 1e3:.1f} "
                        f"| {ev[1].rpe[0.5]['trans_per_m'] * 100:.2f} / {e_d.rpe[0.5]['trans_per_m'] * 100:.2f} "
                        f"| {np.degrees(ev[1].rpe[0.5]['rot_per_m']):.2f} / {np.degrees(e_d.rpe[0.5]['rot_per_m']):.2f} "
                        f"| {(cal_d.array.R[2] - tr.R[2]) * 1e3:+.1f} |")
        for i, nm in enumerate(tr.names):
            print("   ", nm, "  ".join(
                f"{p} err {_err(cal.array, tr, p, i):+.3g} deb {_err(cal.array_debiased, tr, p, i):+.3g} "
                f"stat {cal.std[f'{nm}.{p}']:.3g} sys {cal.systematic[f'{nm}.{p}']:.3g}" for p in ("R", "psi", "phi", "scale")),
                  file=sys.stderr)
        ate = " / ".join(f"{e.ate_rmse * 1e3:.1f}" for e in ev + [ew])
        rt = " / ".join(f"{e.rpe[0.5]['trans_per_m'] * 100:.2f}" for e in ev)
        rr = " / ".join(f"{np.degrees(e.rpe[0.5]['rot_per_m']):.2f}" for e in ev)
        e270 = (cal.array.R[2] - tr.R[2]) * 1e3
        d270 = (cal.array_debiased.R[2] - tr.R[2]) * 1e3
        print(f"| {seed} | {max(z):.2f} | {e270:.1f} ({cal.std['s270.R'] * 1e3:.2f}, {cal.systematic['s270.R'] * 1e3:.1f}; "
              f"{d270:+.1f}) "
              f"| {ate} | {rt} | {rr} |", flush=True)
    print("\n| seed | ATE effective / debiased [mm] | RPE trans [%] | RPE rot [deg/m] | s270.R err debiased [mm] |")
    print("|---|---|---|---|---:|")
    print("\n".join(debiased))


def s270(seed=100):
    """Calibration of the rendered drive on ideal flow (the simulator's true displacements) vs the
    kernel's, and the kernel's error of each sensor's flow per speed band (docs/rigs/flow.md)."""
    from robocal.rigs.flow.calibrate import calibrate_array
    from robocal.rigs.flow.model import rot2
    from robocal.rigs.flow.odometry import SensorSteps
    from robocal.rigs.flow.workflow import mounted_array

    sa = default_sim("calibration", 6.0, supersample=2)
    ra = simulate_run(sa, np.random.default_rng(seed))
    st, flows = steps_from_frames(ra.frames, ra.t, ra.gyro, ra.height, sa.camera.focal_px)
    tr = mounted_array()
    hs = np.asarray(sa.height_scale)
    th = ra.poses[:, 2]
    ideal = []
    for i in range(tr.n):
        p = ra.poses[:, :2] + np.einsum("kab,b->ka", rot2(th), tr.positions[i])
        ideal.append(np.einsum("kba,kb->ka", rot2(th[1:] + tr.phi[i]), np.diff(p, axis=0)))
    ideal = np.array(ideal)
    n, K = st.valid.shape
    for label, steps, truth in (
            ("ideal flow", SensorSteps(ra.t, ideal, np.ones((n, K), bool), st.sigma, st.quality), tr),
            ("kernel flow", st, tr.copy(scale=1 / hs))):
        cal = calibrate_array(steps, ra.t, ra.poses, sa.array_nominal, jackknife=False)
        print(f"{label:12s}", " | ".join(
            f"{nm}: R {(cal.array.R[i] - truth.R[i]) * 1e3:+.2f} mm, psi {np.degrees(_err(cal.array, truth, 'psi', i)):+.2f} deg, "
            f"phi {np.degrees(_err(cal.array, truth, 'phi', i)):+.2f} deg, scale {(cal.array.scale[i] / truth.scale[i] - 1) * 100:+.2f} %"
            for i, nm in enumerate(tr.names)))
    f = sa.camera.focal_px
    print("\nkernel error of the along-track flow u per speed band (true u from the simulator), px:")
    print("| sensor | true u [px] | frames | mean u error [px] | relative | mean true v [px] | mean v error [px] |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for i, nm in enumerate(tr.names):
        ut = -ideal[i][:, 0] * f / ra.true_height[i]
        vt = ideal[i][:, 1] * f / ra.true_height[i]
        comp = flows[i].flow_comp_px
        eu, ev = comp[:, 0] - ut, comp[:, 1] - vt
        band = np.round(ut * 4) / 4
        for b in np.unique(band):
            m = (band == b) & np.isfinite(eu)
            if m.sum() >= 100 and abs(b) >= 0.2:
                print(f"| {nm} | {ut[m].mean():+.2f} | {m.sum()} | {eu[m].mean():+.4f} | {eu[m].mean() / ut[m].mean() * 100:+.1f} % "
                      f"| {vt[m].mean():+.3f} | {ev[m].mean():+.4f} |")


if __name__ == "__main__":
    if "--seeds" in sys.argv[1:]:
        seeds()
    elif "--s270" in sys.argv[1:]:
        s270()
    elif "--scaling" in sys.argv[1:]:
        scaling()
    elif "--fixed" in sys.argv[1:]:
        rest = sys.argv[sys.argv.index("--fixed") + 1:]
        if "--repeats" in rest:
            fixed(rest[0], int(rest[rest.index("--repeats") + 1]))
        else:
            fixed(rest[0])
    elif "--command" in sys.argv[1:]:
        if "--repeats" in sys.argv[1:]:
            REPEATS = int(sys.argv.pop(sys.argv.index("--repeats") + 1))
            sys.argv.remove("--repeats")
        rest = sys.argv[sys.argv.index("--command") + 1:]
        command(folder=rest[0] if rest else None)     # a folder keeps the simulated log for the next run
    else:
        main()
