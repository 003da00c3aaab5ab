"""A toy rig for the batch tests: a data set is a YAML list of samples; calibrating it takes their mean.

Imported by name (conftest puts this folder on sys.path), also by the killed-batch subprocess.

The steps are made inside a function so that Dask's cloudpickle ships them
by value to worker processes (this test package is not importable there).
"""

import numpy as np
import yaml


def make_toy_workflow(attempts_dir=None):
    from robocal.workflow import Workflow

    def load_input(path, **_):
        from robocal.io import load_document

        doc = load_document(path)
        return {"a": doc.array("a"), "b": doc.array("b"), "sleep": doc.float("sleep", default=0.0),
                "fail": doc.raw("fail", None)}

    def calibrate(inp, *, out_dir, progress=False, accept_implausible=False, scale=1.0, **_):
        import time
        import uuid
        from pathlib import Path

        from robocal.errors import ConvergenceError

        if attempts_dir is not None:  # one file per attempt: a re-run task leaves two
            Path(attempts_dir, f"{Path(out_dir).name.split('.')[0]}.{uuid.uuid4().hex[:8]}").touch()
        time.sleep(inp["sleep"])
        if inp["fail"]:
            raise ConvergenceError(str(inp["fail"]))
        n = inp["a"].size
        return {k: (float(np.mean(inp[k])) * scale, float(np.std(inp[k], ddof=1) / np.sqrt(n))) for k in "ab"}

    def to_result(cal, inp):
        from robocal.io import CalibrationResult

        return CalibrationResult(rig="toy", method="mean", estimate={k: v[0] for k, v in cal.items()},
                                 std={k: v[1] for k, v in cal.items()}, units={"a": "rad", "b": "m"},
                                 residual_rms=0.0, residual_unit="m")

    def build_report(result, *, base_dir):
        from robocal.report import Report

        rep = Report("toy")
        rep.section("estimate").parameters(result.estimate, result.std, result.units)
        return rep

    from robocal.workflow import Option

    return Workflow(name="toy", help="toy", load_input=load_input, calibrate=calibrate, to_result=to_result,
                    build_report=build_report, calibrate_options=(Option("--scale", type=float, default=1.0),))


def write_fleet(folder, n, *, seed=0, sleep=0.0, fail=(), planted=None, weak=(), n_samples=30):
    """``n`` toy data sets + ``fleet.yaml``: robot i has a ~ N(0.01 * (1 + 0.1 u), 1e-3) rad per sample.

    ``planted``: ``{id: offset}`` added to ``a`` (a mechanical fault); ``weak``: ids recorded with
    10x the noise; ``fail``: ids whose calibration raises.
    """
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for i in range(n):
        ident = f"r{i:02d}"
        noise = 1e-2 if ident in weak else 1e-3
        a = 0.01 + 2e-4 * rng.standard_normal() + (planted or {}).get(ident, 0.0) + noise * rng.standard_normal(n_samples)
        b = 0.1 + 1e-4 * rng.standard_normal() + noise * rng.standard_normal(n_samples)
        doc = {"a": a.tolist(), "b": b.tolist(), "sleep": sleep, "fail": f"planted failure of {ident}" if ident in fail else None}
        (folder / f"{ident}.yaml").write_text(yaml.safe_dump(doc))
        entries.append({"id": ident, "input": f"{ident}.yaml"})
    (folder / "fleet.yaml").write_text(yaml.safe_dump({"datasets": entries}, sort_keys=False))
    return folder / "fleet.yaml"

