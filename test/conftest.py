"""Shared fixtures: no node process outlives its test, even a failed one; the slow mark."""

from pathlib import Path

import pytest

from ros_harness import NodeProcess

SLOW = {line.strip() for line in (Path(__file__).parent / 'slow_tests.txt').read_text()
        .splitlines() if line.strip() and not line.startswith('#')}
"""Tests marked slow (``file::function``, or a whole ``file``): ``--quick`` leaves them out."""


def pytest_collection_modifyitems(config, items):
    """Mark each test named in slow_tests.txt slow (every parameter of it; a file: all)."""
    for item in items:
        file = f'{item.path.parent.name}/{item.path.name}'
        if file in SLOW or f'{file}::{item.originalname}' in SLOW:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def stop_leftover_nodes():
    """Stop node processes a test started but did not stop (it failed before)."""
    yield
    for node in list(NodeProcess.running):
        node.stop()
