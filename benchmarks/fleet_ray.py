"""
Ray against Dask for the fleet's job, on the same simulated bags (ray is no dependency).

The issue asks to use Ray Data if it does this job clearly better here. Ray is not
installed by ``dev.sh``; to run this, put it beside the environment, not in it:

    ./dev.sh run python -m pip install --target /tmp/raypkgs ray==2.60.0
    PYTHONPATH=/tmp/raypkgs ./dev.sh run python benchmarks/fleet_ray.py [--runs 10]

Times, best of ``--repeat``, for the analysis of every bag (``tasks.analyse_batch`` on
paths, the rows returned to the driver): Ray tasks (``ray.remote``, 2 worker processes,
the cluster started apart; one bag a task, then ``--batch`` bags a task), Ray Data
(``from_items(...).map``) where it imports, and Dask's LocalCluster with 2 workers
(``client.map``); the cluster start-ups; a round trip of a no-op task on each. Prints
the figures; asserts nothing.
"""

import argparse
import os
from pathlib import Path
import tempfile
import time


def main():
    """Simulate the fleet, time Ray and Dask on it, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--machines', type=int, default=20)
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument('--repeat', type=int, default=2)
    parser.add_argument('--batch', type=int, default=8, help='bags per task, second row')
    args = parser.parse_args()

    os.environ.setdefault('RAY_AUTH_MODE', 'disabled')     # a local cluster: no token file
    import ray
    from dask.distributed import Client, LocalCluster

    from cvc_balance.fleet import content_digest, find_bags, simulate_fleet
    from cvc_balance.fleet.digest import stat_key
    from cvc_balance.fleet.tasks import analyse_batch

    layout = Path(__file__).resolve().parents[1] / 'config' / 'ct_gantry.yaml'
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch) / 'runs'
        simulate_fleet(layout, root, args.machines, args.runs, days=180.0)
        items = [[(str(b.resolve()), str(root.resolve()), content_digest(b), stat_key(b),
                   str(b))] for b, _ in find_bags([root])]
        print(f'{len(items)} bags; load average {os.getloadavg()[0]:.1f} on '
              f'{os.cpu_count()} cores (the machine is shared: figures under load)')

        def check(outcomes):
            assert sum(len(o) for o in outcomes) == len(items)

        began = time.perf_counter()
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                 runtime_env={'env_vars': {'PYTHONPATH': os.environ.get('PYTHONPATH', '')}})
        remote = ray.remote(num_cpus=1)(analyse_batch)
        ray.get(remote.remote([]))                      # workers up
        ray_start = time.perf_counter() - began
        batched = [sum(items[i:i + args.batch], []) for i in range(0, len(items), args.batch)]
        ray_times, ray_batched = [], []
        for _ in range(args.repeat):
            began = time.perf_counter()
            check(ray.get([remote.remote(item) for item in items]))
            ray_times.append(time.perf_counter() - began)
            began = time.perf_counter()
            check(ray.get([remote.remote(item) for item in batched]))
            ray_batched.append(time.perf_counter() - began)
        noop = ray.remote(num_cpus=1)(_noop)
        ray.get(noop.remote(-1))
        began = time.perf_counter()
        for i in range(200):
            ray.get(noop.remote(-i))
        ray_trip = (time.perf_counter() - began) / 200
        data_times, data_note = [], ''
        try:
            import ray.data
            for _ in range(args.repeat):
                began = time.perf_counter()
                rows = ray.data.from_items([{'item': item} for item in items]).map(
                    lambda row: {'n': len(analyse_batch(row['item']))}).take_all()
                assert len(rows) == len(items)
                data_times.append(time.perf_counter() - began)
        except Exception as error:  # Ray Data needs extras (pandas) this install may lack
            data_note = f'Ray Data not run: {type(error).__name__}: {str(error)[:120]}'
        ray.shutdown()

        began = time.perf_counter()
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        client.submit(analyse_batch, [], pure=False).result()
        dask_start = time.perf_counter() - began
        dask_times, dask_batched = [], []
        for _ in range(args.repeat):
            began = time.perf_counter()
            check(client.gather(client.map(analyse_batch, items, pure=False)))
            dask_times.append(time.perf_counter() - began)
            began = time.perf_counter()
            check(client.gather(client.map(analyse_batch, batched, pure=False)))
            dask_batched.append(time.perf_counter() - began)
        client.submit(_noop, -1, pure=False).result()
        began = time.perf_counter()
        for i in range(200):
            client.submit(_noop, -i, pure=False).result()
        dask_trip = (time.perf_counter() - began) / 200
        client.close()
        cluster.close()

        n = len(items)
        print(f"{'engine (2 workers)':28}{'start s':>9}{'analysis s':>12}{'bags/s':>9}"
              f"{'round trip ms':>15}")
        print(f"{'Ray tasks':28}{ray_start:9.2f}{min(ray_times):12.2f}"
              f"{n / min(ray_times):9.1f}{ray_trip * 1e3:15.2f}")
        print(f"{f'Ray tasks, {args.batch} bags a task':28}{'':9}{min(ray_batched):12.2f}"
              f"{n / min(ray_batched):9.1f}")
        if data_times:
            print(f"{'Ray Data (map)':28}{'':9}{min(data_times):12.2f}"
                  f"{n / min(data_times):9.1f}")
        print(f"{'Dask LocalCluster':28}{dask_start:9.2f}{min(dask_times):12.2f}"
              f"{n / min(dask_times):9.1f}{dask_trip * 1e3:15.2f}")
        print(f"{f'Dask, {args.batch} bags a task':28}{'':9}{min(dask_batched):12.2f}"
              f"{n / min(dask_batched):9.1f}")
        if data_note:
            print(data_note)


def _noop(value):
    return value


if __name__ == '__main__':
    main()
