"""CDR bytes of cvc_balance against two independent decoders: rclpy's and rosbags'."""

import math

from geometry_msgs.msg import WrenchStamped
import pytest
from rclpy.serialization import deserialize_message
from rosbags.typesys import get_typestore, Stores

from cvc_balance.messages.cdr import WrenchStampedEncoder

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize('frame_id', ['', 'stator', 'rotor', 'gantry_base_link', 'ä€'])
def test_wrench_stamped_decodes_with_rclpy_and_rosbags(frame_id):
    force, torque = (1.5, -2.25, 1e300), (-0.0, math.pi, -7e-310)
    data = WrenchStampedEncoder(frame_id).encode(-3, 999_999_999, force, torque)
    msg = deserialize_message(data, WrenchStamped)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (-3, 999_999_999)
    assert msg.header.frame_id == frame_id
    w = msg.wrench
    assert (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z) == \
        force + torque
    other = TYPESTORE.deserialize_cdr(data, 'geometry_msgs/msg/WrenchStamped')
    assert other.header.frame_id == frame_id
    assert (other.header.stamp.sec, other.header.stamp.nanosec) == (-3, 999_999_999)
    assert (other.wrench.force.x, other.wrench.torque.y) == (force[0], torque[1])


def test_same_length_as_rclpy_serialisation():
    from rclpy.serialization import serialize_message
    for frame_id in ('', 'a', 'stator', 'abcdefg', 'abcdefgh'):
        msg = WrenchStamped()
        msg.header.frame_id = frame_id
        ours = WrenchStampedEncoder(frame_id).encode(0, 0, (0,) * 3, (0,) * 3)
        assert len(ours) == len(serialize_message(msg))


@pytest.mark.parametrize('frame_id', ['', 'stator', 'gantry_base_link'])
def test_block_layout_and_per_message_encoder_give_the_same_bytes(frame_id):
    """The numpy template (bags) and the struct encoder (live node) must never drift apart."""
    import numpy as np
    from cvc_balance.messages.cdr import wrench_stamped_layout
    layout = wrench_stamped_layout(frame_id)
    data = bytearray(layout.template)
    values = {'sec': 7, 'nanosec': 123, 'force_x': 1.5, 'force_y': -2.0, 'force_z': 3.25,
              'torque_x': -4.0, 'torque_y': 5.5, 'torque_z': 1e-300}
    for name, (offset, fmt) in layout.fields.items():
        np.frombuffer(data, dtype=fmt, count=1, offset=offset)  # in bounds
        data[offset:offset + np.dtype(fmt).itemsize] = np.array(values[name], fmt).tobytes()
    encoded = WrenchStampedEncoder(frame_id).encode(
        7, 123, (1.5, -2.0, 3.25), (-4.0, 5.5, 1e-300))
    assert bytes(data) == encoded
