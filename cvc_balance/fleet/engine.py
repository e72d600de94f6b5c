"""
A fleet run: find the bags, skip those already analysed, analyse the rest, write the tables.

Two stages, each on the engine (Dask or this process): the new bags' content digests
(:mod:`cvc_balance.fleet.digest`; a bag whose size and time are those already recorded
keeps its digest unread), then the analysis of each bag whose digest is in neither
table (:func:`cvc_balance.fleet.tasks.analyse`). Workers get paths (absolute), never
bytes. Tasks are kept in flight a few per worker thread, not all submitted at once, so a
run of millions of bags holds a bounded number of futures. Results are written every
``checkpoint`` seconds and at the end (:mod:`cvc_balance.fleet.store`): a stopped run
keeps what it had written, and the next run goes on from there.

Engines: ``dask`` (default): an embedded ``LocalCluster`` of worker processes (one
thread each: the engine's numpy releases the GIL only in part), or an existing
scheduler (``scheduler='tcp://host:8786'``) whose workers see the same paths and have
cvc_balance installed; ``local``: one process, no Dask (the baseline).
"""

from dataclasses import dataclass, field
import logging
import os
from pathlib import Path
import sys
import time


from cvc_balance.fleet import store
from cvc_balance.fleet.digest import stat_key
from cvc_balance.fleet.discover import find_bags
from cvc_balance.fleet.rows import FAILURE_SCHEMA, failure_row, RESULT_SCHEMA, table
from cvc_balance.fleet.tasks import analyse_batch, identify_bag_files

ENGINES = ('dask', 'local')
IN_FLIGHT = 4
"""Tasks kept submitted per worker thread."""
DIGEST_BATCH = 32
DIGEST_BYTES = 64 << 20
"""Bags whose digest one task takes: up to DIGEST_BATCH, and up to ~DIGEST_BYTES of them
(reading is fast and tasks have a fixed cost, but a task that hashes a gigabyte of ten-minute
runs keeps one worker busy while the others wait for the next stage)."""
TASK_BYTES = 4 << 20
MAX_BATCH = 16
"""Automatic batches: small bags share a task up to ~4 MB (at most 16 bags), a task
costing ~2-20 ms on the scheduler here; never fewer than IN_FLIGHT tasks per worker."""


@dataclass
class FleetReport:
    """What a fleet run found, skipped, analysed and wrote."""

    results: str
    failures: str
    engine: str
    workers: int = 0
    batch: int = 1                # bags per analysis task
    found: int = 0
    already: int = 0             # bags whose digest was in the results
    failed_before: int = 0       # bags whose digest was in the failures (not retried)
    duplicates: int = 0          # bags with the same content as another found in this run
    analysed: int = 0
    failed: int = 0
    rows: int = 0
    samples: int = 0
    seconds: float = 0.0
    digest_seconds: float = 0.0
    analysis_seconds: float = 0.0
    new_failures: list = field(default_factory=list)    # (bag, reason)


def run_fleet(paths, results, engine='dask', scheduler=None, workers=None, progress=None,
              retry_failures=False, checkpoint=60.0, batch=None):
    """
    Analyse every new bag under ``paths`` into ``results`` (Parquet); return a FleetReport.

    ``workers``: LocalCluster worker processes (default: the machine's cores, at most
    2 here); ``progress``: show a progress bar (default: on a terminal);
    ``retry_failures``: analyse again the bags that failed before; ``batch``: bags per
    analysis task (default: by size, see :data:`TASK_BYTES`). Raises ValueError for a
    results file that is not a fleet table.
    """
    if engine not in ENGINES:
        raise ValueError(f'engine {engine!r}: give one of {", ".join(ENGINES)}')
    started = time.perf_counter()
    results = Path(results)
    failures = store.failures_path(results)
    old = store.read(results, RESULT_SCHEMA)
    old_failures = store.read(failures, FAILURE_SCHEMA)
    report = FleetReport(str(results), str(failures), engine)
    bags = find_bags(paths)
    report.found = len(bags)
    show = sys.stderr.isatty() if progress is None else progress
    with _engine(engine, scheduler, workers) as run:
        report.workers = run.workers
        # Stage 1: content digests (those of unchanged bags from the tables).
        known = _known_digests(old, old_failures)
        stats = {}
        for bag, _ in bags:
            try:
                stats[bag] = stat_key(bag)
            except OSError:
                stats[bag] = None
        digests = {bag: known.get((str(bag), stats[bag])) for bag, _ in bags}
        unknown = [bag for bag, _ in bags if digests[bag] is None]
        moment = time.perf_counter()
        batches = [[os.path.abspath(b) for b in part]
                   for part in digest_batches(unknown, [(stats[b] or (0,))[0] for b in unknown])]
        by_absolute = {os.path.abspath(b): b for b in unknown}
        unreadable = []
        for outcome in run.map(identify_bag_files, batches, 'digest', show):
            for path, stat, digest in outcome:
                bag = by_absolute[path]
                if stat is None:
                    unreadable.append((bag, digest))
                else:
                    stats[bag], digests[bag] = stat, digest
        report.digest_seconds = time.perf_counter() - moment
        # Stage 2: analyse what is new.
        done = set(old.column('digest').to_pylist())
        failed = set(old_failures.column('digest').to_pylist())
        todo, seen = [], set()
        for bag, root in bags:
            digest = digests[bag]
            if digest is None:
                continue
            if digest in done:
                report.already += 1
            elif digest in failed and not retry_failures:
                report.failed_before += 1
            elif digest in seen:
                report.duplicates += 1
            else:
                seen.add(digest)
                todo.append((os.path.abspath(bag), os.path.abspath(root), digest,
                             stats[bag], str(bag)))
        new_rows, new_failures = [], []
        now = time.time_ns() // 1000 * 1000
        for bag, reason in unreadable:
            new_failures.append(failure_row(None, bag, (None, None), (None, None), reason, now))
        moment = time.perf_counter()
        last_write = time.monotonic()
        if batch is None:
            batch = automatic_batch([item[3][0] for item in todo], run.workers)
        report.batch = batch
        tasks = [todo[i:i + batch] for i in range(0, len(todo), max(1, batch))]
        retried = {item[2] for item in todo} & failed
        for outcome in run.map(analyse_batch, tasks, 'analyse', show):
            for status, payload in outcome:
                if status == 'ok':
                    new_rows += payload
                    report.analysed += 1
                    report.samples += payload[0]['accepted']
                else:
                    new_failures.append(payload)
            if time.monotonic() - last_write > checkpoint:
                _write(results, failures, new_rows, new_failures, retried)
                last_write = time.monotonic()
        report.analysis_seconds = time.perf_counter() - moment
    _write(results, failures, new_rows, new_failures, retried)
    report.failed = len(new_failures)
    report.rows = len(new_rows)
    report.new_failures = [(row['bag'], row['reason']) for row in new_failures]
    report.seconds = time.perf_counter() - started
    return report


def digest_batches(bags, sizes):
    """Split ``bags`` (``sizes`` bytes) into digest tasks: see :data:`DIGEST_BYTES`."""
    batches, batch, total = [], [], 0
    for bag, size in zip(bags, sizes):
        if batch and (len(batch) == DIGEST_BATCH or total + size > DIGEST_BYTES):
            batches.append(batch)
            batch, total = [], 0
        batch.append(bag)
        total += size
    return batches + [batch] if batch else batches


def automatic_batch(sizes, workers):
    """Return bags per task for bags of ``sizes`` (bytes): see :data:`TASK_BYTES`."""
    if not sizes:
        return 1
    typical = max(float(sorted(sizes)[len(sizes) // 2]), 1.0)
    batch = int(min(MAX_BATCH, max(1, TASK_BYTES // typical)))
    most = max(1, len(sizes) // (IN_FLIGHT * max(workers, 1)))
    return max(1, min(batch, most))


def _known_digests(*tables):
    """{(bag, (bytes, mtime ns)): digest} of the bags the tables hold."""
    known = {}
    for stored in tables:
        columns = stored.select(['bag', 'bag_bytes', 'bag_mtime_ns', 'digest']).to_pydict()
        for bag, size, mtime, digest in zip(columns['bag'], columns['bag_bytes'],
                                            columns['bag_mtime_ns'], columns['digest']):
            if digest is not None and size is not None:
                known[(bag, (size, mtime))] = digest
    return known


def _write(results, failures, new_rows, new_failures, retried):
    """
    Add this run's rows to both tables as they are now (retried failures replaced).

    Under the tables' lock, read again: another run writing the same tables meanwhile
    keeps its rows (:func:`cvc_balance.fleet.store.merged`).
    """
    with store.locked(results):
        if new_rows or not results.exists():
            store.write(results, store.merged(store.read(results, RESULT_SCHEMA),
                                              table(new_rows, RESULT_SCHEMA)))
        if new_failures or retried or not failures.exists():
            # A retried bag's old failure goes: it failed again (added back) or it is done.
            store.write(failures, store.merged(store.read(failures, FAILURE_SCHEMA),
                                               table(new_failures, FAILURE_SCHEMA), retried))


class _Local:
    """Run tasks in this process, one after the other."""

    workers = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def map(self, function, items, label, show):
        """Yield function(item) for each item (a list of bags), in order."""
        bar = _bar(items, label, show)
        for item in items:
            yield function(item)
            bar.update(len(item))
        bar.close()


class _Dask:
    """Run tasks on a Dask cluster: an embedded LocalCluster, or an existing scheduler."""

    def __init__(self, scheduler, workers):
        from dask.distributed import Client, LocalCluster
        self.cluster = None
        if scheduler:
            try:
                self.client = Client(scheduler, timeout='20s')
            except (OSError, TimeoutError) as error:
                raise OSError(f'no Dask scheduler at {scheduler}: {error}') from None
        else:
            import dask
            # Dask sets MALLOC_TRIM_THRESHOLD_ in its workers, so glibc hands freed memory
            # back at once and each bag's arrays are faulted in anew: on 8 ten-minute bags
            # 3.6x the page faults of one process, 2.6 s more system time. Its other
            # settings (one BLAS thread a worker process) stay.
            environ = {name: value for name, value in
                       dask.config.get('distributed.nanny.pre-spawn-environ', {}).items()
                       if name != 'MALLOC_TRIM_THRESHOLD_'}
            with dask.config.set({'distributed.nanny.pre-spawn-environ': environ}):
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None,
                                            silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
        self.workers = sum(self.client.nthreads().values())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        return False

    def map(self, function, items, label, show):
        """Yield function(item) (item: a list of bags) as tasks finish, a few in flight."""
        from dask.distributed import as_completed
        bar = _bar(items, label, show)
        pending = iter(items)
        window = max(1, IN_FLIGHT * self.workers)
        running = as_completed()
        origin = {}

        def submit(count):
            for item in pending:
                future = self.client.submit(function, item, pure=False)
                origin[future.key] = item
                running.add(future)
                count -= 1
                if not count:
                    return
        submit(window)
        for future in running:
            item = origin.pop(future.key)
            try:
                outcome = future.result()
            except Exception as error:  # the worker died (KilledWorker) or the task broke
                outcome = _lost(function, item, error)
            future.release()
            submit(1)
            bar.update(len(item))
            yield outcome
        bar.close()


def _lost(function, item, error):
    """Return the outcome of a task that did not come back: each of its bags failed."""
    from cvc_balance.physics.layout import one_line
    reason = f'worker lost: {type(error).__name__}: {one_line(error, 300)}'
    now = time.time_ns() // 1000 * 1000
    if function is identify_bag_files:
        return [(path, None, reason) for path in item]
    return [('failed', failure_row(digest, label, stat, (None, None), reason, now))
            for _, _, digest, stat, label in item]


def _engine(engine, scheduler, workers):
    if engine == 'local':
        if scheduler:
            raise ValueError('--scheduler needs --engine dask')
        return _Local()
    return _Dask(scheduler, workers or min(2, os.cpu_count() or 1))


def _bar(items, label, show):
    from tqdm import tqdm
    total = sum(len(item) for item in items)
    return tqdm(total=total, desc=label, unit='bag', file=sys.stderr,
                disable=not show or not total, leave=False)
