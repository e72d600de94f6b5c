"""
What goes over the wire and into bags: topic names and types, CDR, ros2msg schemas.

Below both the bags and the ROS node (no rclpy here), so that the node, replay, play
and record agree on one contract. Public API: :mod:`~cvc_balance.messages.topics`
(names and types), :class:`WrenchStampedEncoder` and :class:`CdrLayout` (CDR bytes),
:func:`schema_text` (ros2msg schemas as rosbag2 writes them).
"""

from cvc_balance.messages import topics
from cvc_balance.messages.cdr import CdrLayout, WrenchStampedEncoder
from cvc_balance.messages.msg_schema import schema_text

__all__ = ['CdrLayout', 'schema_text', 'topics', 'WrenchStampedEncoder']
