"""
A fleet of machines: every run of every machine analysed on a distributed engine, trends.

Public API: :func:`find_bags` (the bags under some paths: files and rosbag2 directories),
:func:`content_digest` (a bag's identity by content), :func:`run_fleet` (each new bag's
replay record, on Dask or in this process, into a Parquet table and a table of failures),
:func:`machine_trends` (per machine and plane the unbalance over time, its fitted drift and
the date it is projected to leave its grade; DuckDB over the table), :func:`simulate_fleet`
(machines x runs over months with drifts, as bags). Layer 3: above ``bag``.

Each is imported when first asked for: a Dask worker that imports ``fleet.tasks`` does not
pay for the trends' scipy.stats and DuckDB, nor for Dask itself (0.6 s a worker here).
"""

import importlib

_HOMES = {'content_digest': 'digest', 'find_bags': 'discover', 'FleetReport': 'engine',
          'machine_trends': 'trends', 'run_fleet': 'engine', 'simulate_fleet': 'simulate'}

__all__ = sorted(_HOMES, key=str.lower)


def __getattr__(name):
    """Return a public name of the package, importing its module on first use."""
    if name not in _HOMES:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return getattr(importlib.import_module(f'{__name__}.{_HOMES[name]}'), name)
