"""Issue 16's fast paths give the results of the paths they replace: memory-mapped uncompressed frames vs
the compressed .npz files written before, the kernel's changes (8-bit differences, one transposed array
per sequence; the C kernel) vs the outputs recorded before them, and numba's cache cannot serve stale code."""

import ast
import shutil
from pathlib import Path

import numpy as np
import pytest

from robocal.errors import FileFormatError
from robocal.rigs.flow import kernel, kernel_compiled, simulate
from robocal.rigs.flow.log import load_run, load_steps, read_frames_npz, write_frames_npz
from robocal.rigs.flow.workflow import odometry_run

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"
#: odometry of examples/flow/frames and examples/flow/loop computed at 2989618, before issue 16's changes
BEFORE = Path(__file__).parent / "data" / "odometry_before_issue16.npz"


@pytest.fixture(scope="module")
def frames_run():
    spec = load_run(EX / "frames" / "run.yaml")
    return spec, odometry_run(spec)


@pytest.mark.parametrize("backend", ["c", "numba"])
def test_example_odometry_unchanged_by_the_speed_work(backend, frames_run, monkeypatch):
    """With either kernel (the C extension, or the numba fallback), as recorded before issue 16."""
    if backend == "c" and kernel._flowc() is None:
        pytest.skip("the C kernel was not built (no C compiler at install)")
    monkeypatch.setenv(kernel.KERNEL_ENV, backend)
    spec, _ = frames_run
    od, flows, _ = odometry_run(spec)
    assert od.frames["flow_kernel"].split()[0] == backend
    before = np.load(BEFORE)
    # the kernel's flow is integer SADs + the same double arithmetic (no fastmath in the fit and
    # the aggregation): bit-identical on any IEEE machine
    assert np.array_equal(np.stack([f.flow_px for f in flows]), before["frames_flow"], equal_nan=True)
    assert np.array_equal(np.stack([f.quality for f in flows]), before["frames_quality"])
    # poses go through LAPACK's least squares, whose last bits may differ between BLAS builds:
    # ~1e-16 relative a step over <= 1200 steps of a ~1 m path is < 1e-12 m; 1e-9 m is still 5 orders
    # below the flow noise (0.06 px ~ 0.1 mm a frame), so any change of the algorithm fails here
    np.testing.assert_allclose(od.poses, before["frames_poses"], rtol=0, atol=1e-9)
    od_loop, _, _ = odometry_run(load_run(EX / "loop" / "run.yaml"))
    np.testing.assert_allclose(od_loop.poses, before["loop_poses"], rtol=0, atol=1e-9)


def test_memory_mapped_and_compressed_frames_give_the_same_steps(tmp_path, frames_run):
    spec, (od, _, steps) = frames_run
    d = read_frames_npz(EX / "frames" / "frames.npz")         # the example is compressed (pre-0.2 file)
    assert not isinstance(d["frames"], np.memmap)
    raw = tmp_path / "raw"
    shutil.copytree(EX / "frames", raw)
    write_frames_npz(raw / "frames.npz", d["frames"], d["t"], d["gyro"], d["height"])
    m = read_frames_npz(raw / "frames.npz")
    assert isinstance(m["frames"], np.memmap) and not m["frames"].flags.writeable
    for k in d:
        assert np.array_equal(m[k], d[k]), k
    steps_m, _ = load_steps(load_run(raw / "run.yaml"))
    assert np.array_equal(steps_m.disp, steps.disp, equal_nan=True)
    assert np.array_equal(steps_m.valid, steps.valid) and np.array_equal(steps_m.sigma, steps.sigma)
    # uncompressed frames are ~10 % larger than compressed ones (a textured floor barely compresses)
    assert (raw / "frames.npz").stat().st_size < 1.3 * (EX / "frames" / "frames.npz").stat().st_size


def test_truncated_stored_frames_are_named(tmp_path):
    d = read_frames_npz(EX / "frames" / "frames.npz")
    p = tmp_path / "frames.npz"
    write_frames_npz(p, d["frames"], d["t"], d["gyro"], d["height"])
    data = bytearray(p.read_bytes())
    # a stored member whose header promises more frames than its bytes hold: shrink the frame count
    old, new = b"'shape': (3, 121, 64, 64)", b"'shape': (3, 122, 64, 64)"
    i = data.index(old)
    data[i:i + len(old)] = new
    p.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match="frames.npz.*damaged"):
        read_frames_npz(p)


@pytest.mark.parametrize("module", [kernel_compiled, simulate])
def test_cached_kernels_depend_on_their_own_file_only(module):
    """numba's cache (``cache=True``) is invalidated by its own source file's time stamp and size, not by
    the files it calls into: a compiled function calling a compiled function of another module would
    keep the old callee's code after that module changed. So the compiled functions call only
    compiled functions of their own module (and NumPy / math)."""
    tree = ast.parse(Path(module.__file__).read_text())
    jitted = {f.name for f in tree.body if isinstance(f, ast.FunctionDef)
              and any("njit" in ast.unparse(d) for d in f.decorator_list)}
    assert jitted
    imported = set()
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("robocal"):
            imported |= {a.asname or a.name for a in node.names}
    for f in tree.body:
        if isinstance(f, ast.FunctionDef) and f.name in jitted:
            called = {n.func.id for n in ast.walk(f) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
            assert not (called & imported), f"{f.name} calls {called & imported} from another module"


def test_kernels_import_without_a_writable_cache_folder():
    """A read-only install without a writable cache folder: the kernels compile per process instead of
    ``cache=True`` failing on import (numba finds no cache locator here: only IPython's is allowed)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_LOCATOR_CLASSES="numba.core.caching.IPythonCacheLocator")
    code = ("import robocal.rigs.flow.kernel_compiled as k; from numba.core.caching import NullCache; "
            "print(k.CACHE, type(k._sad8_batch._cache).__name__)")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "NullCache"]
    from robocal.rigs.flow import kernel_compiled as k

    assert k.CACHE and type(k._sad8_batch._cache).__name__ == "FunctionCache"   # this checkout caches
