"""
A bare relay: JointState in, WrenchStamped out, nothing computed (latency baseline).

Same subscription QoS, executor and output QoS as balance_monitor, so the
difference between the two is the node's own work.
"""

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

from cvc_balance.ros.balance_monitor import input_qos, OUTPUT_QOS, spin
from geometry_msgs.msg import WrenchStamped


class Relay(Node):
    """Republish each joint_states message's stamp as a WrenchStamped on ``relay_out``."""

    def __init__(self):
        """Wire joint_states to relay_out."""
        super().__init__('relay')
        self._out = self.create_publisher(WrenchStamped, 'relay_out', OUTPUT_QOS)
        self._msg = WrenchStamped()
        self._msg.header.frame_id = 'stator'
        self.create_subscription(JointState, 'joint_states', self._relay, input_qos(200))

    def _relay(self, msg):
        self._msg.header.stamp = msg.header.stamp
        self._out.publish(self._msg)


def main():
    """Run the relay until SIGINT or SIGTERM."""
    rclpy.init()
    node = Relay()
    try:
        spin(node)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
