"""The flow kernel's C extension (rigs/flow/flowc.c -> ``_flowc``) against the numba kernel it replaces on the
default path (issue 16): the same block flows, statuses and frame flows to the bit; the fallback when the
extension is missing or switched off; the odometry command's imports without numba and SciPy."""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.rigs.flow import kernel as K
from robocal.rigs.flow.kernel import FlowConfig, compute_flow, compute_flow_sequence, match_blocks

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"
needs_c = pytest.mark.skipif(K._flowc() is None, reason="the C kernel was not built (no C compiler at install)")


def _compiler_and_headers() -> bool:
    cc = os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    return shutil.which(cc.split()[0]) is not None and Path(sysconfig.get_paths()["include"], "Python.h").is_file()


def test_extension_is_built_where_a_compiler_is_present():
    """``optional = true`` in pyproject.toml: a failed build is skipped silently. Where the install had
    what it needs (the compiler Python was built with, and Python.h), the extension must be there."""
    if not _compiler_and_headers():
        pytest.skip("no C compiler or Python headers: the install skips the extension (the numba kernel runs)")
    assert K._flowc() is not None, "a C compiler and Python.h are present, but robocal.rigs.flow._flowc was not built"
    assert K._flowc().SIMD in ("avx2", "sse2", "portable")


@pytest.fixture(scope="module")
def pairs():
    """Shifted photographs (the accepted path), pure noise (ambiguous / poor SAD), flat frames (no texture)."""
    from robocal.rigs.flow.simulate import load_texture, shifted_pairs

    tex, _ = load_texture("gravel")
    prev, curr, _ = shifted_pairs(tex, 120, np.random.default_rng(0), binning=2)
    rng = np.random.default_rng(1)
    noise = rng.integers(0, 256, size=(16, 64, 64), dtype=np.uint8)
    flat = np.full((4, 64, 64), 128, np.uint8)
    return np.concatenate([prev, noise[:8], flat[:2]]), np.concatenate([curr, noise[8:], flat[2:]])


def _run(backend, prev, curr, config):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(K.KERNEL_ENV, backend)
        assert K.kernel_backend() == backend
        seq = np.concatenate([prev[:30], curr[:30]])
        return match_blocks(prev, curr, config), compute_flow(prev, curr, config), compute_flow_sequence(seq, config)


@needs_c
@pytest.mark.parametrize("config", [
    FlowConfig(), FlowConfig(subpixel="half"), FlowConfig(subpixel="quarter"), FlowConfig(subpixel="parabolic"),
    FlowConfig(subpixel="none", aggregate="mean"), FlowConfig(aggregate="median"),
    FlowConfig(block=6, search=3),            # the generic block size (no SSE2 path)
    FlowConfig(search=1),                     # every offset inside the best's 3x3: no second minimum
    FlowConfig(grid=4, search=6), FlowConfig(aggregate="tensor", refine="lk"),
], ids=lambda c: f"{c.subpixel}-{c.aggregate}-b{c.block}-s{c.search}-g{c.grid}-{c.refine}")
def test_c_and_numba_kernels_give_the_same_flow_to_the_bit(pairs, config):
    """Integer SADs, then the same double-precision fit and aggregation in the same order (no fused
    multiply-add in either): equal, not close. A tolerance here would hide a changed tie rule or test."""
    c = _run("c", *pairs, config)
    nb = _run("numba", *pairs, config)
    for field in ("flow", "status", "sad_min", "distinctness", "texture", "centres"):
        assert np.array_equal(getattr(c[0], field), getattr(nb[0], field), equal_nan=True), field
    for a, b in zip(c[1:], nb[1:]):
        for field in ("flow_px", "flow_comp_px", "quality", "valid", "spread_px", "agreement", "centroid_px",
                      "n_accepted", "n_no_texture", "n_bad_sad", "n_ambiguous"):
            assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=True), field
        assert a.reason == b.reason
    # the comparison covers every outcome of a block, not only accepted ones
    assert set(np.unique(c[0].status)) >= {0, 1, 3}


def test_fallback_when_the_extension_is_missing_or_switched_off(monkeypatch, pairs):
    prev, curr = pairs[0][:8], pairs[1][:8]
    monkeypatch.setattr(K, "_FLOWC", None)          # as after an install without a compiler
    monkeypatch.delenv(K.KERNEL_ENV, raising=False)
    assert K.kernel_backend() == "numba" and K.kernel_name() == "numba"
    r = compute_flow(prev, curr)
    assert r.valid.all()
    monkeypatch.setenv(K.KERNEL_ENV, "c")
    with pytest.raises(InputError, match="ROBOCAL_FLOW_KERNEL=c but the C kernel"):
        compute_flow(prev, curr)
    monkeypatch.setenv(K.KERNEL_ENV, "fast")
    with pytest.raises(InputError, match="'auto', 'c' or 'numba', got 'fast'"):
        K.kernel_backend()


@needs_c
def test_the_c_kernel_refuses_short_buffers():
    """The Python side checks shapes; the extension still checks every buffer it reads or writes."""
    f = K._flowc()
    z = np.zeros((2, 64, 64), np.uint8)
    ys = np.array([5], np.int64)
    out = [np.empty((1, 1, 2)), np.empty((1, 1), np.int8), np.empty((1, 1)), np.empty((1, 1)), np.empty((1, 1))]
    with pytest.raises(ValueError, match="prev holds 8192 bytes, expected at least 12288"):
        f.match(z, z, 2, 0, 1, 64, 8, 4, ys, ys, 30.0, 5000.0, 0.25, 4, *out)
    with pytest.raises(ValueError, match="leaves the frame"):
        f.match(z, z, 0, 0, 1, 64, 8, 4, np.array([55], np.int64), ys, 30.0, 5000.0, 0.25, 4, *out)


@needs_c
def test_odometry_command_imports_neither_numba_nor_scipy(tmp_path):
    """The command's fixed cost (issue 16: < 0.3 s after the first run) leaves no room for numba (0.6-1 s to
    import), scipy.special / spatial / optimize, OpenCV or matplotlib: with the C kernel, a frames log's
    odometry with --no-report imports none of them, nor numpy.ma (14 ms, which np.median and np.unique
    import on their first call; model.median stands in); result.json names the kernel that ran."""
    out = tmp_path / "odo"
    # (NumPy 1.x imports numpy.ma with numpy itself: then it is no cost of ours and not asked about)
    code = ("import sys; from robocal.cli.main import main; ma0 = 'numpy.ma' in sys.modules; "
            f"rc = main(['flow', 'odometry', {str(EX / 'frames' / 'run.yaml')!r}, '--no-report', '--no-progress', "
            f"'--out', {str(out)!r}]); "
            "heavy = ('numba', 'scipy', 'cv2', 'matplotlib', 'dask', 'distributed', 'rosbags', 'numpy.ma'); "
            "print(sorted(m for m in heavy if m in sys.modules and not (m == 'numpy.ma' and ma0))); sys.exit(rc)")
    env = {k: v for k, v in os.environ.items() if k != K.KERNEL_ENV}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]"
    summary = json.loads((out / "result.json").read_text())["diagnostics"]["summary"]
    assert summary["flow_kernel"] == f"c ({K._flowc().SIMD})"


def test_the_portable_c_path_gives_the_same_flow(tmp_path, pairs):
    """The plain C path (no SSE2: ARM, or any CPU the intrinsics do not cover) is what machines other than
    x86 build; compiled here with -DFLOWC_PORTABLE and compared with the numba kernel, bit for bit."""
    import importlib.machinery
    import importlib.util

    if not _compiler_and_headers():
        pytest.skip("no C compiler or Python headers")
    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()
    src = Path(K.__file__).with_name("flowc.c")
    so = tmp_path / ("_flowc" + importlib.machinery.EXTENSION_SUFFIXES[0])
    subprocess.run([*cc, "-O2", "-shared", "-fPIC", "-DFLOWC_PORTABLE", f"-I{sysconfig.get_paths()['include']}",
                    "-o", str(so), str(src), "-lm"], check=True, capture_output=True)
    spec = importlib.util.spec_from_file_location("_flowc", so)
    portable = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(portable)
    assert portable.SIMD == "portable"
    prev, curr = pairs
    ref = _run("numba", prev, curr, FlowConfig())
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(K, "_FLOWC", portable)
        mp.delenv(K.KERNEL_ENV, raising=False)
        assert K.kernel_name() == "c (portable)"
        bm, ff = match_blocks(prev, curr), compute_flow(prev, curr)
    for field in ("flow", "status", "sad_min", "distinctness", "texture"):
        assert np.array_equal(getattr(bm, field), getattr(ref[0], field), equal_nan=True), field
    assert np.array_equal(ff.flow_px, ref[1].flow_px, equal_nan=True)
