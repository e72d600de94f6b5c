"""
The fleet's cost: bags/s and samples/s on Dask with 1 and 2 workers against one process.

A simulated fleet (``--machines`` x ``--runs`` short checks with load cells, as the tests
make, or ``--rate`` Hz for longer bags) is analysed four ways, each into a fresh results
table: single-process replay (``analyse_bag`` of every bag in a loop: the floor), the
fleet's ``local`` engine (digests, rows and Parquet too), and the Dask LocalCluster with 1
and 2 worker processes (its start-up timed apart). Overhead per bag = (fleet time - the
single-process loop's) / bags. A scheduler round trip: the mean of 200 submit-and-wait
of a no-op task on the 2-worker cluster. Prints the figures; asserts nothing.

    ./dev.sh run python benchmarks/fleet_throughput.py [--machines 20] [--runs 10]
"""

import argparse
import os
from pathlib import Path
import tempfile
import time


def main():
    """Simulate the fleet, time each way of analysing it, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--machines', type=int, default=20)
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument('--rate', type=float, default=100.0, help='encoder samples/s')
    parser.add_argument('--cell-rate', type=float, help='load-cell readings/s (default --rate)')
    parser.add_argument('--steady', type=float, default=3.0,
                        help='seconds of each run at the service speed (596: 10-minute runs)')
    parser.add_argument('--keep', metavar='DIR', help='simulate into DIR, or reuse its fleet')
    parser.add_argument('--repeat', type=int, default=2, help='best of this many')
    args = parser.parse_args()

    from dask.distributed import Client, LocalCluster

    from cvc_balance.bag.run_summary import analyse_bag
    from cvc_balance.fleet import find_bags, run_fleet, simulate_fleet

    layout = Path(__file__).resolve().parents[1] / 'config' / 'ct_gantry.yaml'
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch) / 'runs'
        began = time.perf_counter()
        simulate_fleet(layout, root, args.machines, args.runs, days=180.0, rate=args.rate,
                       cell_rate=args.rate)
        bags = [b for b, _ in find_bags([root])]
        size = sum(_bytes(b) for b in bags)
        print(f'fleet: {len(bags)} bags ({args.machines} machines x {args.runs} runs), '
              f'{size / 1e6:.1f} MB, simulated in {time.perf_counter() - began:.1f} s; '
              f'load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores')

        def single():
            samples = 0
            for bag in bags:
                samples += analyse_bag(bag)['accepted']
            return samples
        samples = single()              # warm: imports, page cache
        best = {}
        best['single process (analyse_bag loop)'] = min(
            _timed(single) for _ in range(args.repeat))

        def fleet(engine, workers, k):
            out = Path(scratch) / f'{engine}{workers}_{k}.parquet'
            report = run_fleet([root], out, engine=engine, workers=workers, progress=False)
            assert report.analysed == len(bags), report
            return report
        reports = {}
        for engine, workers in (('local', 1), ('dask', 1), ('dask', 2)):
            runs = []
            for k in range(args.repeat):
                began = time.perf_counter()
                report = fleet(engine, workers, k)
                runs.append((time.perf_counter() - began, report))
            label = f'fleet --engine {engine}' + (f' --workers {workers}'
                                                  if engine == 'dask' else '')
            best[label], reports[label] = min(runs, key=lambda r: r[0])
        floor = best['single process (analyse_bag loop)']
        print(f"{'how':38}{'wall s':>9}{'bags/s':>9}{'M samples/s':>13}"
              f"{'overhead/bag':>14}{'  analysis only: bags/s':>24}")
        for label, seconds in best.items():
            report = reports.get(label)
            overhead = (seconds - floor) / len(bags) * 1e3
            analysis = f'{len(bags) / report.analysis_seconds:24.1f}' if report else ''
            print(f'{label:38}{seconds:9.2f}{len(bags) / seconds:9.1f}'
                  f'{samples / seconds / 1e6:13.3f}{overhead:12.1f}ms{analysis}')

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
        print('the machine is shared: figures taken under load (see the load average above)')


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
