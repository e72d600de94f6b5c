"""
A pytest plugin for mutation runs: each test starts without traced programs or tables.

:mod:`cvc_balance.physics.compensated` and :mod:`cvc_balance.physics.inertia` trace their
kernels and build their cos/sin table once per process and keep them. In one mutation
run's process that hides mutants: mutmut records which tests reach each function while
the caches fill (so ``trace_cos_sin`` or the table is put down to the first few tests
only, not to the accuracy tests), and a mutant is tested with those few. Emptied before
each test, every test that needs a program traces it again, from the code under test.
``benchmarks/mutation.py`` loads it (``-p fresh_programs``) for the modules in FRESH.
"""

import threading

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """Empty the program caches, the table and the threads' bound programs."""
    from cvc_balance.physics import compensated, inertia
    compensated._COS_SIN.clear()
    compensated._TABLES.clear()
    compensated._LOCAL = threading.local()
    inertia._PROGRAMS.clear()
    inertia._LOCAL = threading.local()
