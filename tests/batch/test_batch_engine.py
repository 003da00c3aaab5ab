"""open_executor: serial without Dask for one worker, an embedded LocalCluster, an existing scheduler."""

import pytest
from batch_toy import write_fleet

from robocal.batch import load_manifest, open_executor, run_batch
from robocal.errors import InputError


def test_one_worker_is_serial_and_bad_arguments_are_refused():
    with open_executor(1) as ex:
        assert ex is None
    with pytest.raises(InputError, match="--workers must be >= 1, got 0"):
        with open_executor(0):
            pass
    with pytest.raises(InputError, match="exclude each other"):
        with open_executor(2, "tcp://127.0.0.1:8786"):
            pass


def test_an_existing_cluster_is_used_as_it_is(tmp_path, toy):
    distributed = pytest.importorskip("distributed")
    lines = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as cluster:
        with open_executor(scheduler=cluster.scheduler_address, echo=lines.append) as client:
            assert sum(client.nthreads().values()) == 2
            outcome = run_batch(toy, load_manifest(write_fleet(tmp_path / "in", 3)), tmp_path / "out",
                                executor=client, fleet=False)
        assert len(cluster.workers) == 2  # the cluster outlives the batch: it is not ours to stop
    assert [r["status"] for r in outcome.rows] == ["ok"] * 3
    assert len(lines) == 1
    assert lines[0].startswith(f"dask: scheduler {cluster.scheduler_address}, 2 worker(s), 2 thread(s); dashboard ")


def test_the_embedded_cluster_says_what_it_started():
    pytest.importorskip("distributed")
    lines = []
    with open_executor(2, echo=lines.append) as client:
        assert len(client.nthreads()) == 2 and set(client.nthreads().values()) == {1}  # processes, 1 thread each
    assert lines[0].startswith("dask: local cluster of 2 worker process(es); dashboard ")
