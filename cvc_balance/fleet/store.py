"""
The fleet's two Parquet files: RESULTS and, beside it, RESULTS' failures.

``fleet.parquet`` holds the results (:data:`~cvc_balance.fleet.rows.RESULT_SCHEMA`),
``fleet.failures.parquet`` the bags that could not be analysed. Each is written whole to
a staging file in the same folder (``NAME.PID.XXXXXXXX.partial``, removed by a later run
if the writer was killed) and renamed over the old one, so a run that is stopped, or a
full disk, leaves the previous file as it was (readable, nothing lost). A file there that
is not such a table is never overwritten.

Several runs may write one table at once (two ``fleet`` commands on one ``--out``): each
write happens under an exclusive lock of ``RESULTS.lock`` (fcntl), reads the table as it
is then and adds this run's rows to it (:func:`merged`), so no run's rows are lost.
"""

from contextlib import contextmanager
import fcntl
import os
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from cvc_balance.files import staging_file


def failures_path(results):
    """Return the failures table's path beside ``results``: X.parquet, X.failures.parquet."""
    results = Path(results)
    stem = results.name[:-len('.parquet')] if results.name.endswith('.parquet') \
        else results.name
    return results.with_name(f'{stem}.failures.parquet')


def read(path, schema):
    """
    Return the table at ``path`` (an empty one of ``schema`` if there is no file).

    Raises ValueError naming the file when it is not a Parquet table with ``schema``'s
    columns and types (another program's file, or a damaged one).
    """
    path = Path(path)
    if not path.exists():
        return schema.empty_table()
    if path.is_dir():
        raise ValueError(f'{path}: is a directory; give a .parquet file for the table')
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as error:
        raise ValueError(f'{path}: not a readable Parquet table ({error}); not overwritten: '
                         'give another --out') from None
    missing = [f'{field.name} ({field.type})' for field in schema
               if field.name not in table.schema.names
               or not table.schema.field(field.name).type.equals(field.type)]
    if missing:
        raise ValueError(f'{path}: not a cvc-balance fleet table of this version (missing or '
                         f'different: {", ".join(missing[:5])}); not overwritten: give '
                         'another --out')
    return table.select(schema.names).cast(schema)


def write(path, table):
    """Write ``table`` to ``path`` atomically (staging file, then rename); zstd columns."""
    path = Path(path)
    temporary = staging_file(path)
    try:
        pq.write_table(table, temporary, compression='zstd')
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def lock_path(results):
    """Return the lock file of a results table: RESULTS.lock beside it."""
    results = Path(results)
    return results.with_name(results.name + '.lock')


@contextmanager
def locked(results):
    """Hold the exclusive lock of ``results``' tables while the block runs (waits for it)."""
    with open(lock_path(results), 'a') as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def merged(current, added, dropped=()):
    """
    Return ``current`` (a table) with the rows of ``added`` whose (digest, bag) it lacks.

    Rows whose digest is in ``dropped`` are first taken out of ``current`` (a retried
    bag's old failure). A bag's rows share its digest: those another run (or this one,
    at a checkpoint) wrote already are not added twice.
    """
    if len(dropped):
        gone = pc.is_in(current.column('digest'), pa.array(sorted(dropped)))
        current = current.filter(pc.invert(gone))
    have = set(zip(current.column('digest').to_pylist(), current.column('bag').to_pylist()))
    keep = [(digest, bag) not in have for digest, bag in
            zip(added.column('digest').to_pylist(), added.column('bag').to_pylist())]
    return pa.concat_tables([current, added.filter(pa.array(keep, pa.bool_()))])
