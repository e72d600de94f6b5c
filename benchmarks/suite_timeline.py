"""
Where a test run's time goes: each test's CPU and wall time, and when each worker ran it.

A pytest plugin and its report. The plugin writes, per worker, every test's CPU seconds
(this process's own and its children's that were waited for, so a node, player or command
the test started and stopped counts; a process killed and never waited for, such as the
rerun viewer's binary, does not), its wall seconds (setup, call and teardown) and its
start; the report prints each worker's busy span, the files with most CPU and wall time,
and the tests that waited most (wall much longer than CPU: a lock, a sleep, a process)::

    CVC_TIMELINE=/tmp/timeline PYTHONPATH=benchmarks ./dev.sh test -p suite_timeline
    ./dev.sh run python benchmarks/suite_timeline.py /tmp/timeline

It showed the alone tests waiting 60-137 s each for the lock in the middle of a run, while
the other workers took test after test (conftest.py now runs their files last).
"""

import argparse
import collections
import json
import os
from pathlib import Path
import resource
import time

import pytest

_ROWS = []


def _cpu_seconds():
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Measure one test: setup, call and teardown."""
    own, children = _cpu_seconds()
    began, wall = time.time(), time.perf_counter()
    yield
    own_after, children_after = _cpu_seconds()
    _ROWS.append({'test': item.nodeid, 'cpu': own_after - own,
                  'children_cpu': children_after - children,
                  'wall': time.perf_counter() - wall, 'start': began,
                  'worker': os.environ.get('PYTEST_XDIST_WORKER', 'main')})


def pytest_sessionfinish(session):
    """Write this process's rows to $CVC_TIMELINE/<pid>.json."""
    folder = os.environ.get('CVC_TIMELINE')
    if folder and _ROWS:
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / f'{os.getpid()}.json').write_text(json.dumps(_ROWS))


def report(folder, top=15):
    """Print the figures of the rows in ``folder``."""
    rows = [row for path in sorted(Path(folder).glob('*.json'))
            for row in json.loads(path.read_text())]
    if not rows:
        raise SystemExit(f'no timeline rows in {folder}')
    start = min(row['start'] for row in rows)
    cpu = sum(row['cpu'] + row['children_cpu'] for row in rows)
    end = max(row['start'] + row['wall'] for row in rows) - start
    print(f'{len(rows)} tests, {end:.0f} s from the first start to the last end, '
          f'{cpu:.0f} s of CPU measured')
    workers = collections.defaultdict(list)
    for row in rows:
        workers[row['worker']].append(row)
    for worker, mine in sorted(workers.items()):
        last = max(row['start'] + row['wall'] for row in mine) - start
        print(f'  {worker}: {len(mine)} tests, its last ended at {last:.0f} s')
    files = collections.defaultdict(lambda: [0.0, 0.0, float('inf'), 0.0])
    for row in rows:
        entry = files[row['test'].split('::')[0]]
        entry[0] += row['cpu'] + row['children_cpu']
        entry[1] += row['wall']
        entry[2] = min(entry[2], row['start'] - start)
        entry[3] = max(entry[3], row['start'] + row['wall'] - start)
    print(f'\n{"CPU s":>7}{"wall s":>8}{"from":>7}{"to":>7}  file (most CPU first)')
    for name, (used, wall, first, last) in sorted(files.items(), key=lambda f: -f[1][0])[:top]:
        print(f'{used:7.1f}{wall:8.1f}{first:7.0f}{last:7.0f}  {name}')
    print(f'\n{"wall s":>7}{"CPU s":>7}  tests that waited most (wall - CPU)')
    for row in sorted(rows, key=lambda r: -(r['wall'] - r['cpu'] - r['children_cpu']))[:top]:
        print(f'{row["wall"]:7.1f}{row["cpu"] + row["children_cpu"]:7.1f}  {row["test"]}')


def main():
    """Print the report of a timeline folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('folder', help='the CVC_TIMELINE folder of a run')
    parser.add_argument('--top', type=int, default=15)
    args = parser.parse_args()
    report(args.folder, args.top)


if __name__ == '__main__':
    main()
