"""
What a worker does with one bag: pure functions of a path, importable by every worker.

Workers get paths, never bag bytes (bags are gigabytes; each worker reads from the shared
file system), and open a fresh reader per bag: nothing read from one file (schema and
channel ids are per file) is kept for the next. A task never raises for a bad bag: it
returns the reason, so one damaged bag cannot stop or retry a fleet run.
"""

import os
import stat
import time

from cvc_balance.bag.machine import machine_of
from cvc_balance.bag.run_summary import analyse_bag
from cvc_balance.fleet.digest import content_digest, stat_key
from cvc_balance.fleet.rows import failure_row, result_rows
from cvc_balance.physics.layout import one_line


def identify_bag_file(path):
    """
    Return (path, (bytes, mtime ns), digest) of a bag, or (path, None, reason) if unreadable.

    Only regular files and directories are read: a FIFO would block the worker for ever
    and a device (a link to /dev/zero named ``*.mcap``) never end; a broken symbolic
    link is said as such.
    """
    refused = not_a_bag_file(path)
    if refused is not None:
        return str(path), None, refused
    try:
        return str(path), stat_key(path), content_digest(path)
    except OSError as error:
        return str(path), None, f'cannot read: {error.strerror or error}'


_KINDS = ((stat.S_ISFIFO, 'a FIFO'), (stat.S_ISCHR, 'a character device'),
          (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'))


def not_a_bag_file(path):
    """Return why ``path`` is not read as a bag (not a regular file or directory), or None."""
    link = f'a symbolic link to {os.readlink(path)}, ' if os.path.islink(path) else ''
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return f'{link or "gone: "}which does not exist (a broken link): not read'
    except OSError as error:
        return f'cannot read: {error.strerror or error}'
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), 'a special file')
    return f'{link}not a regular file ({kind}): not read'


def identify_bag_files(paths):
    """:func:`identify_bag_file` of several bags (one task for many small ones)."""
    return [identify_bag_file(path) for path in paths]


def analyse_batch(items):
    """:func:`analyse` of each (path, root, digest, stat, label) of ``items``."""
    return [analyse(*item) for item in items]


def analyse(path, root, digest, stat, label=None):
    """
    Analyse one bag; return ('ok', rows) or ('failed', failure row).

    ``root``: the folder it was found under (for a machine id from its path); ``digest``
    and ``stat`` as :func:`identify_bag_file` gave them; ``label``: the bag's name in the
    tables (default ``path``).
    """
    label = path if label is None else label
    started = time.perf_counter()
    now = time.time_ns() // 1000 * 1000     # to the microsecond, as every time in the tables
    try:
        machine = machine_of(path, root)
    except OSError:
        machine = (str(path), 'path')
    try:
        record = analyse_bag(path)
    except Exception as error:    # a bad bag, or a bug: said in one line, the run goes on
        reason = one_line(error, 500)
        if not isinstance(error, (ValueError, OSError)):
            reason = f'internal error: {type(error).__name__}: {reason}'
        return 'failed', failure_row(digest, label, stat, machine, reason, now)
    if not record['segments']:
        return 'failed', failure_row(digest, label, stat, machine, 'no layout segment', now)
    return 'ok', result_rows(record, digest, label, stat, machine, now,
                             time.perf_counter() - started)
