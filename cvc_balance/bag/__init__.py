"""
Bags: reading and writing rosbag2 MCAP files, offline replay, simulated runs.

No ROS graph needed. Public API: :class:`Bag` (fast, forgiving reader),
:class:`BagWriter` (rosbag2-style MCAP), :func:`replay` (a bag's motion through the
vectorised engine), :func:`load_scenario` and :func:`write_bag` (simulated input bags).
"""

from cvc_balance.bag.mcap_reader import Bag, BagError
from cvc_balance.bag.mcap_writer import BagWriter
from cvc_balance.bag.replay import replay, ReplaySummary
from cvc_balance.bag.scenario import load_scenario, Scenario, ScenarioError, write_bag

__all__ = ['Bag', 'BagError', 'BagWriter', 'load_scenario', 'replay', 'ReplaySummary',
           'Scenario', 'ScenarioError', 'write_bag']
