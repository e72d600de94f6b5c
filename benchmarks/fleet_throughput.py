"""
The fleet's cost: bags/s and samples/s on Dask with 1 and 2 workers against one process.

A simulated fleet (``--machines`` x ``--runs`` checks with load cells: short ones by
default, as the tests make; ``--realistic``: 10-minute runs at 1 kHz, encoder and cells)
is analysed four ways, each into a fresh results table: single-process replay
(``analyse_bag`` of every bag in a loop: the floor), the fleet's ``local`` engine
(digests, rows and Parquet too), and the Dask LocalCluster with 1 and 2 worker processes
(its start-up included: a user waits for it). Each is run ``--repeat`` times, interleaved,
and printed as median and spread with the load average at its start. Overhead per bag =
(fleet time - the single-process loop's) / bags; speed-up = the single-process loop's time
/ the fleet's; CPU s/bag: of every process of the run (the client's, the workers'). Where
sessions share the CPU fairly (Linux's autogroup, on the shared development machine: two
CPU-bound processes of one session got 0.64 cores between them at load 5.6, one alone
0.67), a session's processes together get its share under load, however many they are:
there the speed-up of 2 workers shows only on idle cores, and CPU s/bag is the figure to
compare. ``--before PATH``: the fleet runs also with the code in PATH (a checkout before
the change, in a fresh process with PYTHONPATH=PATH), the baseline. A scheduler
round trip: the mean of 200 submit-and-wait of a no-op task on a 2-worker cluster. Prints
the figures; asserts nothing.

    ./dev.sh run python benchmarks/fleet_throughput.py [--machines 20] [--runs 10]
    ./dev.sh run python benchmarks/fleet_throughput.py --realistic [--keep /tmp/fleet]
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

FLEET_RUN = """
import json, sys, time
from cvc_balance.fleet import run_fleet
began = time.perf_counter()
report = run_fleet([sys.argv[1]], sys.argv[2], engine=sys.argv[3], workers=int(sys.argv[4]),
                   progress=False)
print(json.dumps({'seconds': time.perf_counter() - began, 'analysed': report.analysed,
                  'analysis_seconds': report.analysis_seconds,
                  'batch': getattr(report, 'batch', 1)}))
"""


def main():
    """Simulate the fleet, time each way of analysing it, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--machines', type=int, default=20)
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument('--rate', type=float, default=100.0, help='encoder samples/s')
    parser.add_argument('--cell-rate', type=float, help='load-cell readings/s (default --rate)')
    parser.add_argument('--steady', type=float, default=3.0,
                        help='seconds of each run at the service speed')
    parser.add_argument('--realistic', action='store_true', help='10-minute runs at 1 kHz '
                        '(--rate 1000 --steady 596), 2 machines x 6 runs unless given')
    parser.add_argument('--keep', metavar='DIR', help='simulate into DIR, or reuse its fleet')
    parser.add_argument('--repeat', type=int, default=3, help='runs of each way')
    parser.add_argument('--before', metavar='PATH', help='also the fleet runs of the code in '
                        'PATH (a checkout before the change): the baseline')
    args = parser.parse_args()
    if args.realistic:
        defaults = parser.parse_args([])
        if args.machines == defaults.machines and args.runs == defaults.runs:
            args.machines, args.runs = 2, 6
        args.rate, args.steady = 1000.0, 596.0

    from cvc_balance.bag.run_summary import analyse_bag
    from cvc_balance.fleet import find_bags, run_fleet, simulate_fleet

    layout = Path(__file__).resolve().parents[1] / 'config' / 'ct_gantry.yaml'
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(args.keep) if args.keep else Path(scratch) / 'runs'
        began = time.perf_counter()
        if not root.exists() or not any(root.iterdir()):
            simulate_fleet(layout, root, args.machines, args.runs, days=180.0, rate=args.rate,
                           cell_rate=args.cell_rate or args.rate, steady=args.steady)
        bags = [b for b, _ in find_bags([root])]
        size = sum(_bytes(b) for b in bags)
        print(f'fleet: {len(bags)} bags in {root}, {size / 1e6:.1f} MB, ready in '
              f'{time.perf_counter() - began:.1f} s; load average {os.getloadavg()[0]:.1f} on '
              f'{os.cpu_count()} cores')

        def single():
            samples = 0
            for bag in bags:
                samples += analyse_bag(bag)['accepted']
            return samples
        samples = single()              # warm: imports, page cache

        ways = [('single process (analyse_bag loop)', None, 0),
                ('fleet --engine local', 'local', 1), ('fleet, Dask, 1 worker', 'dask', 1),
                ('fleet, Dask, 2 workers', 'dask', 2)]
        if args.before:
            ways += [(f'before: {label}', engine, workers) for label, engine, workers
                     in ways[1:]]
        runs = {label: [] for label, _, _ in ways}
        for k in range(args.repeat):
            for label, engine, workers in ways:
                load = os.getloadavg()[0]
                used = _cpu()
                if engine is None:
                    seconds = _timed(single)
                    runs[label].append((seconds, load, None, 1, _cpu() - used))
                    continue
                out = Path(scratch) / f'{label.replace(" ", "_")}_{k}.parquet'
                if label.startswith('before'):
                    report = _before(args.before, root, out, engine, workers, scratch)
                else:
                    began = time.perf_counter()
                    done = run_fleet([root], out, engine=engine, workers=workers,
                                     progress=False)
                    report = {'seconds': time.perf_counter() - began,
                              'analysed': done.analysed, 'batch': done.batch,
                              'analysis_seconds': done.analysis_seconds}
                assert report['analysed'] == len(bags), report
                runs[label].append((report['seconds'], load, report['analysis_seconds'],
                                    report['batch'], _cpu() - used))
        floor = statistics.median(s for s, *_ in runs[ways[0][0]])
        print(f"\n{'how':40}{'wall s: median':>15}{'spread':>16}{'bags/s':>8}"
              f"{'M samples/s':>12}{'overhead/bag':>14}{'speed-up':>9}"
              f"{'analysis: bags/s':>17}{'batch':>6}{'CPU s/bag':>10}  load")
        for label, values in runs.items():
            seconds = statistics.median(s for s, *_ in values)
            overhead = (seconds - floor) / len(bags) * 1e3
            analysis = [a for _, _, a, _, _ in values if a]
            rate = f'{len(bags) / statistics.median(analysis):17.1f}' if analysis else ' ' * 17
            loads = '/'.join(f'{load:.1f}' for _, load, _, _, _ in values)
            cpu = statistics.median(c for *_, c in values) / len(bags)
            print(f'{label:40}{seconds:15.2f}{min(s for s, *_ in values):8.2f} -'
                  f'{max(s for s, *_ in values):6.2f}{len(bags) / seconds:8.1f}'
                  f'{samples / seconds / 1e6:12.3f}{overhead:12.1f}ms{floor / seconds:8.2f}x'
                  f'{rate}{values[0][3]:6}{cpu:10.3f}  {loads}')
        _round_trip()
        print(f'load average at the end {os.getloadavg()[0]:.1f} (the machine is shared: '
              'see the load beside each figure)')


def _before(path, root, out, engine, workers, scratch):
    """Run the fleet with the code in ``path`` in a fresh process; return its figures."""
    done = subprocess.run([sys.executable, '-c', FLEET_RUN, str(root), str(out), engine,
                           str(workers)], check=True, capture_output=True, text=True,
                          cwd=scratch, env=dict(os.environ, PYTHONPATH=str(path)))
    return json.loads(done.stdout.strip().splitlines()[-1])


def _round_trip():
    from dask.distributed import Client, LocalCluster
    began = time.perf_counter()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    client = Client(cluster)
    started = time.perf_counter() - began
    client.submit(abs, -1, pure=False).result()
    began = time.perf_counter()
    for i in range(200):
        client.submit(abs, -i, pure=False).result()
    trip = (time.perf_counter() - began) / 200
    client.close()
    cluster.close()
    print(f'LocalCluster (2 worker processes) start {started:.2f} s; scheduler round trip '
          f'(submit a no-op, wait for its result) {trip * 1e3:.2f} ms')


def _cpu():
    """CPU seconds of this process and of its children that ended (workers, --before runs)."""
    import resource
    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def _timed(function):
    began = time.perf_counter()
    function()
    return time.perf_counter() - began


def _bytes(path):
    if path.is_dir():
        return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
    return path.stat().st_size


if __name__ == '__main__':
    main()
