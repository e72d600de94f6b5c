"""
A big YAML layout read from its file: peak memory and time, this checkout against another.

Writes a layout of N point masses as block YAML (the way people write layouts, about
107 bytes per component), then reads it with :func:`load_layout` in a fresh Python
process per measurement and prints: the file's size; the wall-clock time of the read;
the growth of the process's peak resident memory during the read (``ru_maxrss`` after,
less the resident size before: libyaml's buffers counted too); that growth over the
file's size (the brief's bound: under 3); with ``--tracemalloc``, the peak of Python's
own allocations (numpy's included) in a second process. With ``--compare DIR``, the
same reads with the package of another checkout (e.g. ``/work/main``): before and
after. A read that fails prints its one line (``MemoryError``, a refusal).

    ./dev.sh run python benchmarks/layout_memory.py [--components N ...]
        [--compare /work/main] [--tracemalloc] [--limit-gb G]
"""

import argparse
import json
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile

HERE = Path(__file__).resolve().parents[1]

CHILD = r'''
import json, resource, sys, time, tracemalloc
path, traced = sys.argv[1], sys.argv[2] == '1'
import cvc_balance
from cvc_balance.physics.layout_file import load_layout
def resident():
    with open('/proc/self/statm') as stream:
        return int(stream.read().split()[1]) * resource.getpagesize()
before = resident()
if traced:
    tracemalloc.start()
start = time.perf_counter()
try:
    layout = load_layout(path)
    outcome = f'{len(layout.components)} components'
except BaseException as error:                   # MemoryError too: reported, not raised
    outcome = f'{type(error).__name__}: {str(error)[:120]}'
seconds = time.perf_counter() - start
peak = tracemalloc.get_traced_memory()[1] if traced else None
grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - before
print(json.dumps({'seconds': seconds, 'grown': grown, 'traced': peak, 'outcome': outcome,
                  'package': cvc_balance.__file__}))
'''


def write_layout(n, path, seed=1):
    """Write a block-YAML layout of ``n`` point masses to ``path``; return its size, bytes."""
    rng = random.Random(seed)
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write('name: big\ncomponents:\n')
        for k in range(n):
            stream.write(f'  - name: c{k:07d}\n    mass: {rng.uniform(0.1, 50):.9g}\n'
                         f'    radius: {rng.uniform(0, 0.8):.9g}\n'
                         f'    angle: {rng.uniform(-3, 3):.9g}\n'
                         f'    z: {rng.uniform(-0.2, 0.2):.9g}\n')
        stream.write('supports:\n  - {name: front, z: -0.25}\n'
                     '  - {name: rear, z: 0.25, axial: true}\n')
    return path.stat().st_size


def measure(root, path, traced, limit_gb):
    """
    Read ``path`` with the package under ``root`` in a child process; return its record.

    The child is the checkout's own environment's Python (``.venv``; an editable install
    finds its package before PYTHONPATH would), else this one with PYTHONPATH.
    """
    python = root / '.venv' / 'bin' / 'python'
    python = str(python) if python.exists() else sys.executable
    env = dict(os.environ, PYTHONPATH=str(root))
    limit = int(limit_gb * 2**30)

    def cap():                                    # the child's address space, bytes
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    done = subprocess.run([python, '-c', CHILD, str(path), '1' if traced else '0'],
                          env=env, cwd=root, capture_output=True, text=True, preexec_fn=cap,
                          check=False)
    lines = done.stdout.strip().splitlines()
    if done.returncode or not lines:
        tail = (done.stderr.strip().splitlines() or ['?'])[-1]
        return {'seconds': None, 'grown': None, 'traced': None, 'outcome': tail[:120]}
    record = json.loads(lines[-1])
    if not record['package'].startswith(str(root)):
        raise SystemExit(f'{root}: the child read the package at {record["package"]}')
    return record


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--components', type=int, nargs='+', default=[45_000, 450_000])
    parser.add_argument('--compare', metavar='DIR', help='another checkout to read with too')
    parser.add_argument('--tracemalloc', action='store_true',
                        help="also the peak of Python's allocations (slower)")
    parser.add_argument('--limit-gb', type=float, default=8.0,
                        help="the child's address-space limit, GiB (default 8)")
    args = parser.parse_args()
    roots = [('this', HERE)] + ([('compare', Path(args.compare).resolve())]
                                if args.compare else [])
    print(f'block YAML layouts of point masses; load average {os.getloadavg()[0]:.1f}; '
          'one fresh process per read')
    print(f'{"components":>10} {"MB":>6} {"checkout":>28} {"read s":>7} {"peak MB":>8} '
          f'{"x text":>6} {"traced MB":>9}  outcome')
    with tempfile.TemporaryDirectory() as scratch:
        for n in args.components:
            path = Path(scratch) / f'layout_{n}.yaml'
            size = write_layout(n, path)
            for label, root in roots:
                rows = [measure(root, path, False, args.limit_gb)]
                if args.tracemalloc:
                    rows.append(measure(root, path, True, args.limit_gb))
                r = rows[0]
                traced = rows[-1]['traced'] if args.tracemalloc else None
                seconds = '-' if r['seconds'] is None else f'{r["seconds"]:.1f}'
                grown = '-' if r['grown'] is None else f'{r["grown"] / 1e6:.0f}'
                ratio = '-' if r['grown'] is None else f'{r["grown"] / size:.2f}'
                traced = '-' if traced is None else f'{traced / 1e6:.0f}'
                print(f'{n:>10} {size / 1e6:6.1f} {str(root)[-28:]:>28} {seconds:>7} '
                      f'{grown:>8} {ratio:>6} {traced:>9}  {r["outcome"]}', flush=True)
    print(f'load average {os.getloadavg()[0]:.1f} at the end; peak MB: the growth of the '
          'resident peak during the read (MB = 10^6 bytes)')


if __name__ == '__main__':
    main()
