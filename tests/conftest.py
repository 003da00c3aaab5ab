"""Suite-wide test settings.

Hypothesis runs derandomized by default so that CI on a clean clone is
repeatable: a fuzz test fails on a change of the code, not on the luck of the
draw (stop 10's CI failed on a case no earlier run had drawn). To hunt for new
failures, run with fresh random examples::

    HYPOTHESIS_PROFILE=explore python -m pytest -q -k "fuzz or property"

Test order is random (pytest-randomly, in the test extra; the header prints
``--randomly-seed=N`` to reproduce an order, ``-p no:randomly`` switches it
off). It reseeds ``random`` and NumPy's global state before each test, which
no test relies on (randomness comes from a seeded ``np.random.Generator``),
and it does not touch Hypothesis: with ``derandomize=True`` Hypothesis draws
from a seed of its own per test, so the examples are the same in any order.
"""

import os
from pathlib import Path

import pytest
from hypothesis import settings

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


#: node ids marked `slow` from tests/heavy_tests.txt (see its header)
_HEAVY = {line.strip() for line in (Path(__file__).parent / "heavy_tests.txt").read_text(encoding="utf-8").splitlines()
          if line.strip() and not line.startswith("#")}


def pytest_configure(config):
    # One BLAS thread per xdist worker unless the caller chose: with one worker per core, OpenBLAS's
    # default (a thread per core in every worker) oversubscribes the cores, and its threads spin while
    # waiting, so the small factorisations the estimators run get slower, not faster. Set here, in the
    # controller before the workers start, because the workers inherit the environment and read it when
    # NumPy is first imported.
    if (getattr(config.option, "numprocesses", 0) or 0) > 1 and "PYTEST_XDIST_WORKER" not in os.environ:
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid in _HEAVY:
            item.add_marker(pytest.mark.slow)
