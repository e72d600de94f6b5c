"""
Write test/file_costs.txt: the seconds each test file took in a run, most first.

conftest.py runs the files in that order, so that ``./dev.sh test``'s workers take the
longest files first and end together (pytest-xdist's own order puts the files with the
most tests first: the few long live tests then came last, one worker running them alone
at the end). From a JUnit XML report of a whole run::

    ./dev.sh test --junitxml=/tmp/run.xml
    ./dev.sh run python benchmarks/test_costs.py /tmp/run.xml

A stale list costs only time: a file not listed runs after the listed ones.
"""

import argparse
from collections import Counter
from pathlib import Path
import xml.etree.ElementTree as ElementTree

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'test' / 'file_costs.txt'


def file_costs(report):
    """Return {test file (test/name.py): seconds} of a JUnit XML report."""
    costs = Counter()
    for case in ElementTree.parse(report).iter('testcase'):
        module = case.get('classname', '').split('.')
        name = next((part for part in module if part.startswith('test_')), None)
        if name is not None:
            costs[f'test/{name}.py'] += float(case.get('time', 0.0))
    return costs


def main():
    """Read the report, write the list."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('report', type=Path, help='JUnit XML report of a whole run')
    args = parser.parse_args()
    costs = file_costs(args.report)
    lines = ['# Seconds each test file took (benchmarks/test_costs.py), most first: conftest.py',
             '# runs the files in this order. Regenerate when files are added or change cost.']
    lines += [f'{seconds:7.1f} {name}' for name, seconds in costs.most_common()]
    OUT.write_text('\n'.join(lines) + '\n')
    print(f'{OUT}: {len(costs)} files, {sum(costs.values()):.0f} s in all')


if __name__ == '__main__':
    main()
