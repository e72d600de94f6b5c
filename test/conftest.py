"""Shared fixtures: no node process outlives its test, even a failed one; slow and alone."""

import fcntl
import os
from pathlib import Path

import pytest

from ros_harness import NodeProcess


def _listed(name):
    """Return the tests a list beside this file names (``file::function`` or ``file``)."""
    return {line.strip() for line in (Path(__file__).parent / name).read_text().splitlines()
            if line.strip() and not line.startswith('#')}


SLOW = _listed('slow_tests.txt')
"""Tests marked slow (``file::function``, or a whole ``file``): ``--quick`` leaves them out."""
ALONE = _listed('alone_tests.txt')
"""Tests marked alone: under xdist no other test runs beside them (live timing)."""


def _file_costs():
    """Return {test file: seconds} of file_costs.txt (benchmarks/test_costs.py writes it)."""
    costs = {}
    for line in (Path(__file__).parent / 'file_costs.txt').read_text().splitlines():
        if line.strip() and not line.startswith('#'):
            seconds, name = line.split()
            costs[name] = float(seconds)
    return costs


COSTS = _file_costs()
"""Seconds each file took in a measured run: the longest files run first."""


def pytest_collection_modifyitems(config, items):
    """
    Mark tests slow and alone by their lists; order the files longest first, alone last.

    Longest first: with ``./dev.sh test``'s workers (``--no-loadscope-reorder``: files
    in this order) the long files start early and the workers end together. A file not
    in file_costs.txt comes after those listed; a file's own tests keep their order.
    Files with a test marked alone come at the very end, when the other workers have no
    file left to start: earlier, a test waiting for the lock alone waited while they took
    test after test (a lock shared is granted beside a waiting exclusive one), 60-137 s
    each, and the files queued behind it on its worker waited with it.
    Each test named in slow_tests.txt is marked slow, in alone_tests.txt alone (a test
    may also be marked alone where it is written).
    """
    def file_of(item):
        return f'{item.path.parent.name}/{item.path.name}'
    for item in items:
        file = file_of(item)
        for listed, mark in ((SLOW, pytest.mark.slow), (ALONE, pytest.mark.alone)):
            if file in listed or f'{file}::{item.originalname}' in listed:
                item.add_marker(mark)
    alone_files = {file_of(item) for item in items if item.get_closest_marker('alone')}
    items.sort(key=lambda item: (file_of(item) in alone_files, -COSTS.get(file_of(item), 0.0)))


@pytest.fixture(autouse=True)
def alone_when_marked(request, tmp_path_factory):
    """
    With pytest-xdist workers, run a test marked ``alone`` with no other test beside it.

    Every test holds a shared lock on a file of this run (in the workers' common temporary
    folder, or ``CVC_TEST_LOCK``: dev.sh's colcon run beside the tests holds it shared too)
    while it runs; a test marked alone holds it exclusively, so it waits for the other
    workers' tests to end and they wait for it.
    """
    path = os.environ.get('CVC_TEST_LOCK')
    if 'PYTEST_XDIST_WORKER' not in os.environ and path is None:   # nothing runs beside
        yield
        return
    with open(path or tmp_path_factory.getbasetemp().parent / 'alone.lock', 'a') as lock:
        alone = request.node.get_closest_marker('alone') is not None
        fcntl.flock(lock, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        yield


@pytest.fixture(autouse=True)
def stop_leftover_nodes():
    """Stop node processes a test started but did not stop (it failed before)."""
    yield
    for node in list(NodeProcess.running):
        node.stop()
