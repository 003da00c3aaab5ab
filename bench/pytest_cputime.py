"""A pytest plugin: CPU seconds per test (its process plus the subprocesses it waited for), slowest first.

On a shared machine wall times (``--durations``) measure the neighbours; CPU time measures the
test (OpenBLAS's spinning threads included). Use with one process::

    PYTHONPATH=bench python -m pytest tests/camera -n 0 -p no:randomly -p pytest_cputime
"""

import os

import pytest

_rows = []


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    t0 = os.times()
    yield
    t1 = os.times()
    cpu = sum(getattr(t1, k) - getattr(t0, k) for k in ("user", "system", "children_user", "children_system"))
    _rows.append((cpu, item.nodeid))


def pytest_terminal_summary(terminalreporter):
    terminalreporter.write_line("CPU-s  test (setup + call + teardown)")
    for cpu, nodeid in sorted(_rows, reverse=True)[:30]:
        terminalreporter.write_line(f"{cpu:6.2f}  {nodeid}")
    terminalreporter.write_line(f"total {sum(r[0] for r in _rows):.1f} CPU-s over {len(_rows)} tests")
