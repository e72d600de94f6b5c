"""
The fleet's files by hand: digests, the bags found, what a task reads, the tables, batches.

References: SHA-256 by :mod:`hashlib` over the bytes the digest's description names
(written here, not by the package), ``os.stat``, file trees and batch sizes worked out by
hand, the tables read back by pyarrow, a second ``flock`` on the lock file. Every bag here
is a few bytes (a failure in microseconds) or the bundled ``tilted_shift.mcap`` (0.3 s).
"""

import fcntl
import hashlib
import os
from pathlib import Path
import shutil
import socket
import sys
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from cvc_balance.fleet import digest as fleet_digest
from cvc_balance.fleet import engine, store, tasks
from cvc_balance.fleet.discover import find_bags, is_bag_directory
from cvc_balance.fleet.rows import FAILURE_SCHEMA, RESULT_SCHEMA, table

ROOT = Path(__file__).resolve().parents[1]
TILTED = ROOT / 'bags' / 'tilted_shift.mcap'


# -- digest ------------------------------------------------------------------------------------

def test_a_files_digest_is_the_sha256_of_its_bytes_read_in_pieces(tmp_path):
    """Two and a half pieces of 1 MiB, one byte, nothing: hashlib over the whole bytes."""
    data = np.random.default_rng(29).integers(0, 256, (5 << 19) + 3, np.uint8).tobytes()
    for size in (len(data), 1 << 20, 1, 0):
        path = tmp_path / f'{size}.mcap'
        path.write_bytes(data[:size])
        assert fleet_digest.content_digest(path) == hashlib.sha256(data[:size]).hexdigest()
        assert fleet_digest.content_digest(str(path)) == hashlib.sha256(data[:size]).hexdigest()


def test_a_directorys_digest_names_sizes_and_bytes_of_its_files_in_name_order(tmp_path):
    """
    Each regular, not hidden file as (8-byte length, name, 8-byte size, bytes), by name.

    A name that is not UTF-8 (the byte 0xff) goes in as its bytes; a hidden file and a
    folder inside count for nothing; renaming the directory changes nothing, renaming a
    file does.
    """
    bag = tmp_path / 'run'
    bag.mkdir()
    content = {b'metadata.yaml': b'rosbag2_bagfile_information: {}\n',
               b'run_0.mcap': bytes(range(256)) * 4100, b'\xffodd.db3': b'\x00\x01'}
    for name, data in content.items():
        with open(os.path.join(os.fsencode(bag), name), 'wb') as stream:
            stream.write(data)
    (bag / '.hidden').write_bytes(b'never read')
    (bag / 'inner').mkdir()
    (bag / 'inner' / 'x.mcap').write_bytes(b'never read')
    by_hand = hashlib.sha256()
    for name in sorted(content, key=os.fsdecode):
        by_hand.update(len(name).to_bytes(8, 'little') + name)
        by_hand.update(len(content[name]).to_bytes(8, 'little') + content[name])
    assert fleet_digest.content_digest(bag) == by_hand.hexdigest()
    moved = bag.rename(tmp_path / 'elsewhere')
    assert fleet_digest.content_digest(moved) == by_hand.hexdigest()
    (moved / 'run_0.mcap').rename(moved / 'run_1.mcap')
    assert fleet_digest.content_digest(moved) != by_hand.hexdigest()


def test_a_bags_stat_key_is_its_size_and_newest_time(tmp_path):
    """A file: (size, mtime ns); a directory: its files' sizes summed, their newest time."""
    one = tmp_path / 'one.mcap'
    one.write_bytes(b'12345')
    os.utime(one, ns=(7, 1_700_000_000_123_456_789))
    assert fleet_digest.stat_key(one) == (5, 1_700_000_000_123_456_789)
    assert fleet_digest.stat_key(str(one)) == (5, 1_700_000_000_123_456_789)
    bag = tmp_path / 'bag'
    bag.mkdir()
    assert fleet_digest.stat_key(bag) == (0, 0)
    for name, size, mtime in (('a', 3, 2_000), ('b', 11, 9_000), ('c', 4, 5_000),
                              ('.hidden', 100, 99_000)):
        (bag / name).write_bytes(b'x' * size)
        os.utime(bag / name, ns=(1, mtime))
    (bag / 'folder').mkdir()
    os.utime(bag / 'folder', ns=(1, 50_000))
    assert fleet_digest.stat_key(bag) == (3 + 11 + 4, 9_000)


# -- discover ----------------------------------------------------------------------------------

def test_bags_found_in_name_order_bag_folders_beside_files_links_and_staging_skipped(tmp_path):
    """
    Find bags in name order; skip links to folders and staging folders.

    By hand: one folder's bags (files and rosbag2 directories) in one name order, then
    its sub-folders in name order; a link to a folder, a staging folder not searched.
    """
    runs = tmp_path / 'runs'
    for folder in ('runs/b_bag', 'runs/d_bag', 'runs/c/z', 'runs/a', 'runs/x.partial',
                   'elsewhere'):
        (tmp_path / folder).mkdir(parents=True)
    for bag in ('b_bag', 'd_bag'):
        (runs / bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
        (runs / bag / 'run_0.mcap').write_bytes(b'x')
    for name in ('runs/c.mcap', 'runs/a.db3', 'runs/e.mcap', 'runs/c/z/1.mcap',
                 'runs/c/0.mcap', 'runs/a/2.mcap', 'runs/x.partial/3.mcap',
                 'elsewhere/4.mcap', 'runs/notes.txt'):
        (tmp_path / name).write_bytes(b'x')
    (runs / 'linked').symlink_to(tmp_path / 'elsewhere', target_is_directory=True)
    assert is_bag_directory(runs / 'b_bag') and not is_bag_directory(runs / 'c')
    found = find_bags([runs])
    assert [str(bag.relative_to(runs)) for bag, _ in found] == [
        'a.db3', 'b_bag', 'c.mcap', 'd_bag', 'e.mcap', 'a/2.mcap', 'c/0.mcap', 'c/z/1.mcap']
    assert {root for _, root in found} == {runs}
    # A rosbag2 directory given: itself, found under its parent; given twice: once.
    assert find_bags([runs / 'b_bag', str(runs / 'b_bag')]) == [(runs / 'b_bag', runs)]


# -- tasks -------------------------------------------------------------------------------------

def test_what_is_not_read_as_a_bag_and_why_in_the_words_said(tmp_path):
    """Regular files and folders read; a FIFO, a device, a socket, links, a bad path not."""
    regular = tmp_path / 'a.mcap'
    regular.write_bytes(b'abc')
    os.mkfifo(tmp_path / 'fifo.mcap')
    listening = socket.socket(socket.AF_UNIX)
    listening.bind(str(tmp_path / 'socket.mcap'))
    try:
        (tmp_path / 'to_fifo.mcap').symlink_to(tmp_path / 'fifo.mcap')
        (tmp_path / 'to_null.mcap').symlink_to('/dev/null')
        (tmp_path / 'to_file.mcap').symlink_to(regular)
        (tmp_path / 'broken.mcap').symlink_to(tmp_path / 'gone')
        said = {name: tasks.not_a_bag_file(tmp_path / name) for name in (
            'a.mcap', '.', 'fifo.mcap', 'socket.mcap', 'to_fifo.mcap', 'to_null.mcap',
            'to_file.mcap', 'broken.mcap', 'gone.mcap', 'a.mcap/x')}
    finally:
        listening.close()
    assert said == {
        'a.mcap': None, '.': None, 'to_file.mcap': None,
        'fifo.mcap': 'not a regular file (a FIFO): not read',
        'socket.mcap': 'not a regular file (a socket): not read',
        'to_fifo.mcap': f'a symbolic link to {tmp_path / "fifo.mcap"}, not a regular file '
                        '(a FIFO): not read',
        'to_null.mcap': 'a symbolic link to /dev/null, not a regular file (a character '
                        'device): not read',
        'broken.mcap': f'a symbolic link to {tmp_path / "gone"}, which does not exist (a '
                       'broken link): not read',
        'gone.mcap': 'gone: which does not exist (a broken link): not read',
        'a.mcap/x': 'cannot read: Not a directory'}


def test_a_bag_that_cannot_be_read_or_is_of_no_known_kind_is_said(tmp_path, monkeypatch):
    """Say a read error by its reason, else its text; a file of no known kind as special."""
    bag = tmp_path / 'a.mcap'
    bag.write_bytes(b'x')
    for error, said in ((OSError(13, 'Permission denied'), 'Permission denied'),
                        (OSError('no reason given'), 'no reason given')):
        def unreadable(path, error=error):
            raise error
        monkeypatch.setattr(tasks, 'content_digest', unreadable)
        assert tasks.identify_bag_file(bag) == (str(bag), None, f'cannot read: {said}')
    # A kind the list does not name (none here: the list emptied), a FIFO as any other.
    os.mkfifo(tmp_path / 'fifo.mcap')
    monkeypatch.setattr(tasks, '_KINDS', ())
    assert tasks.not_a_bag_file(tmp_path / 'fifo.mcap') == \
        'not a regular file (a special file): not read'


def test_a_task_identifies_bags_by_hand_and_names_what_it_cannot_read(tmp_path):
    """(path, (size, mtime ns), sha256) by os.stat and hashlib; (path, None, why) else."""
    bag = tmp_path / 'a.mcap'
    bag.write_bytes(b'some bytes')
    os.mkfifo(tmp_path / 'fifo.mcap')
    status = os.stat(bag)
    assert tasks.identify_bag_files([bag, tmp_path / 'fifo.mcap']) == [
        (str(bag), (10, status.st_mtime_ns), hashlib.sha256(b'some bytes').hexdigest()),
        (str(tmp_path / 'fifo.mcap'), None, 'not a regular file (a FIFO): not read')]


def test_a_bag_that_fails_gives_one_failure_row_with_its_reason(tmp_path, monkeypatch):
    """Not a bag; a bug inside (said as internal); no layout: each a row, by hand."""
    runs = tmp_path / 'site' / 'gantry_7'
    runs.mkdir(parents=True)
    bag = runs / 'r.mcap'
    bag.write_bytes(b'xyz')
    status, row = tasks.analyse(str(bag), str(tmp_path), 'd1', (3, 44))
    assert status == 'failed'
    assert row['failed_at'] % 1000 == 0 and abs(row['failed_at'] / 1e9 - time.time()) < 60
    assert dict(row, failed_at=0) == {
        'digest': 'd1', 'bag': str(bag), 'bag_bytes': 3, 'bag_mtime_ns': 44,
        'machine_id': 'site/gantry_7', 'machine_source': 'path',
        'reason': f'{bag}: not an MCAP file (no MCAP magic at the start)', 'failed_at': 0}
    assert tasks.analyse(str(bag), str(tmp_path), 'd1', (3, 44), 'r')[1]['bag'] == 'r'
    assert tasks.analyse_batch([(str(bag), str(runs), 'd2', (3, 44))])[0][1]['machine_id'] \
        == 'r'

    def broken(path):
        raise KeyError('segments')
    monkeypatch.setattr(tasks, 'analyse_bag', broken)
    assert tasks.analyse(str(bag), str(runs), 'd', (3, 4))[1]['reason'] == \
        "internal error: KeyError: 'segments'"

    def long(path):
        raise ValueError('y' * 600)
    monkeypatch.setattr(tasks, 'analyse_bag', long)
    assert tasks.analyse(str(bag), str(runs), 'd', (3, 4))[1]['reason'] == \
        'y' * 500 + '... (600 characters)'
    monkeypatch.setattr(tasks, 'analyse_bag', lambda path: {'segments': []})
    status, row = tasks.analyse(str(bag), str(runs), 'd', (3, 4), 'label')
    assert abs(row.pop('failed_at') / 1e9 - time.time()) < 60
    assert (status, row) == ('failed', {
        'digest': 'd', 'bag': 'label', 'bag_bytes': 3, 'bag_mtime_ns': 4, 'machine_id': 'r',
        'machine_source': 'path', 'reason': 'no layout segment'})

    def unreadable(path, root):
        raise PermissionError('no')
    monkeypatch.setattr(tasks, 'machine_of', unreadable)
    row = tasks.analyse(str(bag), str(runs), 'd', (3, 4))[1]
    assert (row['machine_id'], row['machine_source']) == (str(bag), 'path')


# -- store -------------------------------------------------------------------------------------

def test_a_table_read_in_its_own_column_order_and_a_failed_write_leaves_nothing(tmp_path):
    """Columns reordered, extra ones dropped; a type changed refused; a failed write."""
    rows = [{'digest': 'd', 'bag': 'b', 'bag_bytes': 3, 'reason': 'r'}]
    mixed = table(rows, FAILURE_SCHEMA)
    shuffled = pa.table({name: mixed.column(name) for name in reversed(mixed.column_names)})
    shuffled = shuffled.append_column('extra', pa.array([1]))
    pq.write_table(shuffled, tmp_path / 'mixed.parquet')
    got = store.read(tmp_path / 'mixed.parquet', FAILURE_SCHEMA)
    assert got.schema.equals(FAILURE_SCHEMA) and got.to_pylist() == mixed.to_pylist()
    other = mixed.set_column(2, 'bag_bytes', pa.array([3.0]))
    pq.write_table(other, tmp_path / 'other.parquet')
    with pytest.raises(ValueError) as caught:
        store.read(tmp_path / 'other.parquet', FAILURE_SCHEMA)
    assert str(caught.value) == (
        f'{tmp_path / "other.parquet"}: not a cvc-balance fleet table of this version '
        '(missing or different: bag_bytes (int64)); not overwritten: give another --out')
    pq.write_table(pa.table({'x': [1]}), tmp_path / 'x.parquet')
    with pytest.raises(ValueError) as caught:
        store.read(tmp_path / 'x.parquet', RESULT_SCHEMA)
    assert str(caught.value).startswith(
        f'{tmp_path / "x.parquet"}: not a cvc-balance fleet table of this version (missing '
        'or different: digest (string), bag (string), bag_bytes (int64), bag_mtime_ns '
        '(int64), machine_id (string)); not overwritten')
    (tmp_path / 'text.parquet').write_text('no')
    with pytest.raises(ValueError) as caught:
        store.read(tmp_path / 'text.parquet', FAILURE_SCHEMA)
    assert str(caught.value).startswith(f'{tmp_path / "text.parquet"}: not a readable '
                                        'Parquet table (')
    assert str(caught.value).endswith('); not overwritten: give another --out')
    # A write that cannot rename (a folder holds the name): the error, no staging file.
    (tmp_path / 'full.parquet').mkdir()
    (tmp_path / 'full.parquet' / 'keep').write_text('kept')
    with pytest.raises(OSError):
        store.write(tmp_path / 'full.parquet', mixed)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        'full.parquet', 'mixed.parquet', 'other.parquet', 'text.parquet', 'x.parquet']
    store.write(tmp_path / 'ok.parquet', mixed)
    assert pq.read_metadata(tmp_path / 'ok.parquet').row_group(0).column(0).compression \
        == 'ZSTD'


def test_the_tables_lock_is_held_while_the_block_runs(tmp_path):
    """Another open of RESULTS.lock cannot take it in the block, and can after it."""
    results = tmp_path / 'fleet.parquet'

    def free():
        with open(tmp_path / 'fleet.parquet.lock', 'a') as other:
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False
            fcntl.flock(other, fcntl.LOCK_UN)
            return True
    with store.locked(results):
        assert not free()
    assert free()


# -- engine: batches, known digests, lost tasks, the counts of a run -------------------------

def test_digest_batches_by_count_and_bytes_by_hand():
    """At most 32 bags and 64 MiB a task (a bag alone may be bigger); none for none."""
    mib = 1 << 20
    assert engine.digest_batches([], []) == []
    assert engine.digest_batches(list(range(70)), [1] * 70) == \
        [list(range(32)), list(range(32, 64)), list(range(64, 70))]
    sizes = [40 * mib, 24 * mib, 1, 100 * mib, 3 * mib, 61 * mib, 1]
    assert engine.digest_batches(list('abcdefg'), sizes) == \
        [['a', 'b'], ['c'], ['d'], ['e', 'f'], ['g']]


def test_bags_per_task_by_hand():
    """min(16, 4 MiB // median size, bags // (4 workers)), at least 1."""
    mib = 1 << 20
    assert engine.automatic_batch([], 2) == 1
    assert engine.automatic_batch([100_000] * 1000, 2) == 16
    assert engine.automatic_batch([mib] * 1000, 2) == 4
    assert engine.automatic_batch([3 * mib] * 1000, 2) == 1
    assert engine.automatic_batch([5 * mib] * 1000, 2) == 1
    # The median: sizes [10 KB x 3, 2 MiB x 4] sorted, the 4th (index 7 // 2 = 3).
    assert engine.automatic_batch([2 * mib] * 4 + [10_000] * 3, 0) == 1
    assert engine.automatic_batch([2 * mib] * 3 + [10_000] * 4, 0) == 1
    assert engine.automatic_batch([2 * mib] * 3 + [mib] * 4 + [1] * 100, 1) == 16
    assert engine.automatic_batch([2 * mib] * 60 + [10_000] * 4, 1) == 2
    assert engine.automatic_batch([0] * 200, 1) == 16
    # Never fewer than 4 tasks a worker: 40 bags on 2 workers, 5 a task.
    assert engine.automatic_batch([1000] * 40, 2) == 5
    assert engine.automatic_batch([1000] * 40, 3) == 3
    assert engine.automatic_batch([1000] * 7, 2) == 1


def test_a_lost_task_fails_each_of_its_bags(monkeypatch):
    """A digest task: (path, None, why) each; an analysis task: a failure row each."""
    monkeypatch.setattr(engine.time, 'time_ns', lambda: 1_234_567_891)
    error = RuntimeError('worker died\nhard')
    assert engine._lost(engine.identify_bag_files, ['a', 'b'], error) == [
        ('a', None, 'worker lost: RuntimeError: worker died hard'),
        ('b', None, 'worker lost: RuntimeError: worker died hard')]
    assert engine._lost(engine.identify_bag_files, ['a'], KeyError('k' * 400)) == [
        ('a', None, "worker lost: KeyError: '" + 'k' * 299 + '... (402 characters)')]
    lost = engine._lost(engine.analyse_batch, [('/p/a', '/p', 'd1', (1, 2), 'a'),
                                               ('/p/b', '/p', 'd2', (3, 4), 'b')], error)
    assert lost == [('failed', {'digest': d, 'bag': b, 'bag_bytes': s[0], 'bag_mtime_ns': s[1],
                                'machine_id': None, 'machine_source': None,
                                'reason': 'worker lost: RuntimeError: worker died hard',
                                'failed_at': 1_234_567_000})
                    for d, b, s in (('d1', 'a', (1, 2)), ('d2', 'b', (3, 4)))]


def test_known_digests_of_the_tables_by_bag_and_stat():
    """Rows with a digest and a size; a failure of an unreadable bag (no digest) not."""
    results = table([{'digest': 'd1', 'bag': 'a', 'bag_bytes': 3, 'bag_mtime_ns': 5},
                     {'digest': 'd1', 'bag': 'a', 'bag_bytes': 3, 'bag_mtime_ns': 5}],
                    RESULT_SCHEMA)
    failures = table([{'digest': 'd2', 'bag': 'b', 'bag_bytes': 0, 'bag_mtime_ns': 0},
                      {'digest': None, 'bag': 'c', 'bag_bytes': 1, 'bag_mtime_ns': 1},
                      {'digest': 'd4', 'bag': 'e', 'bag_bytes': None, 'bag_mtime_ns': None}],
                     FAILURE_SCHEMA)
    assert engine._known_digests(results, failures) == {('a', (3, 5)): 'd1',
                                                        ('b', (0, 0)): 'd2'}


def test_a_runs_counts_what_it_skips_and_what_it_reads_again(tmp_path, monkeypatch):
    """
    By hand, run after run on one folder: a good bag, two copies of one bad bag, another.

    Run 1: 4 found, 1 analysed, 2 failed, 1 duplicate. Run 2: nothing read again (the
    digests kept by size and time), 1 already, 3 failed before. A bad bag
    changed: hashed again, analysed again. Retried: both old failures replaced. (The
    duplicate, in no table under its own name, is hashed again each run.)
    """
    runs = tmp_path / 'runs'
    runs.mkdir()
    shutil.copy(TILTED, runs / 'a.mcap')
    (runs / 'b.mcap').write_bytes(b'bad')
    (runs / 'c.mcap').write_bytes(b'bad')
    (runs / 'd.mcap').write_bytes(b'worse')
    out = tmp_path / 'fleet.parquet'
    hashed = []
    real = tasks.content_digest
    monkeypatch.setattr(tasks, 'content_digest', lambda path: hashed.append(path) or real(path))

    def counts(report):
        return (report.found, report.already, report.failed_before, report.duplicates,
                report.analysed, report.failed, report.rows)

    first = engine.run_fleet([runs], out, engine='local', progress=False)
    assert counts(first) == (4, 0, 0, 1, 1, 2, 3)
    assert (first.engine, first.workers, first.batch) == ('local', 1, 1)
    assert first.samples == pq.read_table(out).column('accepted')[0].as_py() > 0
    assert (first.results, first.failures) == (str(out),
                                               str(tmp_path / 'fleet.failures.parquet'))
    assert sorted(first.new_failures) == [
        (str(runs / name), f'{runs / name}: not an MCAP file (no MCAP magic at the start)')
        for name in ('b.mcap', 'd.mcap')]
    assert len(hashed) == 4
    hashed.clear()
    second = engine.run_fleet([runs], out, engine='local', progress=False)
    assert counts(second) == (4, 1, 3, 0, 0, 0, 0) and hashed == [str(runs / 'c.mcap')]
    hashed.clear()
    (runs / 'd.mcap').write_bytes(b'worst!')
    third = engine.run_fleet([runs], out, engine='local', progress=False)
    assert counts(third) == (4, 1, 2, 0, 0, 1, 0)
    assert hashed == [str(runs / 'c.mcap'), str(runs / 'd.mcap')]
    failures = pq.read_table(tmp_path / 'fleet.failures.parquet').to_pydict()
    assert sorted(failures['bag']) == [str(runs / n) for n in ('b.mcap', 'd.mcap', 'd.mcap')]
    retried = engine.run_fleet([runs], out, engine='local', progress=False,
                               retry_failures=True, batch=2)
    assert counts(retried) == (4, 1, 0, 1, 0, 2, 0) and retried.batch == 2
    # b's and the changed d's failures replaced; d's first content (no bag has it now) kept.
    failures = pq.read_table(tmp_path / 'fleet.failures.parquet').to_pydict()
    assert failures['bag'] == [str(runs / n) for n in ('d.mcap', 'b.mcap', 'd.mcap')]
    assert pq.read_table(out).num_rows == 3


def test_a_run_refuses_an_unknown_engine_and_a_scheduler_without_dask(tmp_path):
    with pytest.raises(ValueError) as caught:
        engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='spark')
    assert str(caught.value) == "engine 'spark': give one of dask, local"
    with pytest.raises(ValueError) as caught:
        engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='local',
                         scheduler='tcp://x:1')
    assert str(caught.value) == '--scheduler needs --engine dask'
    assert list(tmp_path.iterdir()) == []


# -- rows: a replay record flattened, by hand ---------------------------------------------------

def plane_record(k):
    return {'z': -0.1 + 0.2 * k, 'g_mm': 100.0 + k, 'angle_deg': 10.0 + k,
            'permissible_g_mm': 500.0 + k, 'fraction': 0.2 + k, 'correction_mass_kg': 0.01 + k,
            'correction_angle_deg': 190.0 + k}


def vector_record(base):
    return {'static_unbalance': {'kg_m': base, 'angle_deg': base + 1, 'ci95_kg_m': base + 2},
            'planes': [{'g_mm': base + 10 * k, 'angle_deg': base + 10 * k + 1,
                        'ci95_g_mm': base + 10 * k + 2} for k in (1, 2)]}


def use(base):
    return {'life_used': base, 'l10_hours': base + 1, 'equivalent_load_N': base + 2,
            'unbalance_share': base + 3}


def segment_record(k, balance=True, identified=True, grade=True, source='measured', life=True):
    verdict = {'equivalent_grade': 2.5 + k, 'finest_grade_met': 6.3, 'within_grade': k == 0,
               'level': 'OK', 'verdict': 'WITHIN G 6.3', 'layout_equivalent_grade': 1.5,
               'layout_level': 'WARN', 'layout_verdict': 'v', 'disagreement': 'd',
               'source': source, 'reason': 'why'}
    return {
        'layout': {'name': f'layout {k}', 'digest': f'ld{k}'}, 'from': 99.5,
        'first_sample': 100.0 + k, 'last_sample': 4600.0 + k, 'samples': 50 + k,
        'top_speed': 20.0 + k, 'peak_load_N': 900.0 + k,
        'peak_support_load_N': {'front': 400.0 + k, 'rear': 500.0 + k},
        'warnings': [f'w{k}'], 'model': 'rigid bodies', 'verdict': verdict,
        'balance': {'grade': 6.3, 'service_speed': 23.27, 'speed_source': 'service speed',
                    'permissible_g_mm': 1000.0, 'static_g_mm': 80.0, 'static_angle_deg': 30.0,
                    'planes': [plane_record(0), plane_record(1)]} if balance else None,
        'identified': {'readings': 1374, 'revolutions': 18.3, 'identifiable': True,
                       'fit': {'rms_N': 21.0}, 'identified': vector_record(1.0),
                       'residual': vector_record(5.0),
                       'grade': {'fractions': [0.4, 0.6], 'equivalent_grade': 3.3,
                                 'level': 'OK'} if grade else None} if identified else None,
        'life': [{'name': 'front', 'measured': use(0.1), 'layout': use(0.2)},
                 {'name': 'rear', 'measured': None, 'layout': use(0.3)}] if life else None}


def test_a_replay_record_flattened_to_rows_by_hand(tmp_path):
    """
    Flatten a replay record to rows by hand.

    Run columns on each segment; a segment's numbers, planes, verdict, identification and
    bearings where the record has them, null where not; times to the microsecond.
    """
    from cvc_balance.fleet.rows import result_rows
    record = {'start': 12.0000026, 'end': 30.5, 'samples': 700, 'accepted': 690,
              'rejected': 4, 'dropped': 5, 'skipped': 1, 'problems': ('p1', 'p2'),
              'segments': [segment_record(0),
                           segment_record(1, balance=False, identified=False, life=False,
                                          source='layout'),
                           segment_record(2, grade=False, source='layout')]}
    rows = result_rows(record, 'dg', Path('/runs/a.mcap'), (123, 456), ('m1', 'bag'),
                       7_000, 0.25)
    assert len(rows) == 3
    run = {'digest': 'dg', 'bag': '/runs/a.mcap', 'bag_bytes': 123, 'bag_mtime_ns': 456,
           'machine_id': 'm1', 'machine_source': 'bag', 'run_start': 12_000_003_000,
           'run_end': 30_500_000_000, 'samples': 700, 'accepted': 690, 'rejected': 4,
           'dropped': 5, 'skipped': 1, 'problems': ['p1', 'p2'], 'segments': 3,
           'analysed_at': 7_000, 'analysis_seconds': 0.25}
    for k, row in enumerate(rows):
        assert {key: row[key] for key in run} == run
        assert {key: row[key] for key in (
            'segment', 'layout_name', 'layout_digest', 'layout_from', 'segment_start',
            'segment_end', 'segment_samples', 'top_speed', 'peak_load_N',
            'peak_support_load_N', 'warnings', 'model')} == {
            'segment': k, 'layout_name': f'layout {k}', 'layout_digest': f'ld{k}',
            'layout_from': 99_500_000_000, 'segment_start': (100 + k) * 10**9,
            'segment_end': (4600 + k) * 10**9, 'segment_samples': 50 + k,
            'top_speed': 20.0 + k, 'peak_load_N': 900.0 + k,
            'peak_support_load_N': [('front', 400.0 + k), ('rear', 500.0 + k)],
            'warnings': [f'w{k}'], 'model': 'rigid bodies'}
        assert {key: row[key] for key in (
            'equivalent_grade', 'finest_grade_met', 'within_grade', 'level', 'verdict',
            'verdict_source', 'verdict_reason', 'disagreement', 'layout_equivalent_grade',
            'layout_level', 'layout_verdict')} == {
            'equivalent_grade': 2.5 + k, 'finest_grade_met': 6.3, 'within_grade': k == 0,
            'level': 'OK', 'verdict': 'WITHIN G 6.3',
            'verdict_source': ('measured', 'layout', 'layout')[k],
            'verdict_reason': 'why', 'disagreement': 'd', 'layout_equivalent_grade': 1.5,
            'layout_level': 'WARN', 'layout_verdict': 'v'}
        assert row['running_hours'] == 4500.0 / 3600.0
    first, second, third = rows
    balance = {'grade': 6.3, 'service_speed': 23.27, 'speed_source': 'service speed',
               'permissible_g_mm': 1000.0, 'static_g_mm': 80.0, 'static_angle_deg': 30.0}
    for key, value in balance.items():
        assert (first[key], second[key], third[key]) == (value, None, value), key
    for p, k in (('I', 0), ('II', 1)):
        for key, value in plane_record(k).items():
            assert (first[f'plane_{p}_{key}'], f'plane_{p}_{key}' in second) == (value, False)
    identified = {'identified_readings': 1374, 'identified_revolutions': 18.3,
                  'identifiable': True, 'fit_rms_N': 21.0}
    for what, base in (('identified', 1.0), ('residual', 5.0)):
        identified.update({f'{what}_static_kg_m': base,
                           f'{what}_static_kg_m_angle_deg': base + 1,
                           f'{what}_static_kg_m_ci95': base + 2})
        for p, k in (('I', 1), ('II', 2)):
            identified.update({f'{what}_plane_{p}_g_mm': base + 10 * k,
                               f'{what}_plane_{p}_g_mm_angle_deg': base + 10 * k + 1,
                               f'{what}_plane_{p}_g_mm_ci95': base + 10 * k + 2})
    graded = {'identified_plane_I_fraction': 0.4, 'identified_plane_II_fraction': 0.6,
              'identified_equivalent_grade': 3.3, 'identified_level': 'OK'}
    assert {key: first[key] for key in {**identified, **graded}} == {**identified, **graded}
    assert {key: third[key] for key in identified} == identified
    assert not any(key in second for key in {**identified, **graded})
    assert not any(key in third for key in graded)
    # Bearings: measured where the verdict of record is measured and the cell told it.
    assert first['bearings'] == [dict(use(0.1), support='front', source='measured'),
                                 dict(use(0.3), support='rear', source='layout')]
    assert second['bearings'] is None
    assert third['bearings'] == [dict(use(0.2), support='front', source='layout'),
                                 dict(use(0.3), support='rear', source='layout')]
    # The table takes every row as its schema says; pyarrow reads them back.
    path = tmp_path / 'rows.parquet'
    pq.write_table(table(rows, RESULT_SCHEMA), path)
    back = pq.read_table(path).to_pylist()
    assert back[0]['identified_level'] == 'OK' and back[1]['plane_I_g_mm'] is None
    assert back[2]['bearings'][0] == dict(use(0.2), support='front', source='layout')
    assert back[0]['run_start'].timestamp() == 12.000003


def test_a_segment_without_samples_has_no_running_hours():
    from cvc_balance.fleet.rows import bearing_columns, segment_columns
    empty = segment_record(0)
    empty.update({'from': None, 'first_sample': None, 'last_sample': None})
    columns = segment_columns(0, empty)
    assert (columns['layout_from'], columns['segment_start'], columns['segment_end'],
            columns['running_hours']) == (None, None, None, None)
    segment = segment_record(0)
    segment.update(first_sample=None, last_sample=None)
    assert bearing_columns(segment)['running_hours'] is None
    segment['life'] = []
    assert bearing_columns(segment) == {'running_hours': None, 'bearings': None}


def test_a_failure_row_by_hand():
    from cvc_balance.fleet.rows import failure_row
    assert failure_row('d', Path('/x/b.mcap'), (1, 2), ('m', 'path'), 'why', 5_000) == {
        'digest': 'd', 'bag': '/x/b.mcap', 'bag_bytes': 1, 'bag_mtime_ns': 2,
        'machine_id': 'm', 'machine_source': 'path', 'reason': 'why', 'failed_at': 5_000}


def test_the_median_bag_sets_the_batch():
    """40 bags of 10 kB and 60 of 2 MiB: the median (index 50) is 2 MiB: 2 bags a task."""
    sizes = [10_000] * 40 + [2 << 20] * 60
    assert sorted(sizes)[50] == 2 << 20 and sorted(sizes)[33] == 10_000
    assert engine.automatic_batch(sizes, 1) == 2
    assert engine.automatic_batch(sizes[::-1], 1) == 2


def test_a_run_on_dask_by_default():
    """The documented default engine; the workers a LocalCluster gets: at most 2 here."""
    import inspect
    assert inspect.signature(engine.run_fleet).parameters['engine'].default == 'dask'
    assert engine.ENGINES == ('dask', 'local')


def test_a_retried_bag_that_now_succeeds_leaves_no_failure(tmp_path, monkeypatch):
    """
    Leave no failure row for a retried bag that now succeeds.

    A bag that failed (a read error this time) and is retried: analysed, its failure row
    gone. A run with nothing failing writes an empty failures table beside the results.
    """
    runs = tmp_path / 'runs'
    runs.mkdir()
    shutil.copy(TILTED, runs / 'a.mcap')
    out = tmp_path / 'fleet.parquet'
    real = tasks.analyse_bag

    def flaky(path):
        raise OSError('disk went away')
    monkeypatch.setattr(tasks, 'analyse_bag', flaky)
    first = engine.run_fleet([runs], out, engine='local', progress=False)
    assert (first.analysed, first.failed, first.new_failures) == (
        0, 1, [(str(runs / 'a.mcap'), 'disk went away')])
    monkeypatch.setattr(tasks, 'analyse_bag', real)
    again = engine.run_fleet([runs], out, engine='local', progress=False)
    assert (again.analysed, again.failed_before) == (0, 1)
    retried = engine.run_fleet([runs], out, engine='local', progress=False,
                               retry_failures=True)
    assert (retried.analysed, retried.failed) == (1, 0)
    assert pq.read_table(tmp_path / 'fleet.failures.parquet').num_rows == 0
    assert pq.read_table(out).num_rows == 3
    clean = tmp_path / 'clean'
    clean.mkdir()
    engine.run_fleet([runs], clean / 'f.parquet', engine='local', progress=False)
    assert pq.read_table(clean / 'f.failures.parquet').num_rows == 0
    assert pq.read_table(clean / 'f.parquet').num_rows == 3


def test_a_bug_inside_a_run_is_raised_not_swallowed(tmp_path, monkeypatch):
    (tmp_path / 'a.mcap').write_bytes(b'x')

    def broken(items):
        raise RuntimeError('a bug in the engine')
    monkeypatch.setattr(engine, 'analyse_batch', broken)
    with pytest.raises(RuntimeError, match='^a bug in the engine$'):
        engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='local', progress=False)


def test_the_progress_bars_say_the_bags_of_each_stage(tmp_path, capsys, monkeypatch):
    """On request: 'digest' and 'analyse', of n bags, cleared at the end; off: nothing."""
    for name in ('a.mcap', 'b.mcap'):
        (tmp_path / name).write_bytes(name.encode())
    engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='local', progress=True)
    said = capsys.readouterr().err
    for stage in ('digest', 'analyse'):
        assert f'\r{stage}:   0%|          | 0/2 [00:00<?, ?bag/s]' in said, said
    assert said.endswith('\r') and '\n' not in said
    (tmp_path / 'c.mcap').write_bytes(b'c')
    engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='local', progress=False)
    assert capsys.readouterr().err == ''
    empty = tmp_path / 'empty'
    empty.mkdir()
    engine.run_fleet([empty], tmp_path / 'g.parquet', engine='local', progress=True)
    assert capsys.readouterr().err == ''
    # Not asked: shown on a terminal only.
    (tmp_path / 'd.mcap').write_bytes(b'd')
    monkeypatch.setattr(sys.stderr, 'isatty', lambda: True)
    engine.run_fleet([tmp_path], tmp_path / 'f.parquet', engine='local')
    assert 'digest:   0%|' in capsys.readouterr().err


def test_a_stopped_run_keeps_what_it_wrote_at_its_checkpoints(tmp_path, monkeypatch):
    """
    Keep what a stopped run wrote at its checkpoints.

    Three bags, a task each, the third task stopped: with a checkpoint after every task the
    first two bags' rows are in the tables; with none due (100 s), nothing is written. (A
    real bag is analysed in each run: 0.3 s each here.)
    """
    runs = tmp_path / 'runs'
    runs.mkdir()
    shutil.copy(TILTED, runs / 'a.mcap')
    (runs / 'b.mcap').write_bytes(b'b')
    (runs / 'c.mcap').write_bytes(b'c')
    real = engine.analyse_batch

    def stopped(items):
        if items[0][4].endswith('c.mcap'):
            raise RuntimeError('stopped')
        return real(items)
    monkeypatch.setattr(engine, 'analyse_batch', stopped)
    for checkpoint, rows in ((0.0, 3), (100.0, None)):
        out = tmp_path / f'{checkpoint}.parquet'
        with pytest.raises(RuntimeError, match='^stopped$'):
            engine.run_fleet([runs], out, engine='local', progress=False, batch=1,
                             checkpoint=checkpoint)
        if rows is None:
            assert not out.exists()
        else:
            assert pq.read_table(out).num_rows == rows
            failures = pq.read_table(tmp_path / f'{checkpoint}.failures.parquet')
            assert failures.column('bag').to_pylist() == [str(runs / 'b.mcap')]


def test_a_runs_counts_and_times_over_several_bags(tmp_path):
    """
    Count a run's bags and time its stages, by hand.

    Two good bags, an unreadable one first, three copies of one bad bag, seven more bad
    bags: by hand. Samples: both good bags' accepted samples; 8 tasks of size 5 bytes on 1
    worker: 2 bags a task; each stage's time within the run's.
    """
    runs = tmp_path / 'runs'
    runs.mkdir()
    (runs / '0_broken.mcap').symlink_to(tmp_path / 'gone.mcap')
    shutil.copy(TILTED, runs / 'a.mcap')
    shutil.copy(ROOT / 'bags' / 'spin_up_tube_swap.mcap', runs / 'b.mcap')
    for name in ('c1', 'c2', 'c3'):
        (runs / f'{name}.mcap').write_bytes(b'same')
    for k in range(7):
        (runs / f'd{k}.mcap').write_bytes(f'bad {k}'.encode())
    out = tmp_path / 'fleet.parquet'
    started = time.perf_counter()
    first = engine.run_fleet([runs], out, engine='local', progress=False)
    took = time.perf_counter() - started
    table = pq.read_table(out).to_pydict()
    accepted = {bag: a for bag, a in zip(table['bag'], table['accepted'])}
    assert (first.found, first.analysed, first.duplicates, first.failed) == (13, 2, 2, 9)
    assert first.samples == accepted[str(runs / 'a.mcap')] + accepted[str(runs / 'b.mcap')]
    assert first.batch == 2
    assert 0 <= first.digest_seconds <= first.seconds <= took
    assert 0 <= first.analysis_seconds <= first.seconds
    for seconds, at in zip(table['analysis_seconds'], table['analysed_at']):
        assert 0 < seconds <= first.analysis_seconds
        assert abs(at.timestamp() - time.time()) < 60
    failures = pq.read_table(tmp_path / 'fleet.failures.parquet').to_pylist()
    (broken,) = [row for row in failures if row['digest'] is None]
    now = time.time()
    assert now - 60 < broken['failed_at'].timestamp() <= now
    again = engine.run_fleet([runs], out, engine='local', progress=False)
    assert (again.already, again.failed_before, again.duplicates) == (2, 10, 0)
