"""
Bags: reading and writing rosbag2 bags (MCAP files, directories), offline replay, simulated runs.

No ROS graph needed. Public API: :func:`open_bag` (a bag file or rosbag2 directory, read
fast and forgivingly), :func:`open_writer` (a .mcap file or rosbag2 directory),
:class:`Bag` (one MCAP file), :class:`BagWriter` (rosbag2-style MCAP), :class:`InputTopics`
(which topics are the inputs), :func:`replay` (a bag's motion through the vectorised
engine), :func:`load_scenario` and :func:`write_bag` (simulated input bags).
"""

from cvc_balance.bag.inputs import InputTopics
from cvc_balance.bag.mcap_reader import Bag, BagError
from cvc_balance.bag.mcap_writer import BagWriter
from cvc_balance.bag.replay import replay, ReplaySummary
from cvc_balance.bag.rosbag2 import open_bag, open_writer
from cvc_balance.bag.scenario import load_scenario, Scenario, ScenarioError, write_bag

__all__ = ['Bag', 'BagError', 'BagWriter', 'InputTopics', 'load_scenario', 'open_bag',
           'open_writer', 'replay', 'ReplaySummary', 'Scenario', 'ScenarioError', 'write_bag']
