"""
The lists conftest.py marks and orders tests by name real tests and files.

slow_tests.txt and alone_tests.txt mark tests; file_costs.txt orders the files.

A renamed or deleted test left in a list would silently stop being marked: a slow test
back in ``--quick``, a live test run beside another worker. Each entry is checked against
the test file's own definitions (read with ``ast``, not with the lists' reader).
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def entries(name):
    lines = (ROOT / 'test' / name).read_text().splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith('#')]


@pytest.mark.parametrize('listing', ['slow_tests.txt', 'alone_tests.txt'])
def test_every_listed_test_exists(listing):
    listed = entries(listing)
    assert listed and len(listed) == len(set(listed)), 'empty, or a test listed twice'
    for entry in listed:
        file, _, function = entry.partition('::')
        path = ROOT / file
        assert path.is_file() and path.name.startswith('test_'), entry
        defined = {node.name for node in ast.parse(path.read_text()).body
                   if isinstance(node, ast.FunctionDef)}
        assert not function or function in defined, entry


def test_every_file_in_the_cost_list_exists_once():
    lines = entries('file_costs.txt')
    names = [line.split()[1] for line in lines]
    assert names and len(names) == len(set(names)), 'empty, or a file listed twice'
    seconds = [float(line.split()[0]) for line in lines]
    assert seconds == sorted(seconds, reverse=True), 'most first'
    for name in names:
        path = ROOT / name
        assert path.is_file() and path.name.startswith('test_'), name
