"""
Quality of service of the project's topics: inputs, outputs and the latched layout.

The node subscribes with these, ``play`` publishes with them and ``record`` and the
node's own recording note them in the bag (rosbag2's ``offered_qos_profiles``).
"""

from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from rclpy.qos import ReliabilityPolicy

# A QoSProfile given a depth keeps the last that many (KEEP_LAST) and is VOLATILE unless
# told otherwise: those defaults are not written out.
LAYOUT_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
OUTPUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def input_qos(depth):
    """
    Return the sensor-data QoS (best effort, volatile) with a deeper history.

    The preset's 5 messages are 5 ms of a 1 kHz encoder: on a busy 2-core
    machine a process is descheduled that long often enough to lose about
    1.5 % of the samples (measured). 50 sufficed for the node alone; with its
    own recording and four processes on two cores, runs of 20-40 samples were
    lost; 200 absorbed them in every run. While a 10^5-component layout was parsed on the
    node's layout thread under load, 200 lost 2-8 % of 9000 samples and 1000 (the
    default) 1.
    """
    return QoSProfile(depth=depth, reliability=qos_profile_sensor_data.reliability)
