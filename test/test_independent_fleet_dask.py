"""
The fleet's Dask engine in this process: a scheduler and worker threads, not processes.

test/test_fleet.py runs 100 bags through a LocalCluster of worker processes (its fixture
~20 s; a mutation run cannot see into those processes). Here one LocalCluster of threads
(``processes=False``) serves every test: the engine's bookkeeping by hand (tasks kept in
flight IN_FLIGHT per worker thread, every item's outcome once, a task that breaks turned
into failure rows in the words people read), the cluster it would make (its arguments
recorded), and a run of two bags whose rows are those of the local engine. Starting the
scheduler and its threads costs about a second, once.
"""

import logging
import os
from pathlib import Path
import time

import pyarrow.parquet as pq
import pytest
import yaml

from cvc_balance.fleet import engine
from cvc_balance.fleet.engine import _Dask, IN_FLIGHT, run_fleet
from cvc_balance.fleet.simulate import simulate_fleet

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def cluster():
    from dask.distributed import LocalCluster
    made = LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                        dashboard_address=None, silence_logs=logging.ERROR)
    yield made
    made.close()


def slow_length(item):
    time.sleep(0.002)
    return len(item)


def test_tasks_kept_in_flight_a_few_per_worker_and_each_outcome_once(cluster):
    with _Dask(cluster.scheduler_address, None) as run:
        assert run.workers == 2 and run.cluster is None
        assert run.client.scheduler.address == cluster.scheduler_address
        real = run.client.submit
        state = {'submitted': 0, 'taken': 0, 'most': 0, 'pure': set()}

        def submit(function, item, pure):
            state['submitted'] += 1
            state['pure'].add(pure)
            state['most'] = max(state['most'], state['submitted'] - state['taken'])
            return real(function, item, pure=pure)
        run.client.submit = submit
        items = [[k] * (k % 3 + 1) for k in range(25)]
        got = []
        for outcome in run.map(slow_length, items, 'digest', False):
            state['taken'] += 1
            got.append(outcome)
        assert sorted(got) == sorted(len(item) for item in items)
        # IN_FLIGHT a worker thread, and the one submitted in place of a finished task
        # before that task's outcome is handed over.
        assert state['most'] == IN_FLIGHT * 2 + 1 and state['pure'] == {False}
        assert list(run.map(slow_length, [], 'digest', False)) == []
        client = run.client
    assert client.status == 'closed'
    assert cluster.status.name == 'running'             # a given scheduler is left running


def test_progress_said_on_request_and_a_failure_inside_a_run_raised(cluster, capsys):
    items = [[k] * (k % 3 + 1) for k in range(25)]           # 49 bags in 25 tasks
    with _Dask(cluster.scheduler_address, None) as run:
        assert len(list(run.map(slow_length, items, 'digest', True))) == 25
        said = capsys.readouterr().err
        assert 'digest:   0%|' in said and ' 0/49 [' in said
        assert len(list(run.map(slow_length, items, 'analyse', False))) == 25
        assert capsys.readouterr().err == ''
    with pytest.raises(KeyError):
        with _Dask(cluster.scheduler_address, None):
            raise KeyError('a bug inside a run')


def test_a_scheduler_that_does_not_answer_is_said(monkeypatch):
    import dask.distributed
    asked = []

    def client(address, timeout):
        asked.append((address, timeout))
        raise TimeoutError('timed out after 20 s')
    monkeypatch.setattr(dask.distributed, 'Client', client)
    with pytest.raises(OSError) as caught:
        _Dask('tcp://10.0.0.9:8786', None)
    assert str(caught.value) == 'no Dask scheduler at tcp://10.0.0.9:8786: timed out after 20 s'
    assert asked == [('tcp://10.0.0.9:8786', '20s')]


def test_a_task_that_breaks_fails_each_of_its_bags_in_words(cluster, monkeypatch):
    def broken(item):
        raise RuntimeError('the worker\nran out of memory')
    monkeypatch.setattr(engine, 'identify_bag_files', broken)
    before = time.time_ns()
    with _Dask(cluster.scheduler_address, None) as run:
        (digests,) = list(run.map(broken, [['/a/1.mcap', '/a/2.mcap']], 'digest', False))
        (analysed,) = list(run.map(lambda item: 1 / 0, [[
            ('/a/3.mcap', '/a', 'd3', (30, 300), 'bags/3.mcap'),
            ('/a/4.mcap', '/a', 'd4', (40, 400), 'bags/4.mcap')]], 'analyse', False))
    reason = 'worker lost: RuntimeError: the worker ran out of memory'
    assert digests == [('/a/1.mcap', None, reason), ('/a/2.mcap', None, reason)]
    reason = 'worker lost: ZeroDivisionError: division by zero'
    assert [status for status, _ in analysed] == ['failed', 'failed']
    rows = [row for _, row in analysed]
    assert [{k: v for k, v in row.items() if k != 'failed_at'} for row in rows] == [
        {'digest': d, 'bag': f'bags/{n}.mcap', 'bag_bytes': size, 'bag_mtime_ns': mtime,
         'machine_id': None, 'machine_source': None, 'reason': reason}
        for d, n, size, mtime in (('d3', 3, 30, 300), ('d4', 4, 40, 400))]
    for row in rows:
        assert before // 1000 * 1000 <= row['failed_at'] <= time.time_ns()
        assert row['failed_at'] % 1000 == 0
    long = 'x' * 400
    assert engine._lost(broken, ['/b'], OSError(long)) == [
        ('/b', None, f'worker lost: OSError: {"x" * 300}... (400 characters)')]


class Made:
    """A LocalCluster's stand-in: the arguments it got, the fixture's cluster behind it."""

    def __init__(self, cluster, record):
        self._cluster, self._record = cluster, record

    def __getattr__(self, name):
        return getattr(self._cluster, name)

    def close(self):
        self._record['closed'] = True


def test_the_cluster_it_makes_and_a_run_on_it_gives_the_local_engines_rows(
        cluster, monkeypatch, tmp_path):
    import dask
    import dask.distributed
    made = []

    def local_cluster(**kwargs):
        record = dict(kwargs, environ=dask.config.get('distributed.nanny.pre-spawn-environ'))
        made.append(record)
        return Made(cluster, record)
    monkeypatch.setattr(dask.distributed, 'LocalCluster', local_cluster)
    environ = dask.config.get('distributed.nanny.pre-spawn-environ')
    assert environ.get('MALLOC_TRIM_THRESHOLD_') is not None        # Dask's default
    with _Dask(None, 3) as run:
        assert run.workers == 2                       # the threads the cluster has
        assert run.client.scheduler.address == cluster.scheduler_address
    record = made.pop()
    assert record == {'n_workers': 3, 'threads_per_worker': 1, 'processes': True,
                      'dashboard_address': None, 'silence_logs': logging.ERROR,
                      'environ': {k: v for k, v in environ.items()
                                  if k != 'MALLOC_TRIM_THRESHOLD_'}, 'closed': True}
    assert dask.config.get('distributed.nanny.pre-spawn-environ') == environ
    # A run on Dask by default: the worker processes the cores give, at most 2.
    layout = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
    (tmp_path / 'gantry.yaml').write_text(yaml.safe_dump(layout))
    simulate_fleet(tmp_path / 'gantry.yaml', tmp_path / 'runs', machines=2, runs=1,
                   rate=20.0, cell_rate=20.0, steady=0.2, seed=3)
    report = run_fleet([tmp_path / 'runs'], tmp_path / 'dask.parquet', progress=False)
    (record,) = made
    assert record['n_workers'] == min(2, os.cpu_count() or 1) and record['closed']
    assert (report.engine, report.workers, report.found, report.analysed) == ('dask', 2, 2, 2)
    # The workers asked for, the default for 8 cores and for an unknown count; a scheduler.
    for workers, cores, want in ((1, 2, 1), (None, 8, 2), (None, None, 1)):
        monkeypatch.setattr(os, 'cpu_count', lambda: cores)
        run_fleet([tmp_path / 'runs'], tmp_path / 'again.parquet', workers=workers,
                  progress=False)
        assert made[-1]['n_workers'] == want
    report = run_fleet([tmp_path / 'runs'], tmp_path / 'given.parquet',
                       scheduler=cluster.scheduler_address, progress=False)
    assert len(made) == 4 and (report.workers, report.analysed) == (2, 2)
    local = run_fleet([tmp_path / 'runs'], tmp_path / 'local.parquet', engine='local',
                      progress=False)
    assert (local.found, local.analysed) == (2, 2)
    timing = {'analysed_at', 'analysis_seconds'}
    rows = [{k: v for k, v in row.items() if k not in timing}
            for row in sorted(pq.read_table(tmp_path / 'dask.parquet').to_pylist(),
                              key=lambda row: row['bag'])]
    assert rows == [{k: v for k, v in row.items() if k not in timing}
                    for row in sorted(pq.read_table(tmp_path / 'local.parquet').to_pylist(),
                                      key=lambda row: row['bag'])]
