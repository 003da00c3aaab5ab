"""``robocal batch``: every data set of a manifest calibrated as its own task, each written whole or not at all.

A task runs the rig's workflow steps (``load_input`` -> ``calibrate`` ->
``to_result`` -> ``build_report`` [-> ``write_outputs``], as ``robocal <rig>
calibrate`` does) into a private staging folder ``DIR/.staging/<id>.<token>``
and, once every file is written and its run manifest says ``complete``,
renames it to ``DIR/<id>`` -- one atomic step. So:

* a worker killed half-way leaves only a staging folder (removed at the end
  of the batch); the scheduler runs the task again elsewhere;
* two attempts of one task (a worker thought dead that was not) cannot both
  land: the second rename finds ``DIR/<id>`` there and drops its copy;
* ``resume`` skips every id whose folder is complete: a batch killed half-way
  loses only the data sets that were running.

A data set that fails (any error of its own: a bad file, a calibration that
does not converge, an implausible answer) becomes one row with its one-line
error; the batch goes on. The rows are written to ``DIR/batch.json`` and
``DIR/batch.csv``; the fleet report (:mod:`robocal.batch._fleet`) follows.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import io
import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from robocal.errors import FileFormatError, RobocalError

__all__ = ["BatchOutcome", "run_batch", "dataset_complete", "claim_batch_folder", "calibrate_dataset", "STAGING"]

STAGING = ".staging"
BATCH_LABEL = "batch"


def dataset_complete(folder) -> bool:
    """Whether ``folder`` holds a finished calibration: its run manifest says ``complete``, no ``INCOMPLETE``."""
    from robocal.io import INCOMPLETE, read_manifest

    folder = Path(folder)
    m = read_manifest(folder)
    return (m is not None and m.get("state") == "complete" and (folder / "result.json").is_file()
            and not (folder / INCOMPLETE).exists())


@dataclass
class BatchOutcome:
    """What :func:`run_batch` did.

    Attributes
    ----------
    out_dir : Path
    rows : list of dict
        One per data set, in manifest order: ``id``, ``status`` (``ok``,
        ``error``, ``resumed``), ``error`` (one line or ""), ``seconds``,
        ``residual_rms``, ``inputs``.
    files : list of Path
        The batch's own files (``batch.json``, ``batch.csv``, fleet files).
    """

    out_dir: Path
    rows: list
    files: list = field(default_factory=list)

    @property
    def failed(self) -> list:
        return [r for r in self.rows if r["status"] == "error"]

    def summary(self) -> str:
        n = len(self.rows)
        done = sum(r["status"] == "ok" for r in self.rows)
        resumed = sum(r["status"] == "resumed" for r in self.rows)
        text = f"batch: {done} of {n} data set(s) calibrated"
        if resumed:
            text += f", {resumed} complete from an earlier run"
        if self.failed:
            text += f", {len(self.failed)} failed ({', '.join(r['id'] for r in self.failed[:5])}"
            text += ", ...)" if len(self.failed) > 5 else ")"
        return text


def _option_defaults(wf) -> dict:
    """``{dest: (step, default)}`` of the rig's calibrate options, as ``robocal <rig> calibrate`` parses them."""
    out = {}
    for o in wf.calibrate_options:
        step = "calibrate" if o.to == "" else o.to
        if step not in ("calibrate", "load_input"):
            continue
        action = o.kwargs.get("action")
        default = o.kwargs.get("default", False if action == "store_true" else True if action == "store_false" else None)
        out[o.dest] = (step, default)
    return out


def _split_options(wf, entry) -> tuple[dict, dict]:
    known = _option_defaults(wf)
    unknown = sorted(set(entry.options) - set(known))
    if unknown:
        raise FileFormatError(f"{entry.where}: option {unknown[0]!r} is not one of '{wf.name} calibrate' "
                              f"(known: {', '.join(sorted(known)) or 'none'})")
    load, cal = {}, {}
    for dest, (step, default) in known.items():
        (load if step == "load_input" else cal)[dest] = entry.options.get(dest, default)
    return load, cal


def _check_inputs(wf, entry) -> None:
    n, varargs = len(wf.inputs), any(o.kwargs.get("nargs") in ("+", "*") for o in wf.inputs)
    if len(entry.inputs) < n or (len(entry.inputs) > n and not varargs):
        names = " ".join(o.flags[0].upper() for o in wf.inputs)
        raise FileFormatError(f"{entry.where}: {len(entry.inputs)} input(s), '{wf.name} calibrate' takes "
                              f"{'at least ' if varargs else ''}{n} ({names})")


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, RobocalError):
        return str(exc).replace("\n", " ")
    # not robocal's own check: the data provoked it (or a bug), named by its type so it can be told apart
    return f"{type(exc).__name__}: {exc}".splitlines()[0]


def _calibrate_into(wf, entry, folder: Path, load_options, calibrate_options, accept_implausible, reports=True):
    """The rig's steps, as ``robocal <rig> calibrate`` runs them (``robocal.cli._workflow.calibrate_files``)."""
    from robocal.io import hash_inputs, write_result

    paths = list(entry.inputs)
    try:
        inp = wf.step("load_input")(*paths, **load_options)
        cal = wf.step("calibrate")(inp, out_dir=folder, progress=False, accept_implausible=accept_implausible,
                                   **calibrate_options)
        result = wf.step("to_result")(cal, inp)
        if not result.inputs:
            result.inputs = hash_inputs(paths)
        report = wf.step("build_report")(result, base_dir=folder) if wf.build_report is not None and reports else None
    except RobocalError as exc:
        if exc.source is None and paths:
            raise exc.with_source(" + ".join(map(str, paths))) from None
        raise
    write_result(folder / "result.json", result)
    if report is not None:
        report.write(folder / "report.html")
    extra = wf.step("write_outputs")
    if extra is not None:
        extra(result, folder)
    return result


def calibrate_dataset(wf, entry, out_dir, *, load_options=None, calibrate_options=None,
                      accept_implausible: bool = False, command: str = "robocal batch", reports: bool = True) -> dict:
    """Calibrate one data set into ``out_dir/<id>`` (atomically, see the module docstring); return its row.

    Runs on a worker. Never raises for the data set's own errors: they are
    the row's ``error``.
    """
    from robocal.io import INCOMPLETE, RUN_SCHEMA, RunFolder

    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    final = out_dir / entry.id
    row = {"id": entry.id, "status": "ok", "error": "", "seconds": 0.0, "residual_rms": None,
           "inputs": [str(p) for p in entry.inputs]}
    if dataset_complete(final):  # an earlier attempt of this very task landed (a re-run after a lost worker)
        row["seconds"] = time.perf_counter() - t0
        return row
    staging = out_dir / STAGING / f"{entry.id}.{uuid.uuid4().hex[:12]}"
    staging.mkdir(parents=True)
    label = f"{wf.name}-calibrate"
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    folder = RunFolder(staging, label, {"schema": RUN_SCHEMA, "label": label, "command": command, "rig": wf.name,
                                        "command_line": f"{command} (data set {entry.id})", "started": stamp,
                                        "finished": None, "state": "running", "files": None})
    try:
        (staging / INCOMPLETE).write_text(f"robocal: data set {entry.id} of a batch is being calibrated\n",
                                          encoding="utf-8")
        folder.write("running")
        result = _calibrate_into(wf, entry, staging, load_options or {}, calibrate_options or {}, accept_implausible,
                                 reports)
        row["residual_rms"] = result.residual_rms
        folder.close("complete")
    except Exception as exc:  # noqa: BLE001 - one data set's failure is its row, never the batch's end
        shutil.rmtree(staging, ignore_errors=True)
        row.update(status="error", error=_one_line(exc), seconds=time.perf_counter() - t0)
        return row
    try:
        os.rename(staging, final)  # atomic on one file system; refused when final exists and is not empty
    except OSError:
        shutil.rmtree(staging, ignore_errors=True)
        if not dataset_complete(final):
            row.update(status="error", error=f"{final} exists and is not a finished result of this batch: "
                                             "remove it, or choose another --out")
    row["seconds"] = time.perf_counter() - t0
    return row


def claim_batch_folder(out, *, resume: bool = False) -> Path:
    """``--out`` of a batch: claimed as any command's (:func:`robocal.io.prepare_out_dir`), or kept for ``resume``.

    With ``resume`` a folder holding an earlier batch run (finished or
    killed) is taken as it is: nothing of it is removed, it is marked
    ``INCOMPLETE`` again until this run ends. Without ``resume`` an earlier
    batch's files are removed first, as for every command.
    """
    from robocal.io import INCOMPLETE, RUN_SCHEMA, RunFolder, active_run, prepare_out_dir, read_manifest

    if out is None:  # a fresh robocal-out-batch-<time> folder
        return prepare_out_dir(None, BATCH_LABEL)
    out = Path(out)
    earlier = read_manifest(out) if out.is_dir() else None
    run = active_run()
    if not resume or earlier is None or earlier.get("label") != BATCH_LABEL or run is None:
        return prepare_out_dir(out, BATCH_LABEL)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    manifest = {"schema": RUN_SCHEMA, "label": BATCH_LABEL, "command": run.command or "robocal batch", "rig": run.rig,
                "command_line": run.command_line, "started": stamp, "finished": None, "state": "running",
                "files": None, "resumed": earlier.get("started")}
    folder = RunFolder(out, BATCH_LABEL, manifest, set(earlier.get("kept") or ()))
    (out / INCOMPLETE).write_text(f"robocal: the batch resumed {stamp} has not finished (see .robocal-run.json).\n",
                                  encoding="utf-8")
    folder.write("running")
    run.folders.append(folder)
    return out


def _completed(executor, futures):
    """The futures as they finish: Dask's ``as_completed`` for a Dask client, else concurrent.futures'."""
    if type(executor).__module__.split(".")[0] == "distributed":
        from distributed import as_completed

        return as_completed(futures)
    return cf.as_completed(futures)


def run_batch(wf, entries, out_dir, *, executor=None, resume: bool = False, accept_implausible: bool = False,
              progress: bool = False, fleet: bool = True, reports: bool = True, echo=None) -> BatchOutcome:
    """Calibrate every data set of ``entries`` (:func:`~robocal.batch.load_manifest`) into ``out_dir/<id>``.

    Parameters
    ----------
    wf : robocal.workflow.Workflow
        The rig; its steps run on the workers.
    entries : list of BatchEntry
    out_dir : path
        The batch folder (claimed by the caller, e.g. :func:`claim_batch_folder`).
    executor : Dask Client or concurrent.futures executor, optional
        Where the tasks run (:func:`robocal.batch.open_executor`); default serial.
        The workers must see ``out_dir`` and the inputs at the same paths.
    resume : bool
        Skip the ids whose folder holds a complete result (status ``resumed``).
    accept_implausible : bool
        As ``--accept-implausible`` of ``robocal <rig> calibrate``.
    fleet : bool
        Write ``fleet.json`` / ``fleet.html`` over every complete data set.
    reports : bool
        Write each data set's ``report.html`` (its figures are most of a
        cheap calibration's time; ``robocal report DIR/<id>/result.json``
        builds it later).
    echo : callable, optional
        Gets one line per failed data set as it fails.

    Raises
    ------
    FileFormatError
        An entry whose options or number of inputs the rig does not take
        (checked for all before any work).
    """
    from robocal.io import atomic_write_text
    from robocal.progress import progress as _progress

    out_dir = Path(out_dir)
    if wf.calibrate is None:
        raise FileFormatError(f"rig {wf.name!r} has no calibrate step: nothing to batch")
    plans = {}
    for e in entries:
        _check_inputs(wf, e)
        plans[e.id] = _split_options(wf, e)
    shutil.rmtree(out_dir / STAGING, ignore_errors=True)  # copies a killed earlier run left half-written
    rows: dict[str, dict] = {}
    todo = []
    for e in entries:
        if resume and dataset_complete(out_dir / e.id):
            rows[e.id] = {"id": e.id, "status": "resumed", "error": "", "seconds": 0.0, "residual_rms": None,
                          "inputs": [str(p) for p in e.inputs]}
        else:
            todo.append(e)

    def done(row):
        rows[row["id"]] = row
        if row["status"] == "error" and echo is not None:
            echo(f"{row['id']}: {row['error']}")

    def kwargs(e):
        return dict(load_options=plans[e.id][0], calibrate_options=plans[e.id][1],
                    accept_implausible=accept_implausible, reports=reports)

    if executor is None:
        for e in _progress(todo, desc=f"batch {wf.name}", total=len(todo), enabled=progress):
            done(calibrate_dataset(wf, e, out_dir, **kwargs(e)))
    else:
        submit = executor.submit
        futures = {}
        for e in todo:
            extra = {"pure": False, "key": f"calibrate-{e.id}-{uuid.uuid4().hex[:8]}"} \
                if type(executor).__module__.split(".")[0] == "distributed" else {}
            futures[submit(calibrate_dataset, wf, e, out_dir, **kwargs(e), **extra)] = e
        for fut in _progress(_completed(executor, list(futures)), desc=f"batch {wf.name}", total=len(futures),
                             enabled=progress):
            e = futures[fut]
            try:
                done(fut.result())
            except Exception as exc:  # noqa: BLE001 - the task itself was lost (e.g. its worker died 3 times)
                done({"id": e.id, "status": "error", "error": f"the task was lost: {_one_line(exc)}",
                      "seconds": 0.0, "residual_rms": None, "inputs": [str(p) for p in e.inputs]})
    shutil.rmtree(out_dir / STAGING, ignore_errors=True)
    ordered = [rows[e.id] for e in entries]
    outcome = BatchOutcome(out_dir, ordered)
    outcome.files.append(atomic_write_text(out_dir / "batch.json", json.dumps(
        {"schema": "robocal.batch/1", "rig": wf.name, "datasets": ordered}, indent=2) + "\n"))
    outcome.files.append(atomic_write_text(out_dir / "batch.csv", _csv(ordered)))
    if fleet:
        from robocal.batch._fleet import write_fleet

        outcome.files.extend(write_fleet(out_dir, [e.id for e in entries if rows[e.id]["status"] != "error"],
                                         rig=wf.name, failed=outcome.failed))
    return outcome


def _csv(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["id", "status", "error", "seconds", "residual_rms", "inputs"])
    for r in rows:
        w.writerow([r["id"], r["status"], r["error"], f"{r['seconds']:.3f}",
                    "" if r["residual_rms"] is None else f"{r['residual_rms']:.6g}", ";".join(r["inputs"])])
    return buf.getvalue()
