"""run_batch: one row per data set, each written whole or not at all; resume; a killed worker; a killed batch."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from batch_toy import make_toy_workflow, write_fleet

from robocal.batch import dataset_complete, load_manifest, run_batch
from robocal.errors import FileFormatError
from robocal.io import load_result


def _check_landed(out, ids):
    """Every id complete, loadable, written once (its run manifest lists exactly its files); no staging left."""
    for i in ids:
        assert dataset_complete(out / i), i
        m = json.loads((out / i / ".robocal-run.json").read_text())
        assert m["state"] == "complete" and sorted(m["files"]) == ["report.html", "result.json"]
        assert sorted(p.name for p in (out / i).iterdir()) == [".robocal-run.json", "report.html", "result.json"]
        load_result(out / i / "result.json")
    assert not (out / ".staging").exists()


def test_a_failed_data_set_is_one_row_and_the_batch_goes_on(tmp_path, toy):
    manifest = write_fleet(tmp_path / "in", 6, fail={"r02"})
    (tmp_path / "in" / "r04.yaml").unlink()  # a missing file fails that data set alone
    lines = []
    outcome = run_batch(toy, load_manifest(manifest), tmp_path / "out", echo=lines.append)
    status = {r["id"]: r["status"] for r in outcome.rows}
    assert status == {"r00": "ok", "r01": "ok", "r02": "error", "r03": "ok", "r04": "error", "r05": "ok"}
    rows = {r["id"]: r for r in outcome.rows}
    assert rows["r02"]["error"].endswith("planted failure of r02") and "r02.yaml" in rows["r02"]["error"]
    assert "r04.yaml" in rows["r04"]["error"] and "\n" not in rows["r04"]["error"]
    assert sorted(lines) == sorted(f"{i}: {rows[i]['error']}" for i in ("r02", "r04"))
    _check_landed(tmp_path / "out", ["r00", "r01", "r03", "r05"])
    assert not (tmp_path / "out" / "r02").exists() and not (tmp_path / "out" / "r04").exists()
    saved = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert [r["status"] for r in saved["datasets"]] == [r["status"] for r in outcome.rows]
    assert (tmp_path / "out" / "batch.csv").read_text().count("\n") == 7
    assert "4 of 6" in outcome.summary() and "r02, r04" in outcome.summary()


def test_manifest_options_reach_the_calibrate_step_and_unknown_ones_are_refused(tmp_path, toy):
    manifest = write_fleet(tmp_path / "in", 2)
    plain = run_batch(toy, load_manifest(manifest), tmp_path / "plain", fleet=False)
    entries = load_manifest(manifest)
    scaled = [type(e)(e.id, e.inputs, {"scale": 2.0}, e.where) for e in entries]
    run_batch(toy, scaled, tmp_path / "scaled", fleet=False)
    for i in ("r00", "r01"):
        a = load_result(tmp_path / "plain" / i / "result.json").estimate["a"]
        assert load_result(tmp_path / "scaled" / i / "result.json").estimate["a"] == 2.0 * a
    bad = [type(e)(e.id, e.inputs, {"scael": 2.0}, e.where) for e in entries]
    with pytest.raises(FileFormatError, match="'scael' is not one of 'toy calibrate' .known: scale"):
        run_batch(toy, bad, tmp_path / "bad")
    assert plain.failed == []


def test_resume_keeps_what_is_done_and_redoes_what_failed(tmp_path, toy):
    manifest = write_fleet(tmp_path / "in", 4, fail={"r01"})
    out = tmp_path / "out"
    run_batch(toy, load_manifest(manifest), out)
    before = {i: (out / i / "result.json").stat().st_mtime_ns for i in ("r00", "r02", "r03")}
    write_fleet(tmp_path / "in", 4)  # the failed recording is fixed (and the others' files change too)
    again = run_batch(toy, load_manifest(manifest), out, resume=True)
    assert [r["status"] for r in again.rows] == ["resumed", "ok", "resumed", "resumed"]
    assert {i: (out / i / "result.json").stat().st_mtime_ns for i in before} == before  # not written twice
    _check_landed(out, ["r00", "r01", "r02", "r03"])
    assert json.loads((out / "fleet.json").read_text())["n_robots"] == 4


KILLED_BATCH = """
import sys
sys.path.insert(0, {support!r})
from batch_toy import make_toy_workflow
from robocal.batch import load_manifest, run_batch
run_batch(make_toy_workflow(), load_manifest({manifest!r}), {out!r})
"""


def test_a_batch_killed_half_way_loses_nothing(tmp_path):
    manifest = write_fleet(tmp_path / "in", 6, sleep=0.4)
    out = tmp_path / "out"
    code = KILLED_BATCH.format(support=str(Path(__file__).parent), manifest=str(manifest), out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while sum(dataset_complete(out / f"r{i:02d}") for i in range(6)) < 2:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the batch did not finish 2 data sets in 120 s"
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    done = [f"r{i:02d}" for i in range(6) if dataset_complete(out / f"r{i:02d}")]
    assert 2 <= len(done) < 6
    # what the kill interrupted is a staging copy, never a half folder under its id
    assert all(dataset_complete(p) for p in out.iterdir() if p.is_dir() and p.name != ".staging")
    again = run_batch(make_toy_workflow(), load_manifest(manifest), out, resume=True)
    assert [r["id"] for r in again.rows if r["status"] == "resumed"] == done
    _check_landed(out, [f"r{i:02d}" for i in range(6)])


def test_a_killed_worker_re_runs_its_tasks_elsewhere(tmp_path):
    distributed = pytest.importorskip("distributed")
    attempts = tmp_path / "attempts"
    attempts.mkdir()
    wf = make_toy_workflow(attempts)
    manifest = write_fleet(tmp_path / "in", 8, sleep=1.0, fail={"r05"})
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=50) as cluster, distributed.Client(cluster) as client:
        pids = client.run(os.getpid)
        victim = sorted(pids.values())[0]

        def kill_when_busy():
            # both workers are in a task once two attempts have started
            deadline = time.monotonic() + 60
            while len(list(attempts.iterdir())) < 2 and time.monotonic() < deadline:
                time.sleep(0.02)
            os.kill(victim, signal.SIGKILL)

        import threading

        killer = threading.Thread(target=kill_when_busy)
        killer.start()
        outcome = run_batch(wf, load_manifest(manifest), out, executor=client)
        killer.join()
    rows = {r["id"]: r for r in outcome.rows}
    assert set(rows) == {f"r{i:02d}" for i in range(8)}
    assert rows.pop("r05")["error"].endswith("planted failure of r05")
    assert all(r["status"] == "ok" for r in rows.values()), rows
    _check_landed(out, sorted(rows))
    made = [p.name.split(".")[0] for p in attempts.iterdir()]
    assert len(made) > 8, "the killed worker's task should have been attempted again"
    # the re-run results equal a serial run's: the attempt that died wrote nothing
    serial = run_batch(make_toy_workflow(), load_manifest(manifest), tmp_path / "serial", fleet=False)
    for i in rows:
        assert load_result(out / i / "result.json").estimate == load_result(tmp_path / "serial" / i / "result.json").estimate
    assert serial.failed[0]["id"] == "r05"
    assert np.isfinite(json.loads((out / "fleet.json").read_text())["parameters"]["a"]["median"])
