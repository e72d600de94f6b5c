"""
The fleet's two Parquet files: RESULTS and, beside it, RESULTS' failures.

``fleet.parquet`` holds the results (:data:`~cvc_balance.fleet.rows.RESULT_SCHEMA`),
``fleet.failures.parquet`` the bags that could not be analysed. Each is written whole to
a temporary file in the same folder and renamed over the old one, so a run that is
stopped, or a full disk, leaves the previous file as it was (readable, nothing lost).
A file there that is not such a table is never overwritten.
"""

import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq


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
    """Write ``table`` to ``path`` atomically (temporary file, then rename); zstd columns."""
    path = Path(path)
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    try:
        pq.write_table(table, temporary, compression='zstd')
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
