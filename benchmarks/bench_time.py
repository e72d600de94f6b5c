"""
``cvc-balance bench``'s wall time: the quick run (the default) against the full run.

Runs the command as a user does (a fresh process: imports, scenes, references, methods,
chart), the quick run ``--quick-runs`` times and the full run (``--full``) ``--full-runs``
times, into a scratch folder (docs/ is not touched), and prints each one's wall time, the
median and spread, its CPU time (less sensitive to the load than the wall time), and the
load average beside it. Then checks each quick run's conclusions against each full run's
(:func:`cvc_balance.study.bench.compare`: the methods run, the Pareto fronts to the timing
noise, the order of every two methods the full run sets 2x apart in time or 10x in error)
and prints what differs.
``--before PATH``: also time the full run of the code in PATH (a checkout of the project
before the quick run existed: ``git worktree add --detach /tmp/before <commit>``), run with
this environment, PYTHONPATH=PATH: the baseline.

    ./dev.sh run python benchmarks/bench_time.py [--quick-runs 3] [--full-runs 1]
        [--before /tmp/before]
"""

import argparse
import os
from pathlib import Path
import resource
import statistics
import subprocess
import sys
import tempfile
import time

from cvc_balance.study.bench import compare, read_rows


def timed_bench(folder, name, options=(), pythonpath=None):
    """Run the bench into ``folder``; return (wall s, CPU s, load before, CSV path)."""
    csv_path, png_path = folder / f'{name}.csv', folder / f'{name}.png'
    environment = dict(os.environ)
    if pythonpath:
        environment['PYTHONPATH'] = str(pythonpath)
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'bench', *options,
                    '--csv', str(csv_path), '--png', str(png_path)], check=True, env=environment,
                   cwd=folder, stdout=subprocess.DEVNULL)
    seconds = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return seconds, cpu, load, csv_path


def main():
    """Time the runs, print the figures and the conclusions' comparison."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick-runs', type=int, default=3)
    parser.add_argument('--full-runs', type=int, default=1)
    parser.add_argument('--before', metavar='PATH', help='checkout of the code before')
    args = parser.parse_args()
    print(f'{os.cpu_count()} cores; load average at the start {os.getloadavg()[0]:.1f}')
    timings = {}
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        runs = []
        if args.before:
            runs.append(('before (full run, the code in --before)', 'before', (), args.before))
        runs += [('full (--full)', f'full{k}', ('--full',), None)
                 for k in range(args.full_runs)]
        runs += [('quick (default)', f'quick{k}', (), None) for k in range(args.quick_runs)]
        tables = {'full (--full)': [], 'quick (default)': []}
        for label, name, options, path in runs:
            seconds, cpu, load, csv_path = timed_bench(folder, name, options, path)
            timings.setdefault(label, []).append((seconds, cpu, load))
            if label in tables:
                tables[label].append(read_rows(csv_path))
            print(f'{label:42} {seconds:7.1f} s, CPU {cpu:6.1f} s  (load average {load:.1f} '
                  'at its start)', flush=True)
        print(f"\n{'run':42} {'wall s: median':>15} {'spread':>16} {'CPU s':>7} {'runs':>5} "
              f"{'load':>10}")
        for label, values in timings.items():
            seconds = [s for s, _, _ in values]
            loads = [f'{load:.1f}' for _, _, load in values]
            print(f'{label:42} {statistics.median(seconds):15.1f} '
                  f'{min(seconds):7.1f} - {max(seconds):6.1f} '
                  f'{statistics.median(c for _, c, _ in values):7.1f} {len(values):5} '
                  f'{"/".join(loads):>10}')
        print()
        for i, quick in enumerate(tables['quick (default)']):
            for j, full in enumerate(tables['full (--full)']):
                differences = compare(quick, full)
                said = 'the same' if not differences else '; '.join(differences)
                print(f'quick run {i + 1} against full run {j + 1}: conclusions {said}')
    print(f'load average at the end {os.getloadavg()[0]:.1f}')


if __name__ == '__main__':
    main()
