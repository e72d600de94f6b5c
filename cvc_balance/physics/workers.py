"""
The worker threads of the vectorised paths, one per core, made on first use.

numpy ufuncs and the zstd/lz4 compressors release the GIL, so blocks of work
handed to these threads run on all cores.
"""

from concurrent.futures import ThreadPoolExecutor
import os
import threading

_POOL = []
_PREFIX = 'cvc_worker'


def pool():
    """Return the shared thread pool."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=os.cpu_count() or 1,
                                        thread_name_prefix=_PREFIX))
    return _POOL[0]


def in_pool():
    """
    Tell whether the calling thread is one of the pool's.

    Work that is already on a pool thread must not hand blocks to the pool and wait for
    them: with every thread waiting so, it would wait for ever.
    """
    return threading.current_thread().name.startswith(_PREFIX)
