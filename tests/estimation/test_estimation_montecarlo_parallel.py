"""Monte Carlo on an executor: one SeedSequence child per trial, so any number of workers gives the same bits."""

import concurrent.futures as cf
import subprocess
import sys

import numpy as np
import pytest

from robocal.errors import ConvergenceError, InputError, ShapeError
from robocal.estimation import default_batch_size, executor_workers, monte_carlo


def _study():
    """A nonlinear fit (exponential decay, LM) whose trials sometimes fail: closures, as users write them.

    Defined inside a function so that Dask's cloudpickle ships them by value
    (the test module is not importable by name in a worker process).
    """
    from robocal.errors import ConvergenceError
    from robocal.estimation import Problem, solve

    t = np.linspace(0.0, 4.0, 30)

    def simulate(rng):
        truth = np.array([2.0, 1.3, 0.5]) + rng.normal(0.0, 0.05, 3)
        y = truth[0] * np.exp(-truth[1] * t) + truth[2] + rng.normal(0.0, 0.02, t.size)
        return y, truth

    def estimate(y):
        if y[0] > 2.6:  # a deterministic function of the trial's draws: fails in the same trials everywhere
            raise ConvergenceError("planted failure")
        p = Problem(lambda q: q["p"][0] * np.exp(-q["p"][1] * t) + q["p"][2] - y)
        p.add_block("p", np.array([1.0, 1.0, 0.0]))
        return solve(p, method="lm")

    return simulate, estimate


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as cluster, distributed.Client(cluster) as client:
        yield client


def _same(a, b):
    for name in ("errors", "predicted_std", "bias", "std", "rmse"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)  # bit for bit
    assert a.mean_sq_norm == b.mean_sq_norm and a.failures == b.failures and a.n_trials == b.n_trials
    assert np.array_equal(a.coverage.spread_ratio, b.coverage.spread_ratio)


def test_serial_trials_are_those_of_rng_spawn():
    # trial i draws from rng.spawn(n)[i], as before executors: earlier studies keep their numbers
    simulate, estimate = _study()
    n = 12
    mc = monte_carlo(simulate, estimate, n, np.random.default_rng(5))
    drawn = [simulate(g) for g in np.random.default_rng(5).spawn(n)]
    expect = np.array([estimate(y).x - truth for y, truth in drawn if y[0] <= 2.6])
    assert 0 < len(mc.failures) < n and [i for i, _ in mc.failures] == [i for i, (y, _) in enumerate(drawn) if y[0] > 2.6]
    np.testing.assert_array_equal(mc.errors, expect)


def test_thread_pools_of_1_and_2_and_every_batch_size_give_the_serial_bits():
    simulate, estimate = _study()
    serial = monte_carlo(simulate, estimate, 40, np.random.default_rng(7))
    assert serial.failures, "the study should plant a failed trial to check their indices too"
    for workers, batch in ((1, None), (2, None), (2, 1), (2, 7), (2, 40)):
        with cf.ThreadPoolExecutor(workers) as ex:
            _same(serial, monte_carlo(simulate, estimate, 40, np.random.default_rng(7), executor=ex,
                                      batch_size=batch))


def test_two_dask_workers_give_the_serial_bits(dask_client):
    simulate, estimate = _study()
    serial = monte_carlo(simulate, estimate, 40, np.random.default_rng(8))
    par = monte_carlo(simulate, estimate, 40, np.random.default_rng(8), executor=dask_client, batch_size=3)
    _same(serial, par)
    # both workers took part: the trials really ran elsewhere
    assert executor_workers(dask_client) == 2


def test_a_shape_slip_names_the_same_trial_on_an_executor():
    def simulate(rng):
        return rng.normal(size=3), np.zeros(3)

    def estimate(y):
        return y if y[0] < 1.0 else y[:2]

    with pytest.raises(ShapeError) as serial:
        monte_carlo(simulate, estimate, 30, np.random.default_rng(1), error=lambda est, truth: est)
    with cf.ThreadPoolExecutor(2) as ex, pytest.raises(ShapeError) as par:
        monte_carlo(simulate, estimate, 30, np.random.default_rng(1), executor=ex, batch_size=4,
                    error=lambda est, truth: est)
    assert str(serial.value) == str(par.value)


def test_bad_arguments_and_all_failed():
    simulate, _ = _study()
    with pytest.raises(InputError, match="batch_size"):
        monte_carlo(simulate, lambda y: y, 4, np.random.default_rng(0), batch_size=0)

    def fail(y):
        raise ConvergenceError("never")

    with cf.ThreadPoolExecutor(2) as ex, pytest.raises(ConvergenceError, match="all 4"):
        monte_carlo(simulate, fail, 4, np.random.default_rng(0), executor=ex)


def test_default_batch_size_gives_about_four_tasks_a_worker():
    assert default_batch_size(10_000, 2) == 1250
    assert default_batch_size(3, 8) == 1
    assert executor_workers(None) == 1


def test_the_serial_path_imports_no_dask():
    code = ("import sys, numpy as np\n"
            "from robocal.estimation import monte_carlo\n"
            "monte_carlo(lambda g: (g.normal(size=2), np.zeros(2)), lambda y: y, 5, np.random.default_rng(0),"
            " workers=1)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"
