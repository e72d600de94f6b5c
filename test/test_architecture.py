"""
The package's architecture as a test: one-way imports between layers, no cycles.

Every ``import`` of every module (those inside functions too) is read with ``ast``, so a
lazy import cannot hide an upward dependency. Layers, lowest first: the physics; the
message contract; bags, the rerun view and the methods study; the ROS adapters; the
command line. A package may import its own modules and those of lower layers only. A new
subpackage must be given its layer here, or this test fails.
"""

import ast
from pathlib import Path
import sys

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'cvc_balance'

LAYERS = {
    'physics': 0,      # numpy only: layouts, engine, unbalance, ISO 21940, motion
    'files': 0,        # output paths: checked, written under a temporary name (stdlib)
    'identify': 1,     # the unbalance from measured support loads (numpy)
    'field': 1,        # field balancing: 1x readings, influence coefficients, weight plans
    'messages': 1,     # topic names and types, CDR, ros2msg schemas (no rclpy)
    'design': 1,       # sensitivities, tolerance stacks, balance points, sweeps and charts
    'bag': 2,          # MCAP reading and writing, replay, scenarios (no rclpy)
    'view': 2,         # rerun
    'study': 2,        # methods side by side, the 40-digit reference, the bench
    'report': 2,       # the field-balancing report: HTML and PNG figures
    'ros': 3,          # the node, play, record
    'fleet': 3,        # every run of every machine on Dask, Parquet tables, trends
    'cli': 4,          # the cvc-balance command
}

THIRD_PARTY = {
    # What each layer may import beyond the standard library and the package itself.
    'physics': {'numpy', 'yaml', 'msgspec'},
    'files': set(),
    'identify': {'numpy'},
    'field': {'numpy', 'scipy'},
    'messages': {'ament_index_python'},
    'design': {'numpy', 'scipy', 'yaml', 'matplotlib'},   # matplotlib in design/charts only
    'bag': {'numpy', 'yaml', 'mcap', 'zstandard', 'lz4', 'isal', 'rosbags'},
    'view': {'numpy', 'rerun', 'PIL'},
    'study': {'numpy', 'mpmath', 'matplotlib'},
    'report': {'numpy', 'matplotlib'},
    'fleet': {'numpy', 'scipy', 'yaml', 'pyarrow', 'duckdb', 'dask', 'matplotlib', 'tqdm'},
}


def modules():
    """Yield (dotted name, path) of every module of the package."""
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        yield '.'.join(parts), path


def imports(path):
    """Return the absolute module names that the file at ``path`` imports, at any depth."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f'{path}: relative import (use absolute ones)'
            names.add(node.module)
            # `from cvc_balance.physics import compensated` imports a module too.
            names.update(f'{node.module}.{alias.name}' for alias in node.names)
    return names


def layer(module):
    """Return the subpackage of ``cvc_balance.X.y`` (None for the package itself)."""
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else None


MODULES = dict(modules())


def test_every_subpackage_has_a_layer():
    packages = {layer(name) for name in MODULES} - {None}
    assert packages == set(LAYERS), f'give each subpackage a layer: {packages ^ set(LAYERS)}'


@pytest.mark.parametrize('module', sorted(MODULES))
def test_imports_go_down_only(module):
    own = layer(module)
    for name in imports(MODULES[module]):
        top = name.split('.')[0]
        if top == 'cvc_balance':
            target = layer(name)
            assert target is not None, f'{module} imports the package root'
            assert target == own or LAYERS[target] < LAYERS[own], \
                f'{module} (layer {own}) imports {name} (layer {target}): upward or sideways'
        elif own in THIRD_PARTY and top not in sys.stdlib_module_names:
            assert top in THIRD_PARTY[own], f'{module} (layer {own}) imports {top}'


def test_no_import_cycles():
    graph = {module: {name for name in imports(path) if name in MODULES and name != module}
             for module, path in MODULES.items()}
    # A package's __init__ importing its own modules is how it names its API; a module
    # importing a sibling through the package name is not a cycle of modules.
    for module in graph:
        graph[module] = {t for t in graph[module]
                         if not (module.startswith(t + '.') or t.startswith(module + '.'))}
    visiting, done = [], set()

    def visit(module):
        if module in visiting:
            cycle = visiting[visiting.index(module):] + [module]
            raise AssertionError('import cycle: ' + ' -> '.join(cycle))
        if module in done:
            return
        visiting.append(module)
        for target in sorted(graph[module]):
            visit(target)
        visiting.pop()
        done.add(module)

    for module in sorted(graph):
        visit(module)


def test_an_upward_import_is_caught(tmp_path):
    # The check itself: a physics module importing the node must fail it.
    bad = tmp_path / 'bad.py'
    bad.write_text('def f():\n    from cvc_balance.ros.balance_monitor import main\n')
    MODULES['cvc_balance.physics.bad'] = bad
    try:
        with pytest.raises(AssertionError, match='upward or sideways'):
            test_imports_go_down_only('cvc_balance.physics.bad')
    finally:
        del MODULES['cvc_balance.physics.bad']
