"""
A fleet of machines: every run of every machine analysed on a distributed engine, trends.

Public API: :func:`find_bags` (the bags under some paths: files and rosbag2 directories),
:func:`content_digest` (a bag's identity by content), :func:`run_fleet` (each new bag's
replay record, on Dask or in this process, into a Parquet table and a table of failures),
:func:`machine_trends` (per machine and plane the unbalance over time, its fitted drift and
the date it is projected to leave its grade; DuckDB over the table), :func:`simulate_fleet`
(machines x runs over months with drifts, as bags). Layer 3: above ``bag``.
"""

from cvc_balance.fleet.digest import content_digest
from cvc_balance.fleet.discover import find_bags
from cvc_balance.fleet.engine import FleetReport, run_fleet
from cvc_balance.fleet.simulate import simulate_fleet
from cvc_balance.fleet.trends import machine_trends

__all__ = ['content_digest', 'find_bags', 'FleetReport', 'machine_trends', 'run_fleet',
           'simulate_fleet']
