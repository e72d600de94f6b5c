"""
The worker threads of the vectorised paths, one per core, made on first use.

numpy ufuncs and the zstd/lz4 compressors release the GIL, so blocks of work
handed to these threads run on all cores.
"""

from concurrent.futures import ThreadPoolExecutor
import os

_POOL = []


def pool():
    """Return the shared thread pool."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=os.cpu_count() or 1,
                                        thread_name_prefix='cvc_worker'))
    return _POOL[0]
