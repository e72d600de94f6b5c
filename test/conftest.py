"""Shared fixtures: no node process outlives its test, even a failed one."""

import pytest

from ros_harness import NodeProcess


@pytest.fixture(autouse=True)
def stop_leftover_nodes():
    """Stop node processes a test started but did not stop (it failed before)."""
    yield
    for node in list(NodeProcess.running):
        node.stop()
