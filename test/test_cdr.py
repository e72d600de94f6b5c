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


def rosbags_joint_state(names, positions, velocities, frame_id='gantry'):
    """Serialise a sensor_msgs/JointState with rosbags (not this project's code)."""
    import numpy as np
    msg_type = TYPESTORE.types['sensor_msgs/msg/JointState']
    header = TYPESTORE.types['std_msgs/msg/Header'](
        stamp=TYPESTORE.types['builtin_interfaces/msg/Time'](sec=7, nanosec=9),
        frame_id=frame_id)
    msg = msg_type(header=header, name=list(names),
                   position=np.array(positions, float), velocity=np.array(velocities, float),
                   effort=np.array([], float))
    return bytes(TYPESTORE.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def test_damaged_cdr_is_refused_with_its_reason():
    """
    Each refusal of the CDR readers, on rosbags' bytes cut or altered, and the edges kept.

    A String whose text ends the message is read; one byte short is refused. A name list
    ending the message is read (no position or velocity asked); a list declaring as many
    names as the message has 4-byte words runs out of strings, not past the count; arrays
    ending exactly at the message's end are located.
    """
    import struct
    from cvc_balance.messages.cdr import (find_joint_state_fields, joint_state_names,
                                          read_string_message)
    text = bytes(TYPESTORE.serialize_cdr(TYPESTORE.types['std_msgs/msg/String'](data='tube'),
                                         'std_msgs/msg/String'))
    exact = text[:8 + 5]                        # header, length, 'tube' and its NUL
    assert read_string_message(exact) == 'tube'
    for bad, reason in ((exact[:-1], 'string length beyond the message'),
                        (exact[:4] + struct.pack('<I', 0) + exact[8:],
                         'string length beyond the message'),
                        (b'\x00\x00\x00\x00' + exact[4:], 'not little-endian CDR')):
        with pytest.raises(ValueError) as error:
            read_string_message(bad)
        assert str(error.value) == reason
    data = rosbags_joint_state(['a', 'gantry_joint'], [0.1, 0.2], [1.0, 2.0])
    names, end = joint_state_names(data)
    assert names == ['a', 'gantry_joint']
    assert joint_state_names(data[:end]) == (names, end)       # the names end the message
    offsets, _ = find_joint_state_fields(data, 'gantry_joint')
    assert struct.unpack_from('<d', data, offsets['velocity'])[0] == 2.0
    no_effort = data[:-4]                                       # velocity ends the message
    assert find_joint_state_fields(no_effort, 'gantry_joint')[0] == offsets
    cases = [(b'\x00\x00\x00\x00' + data[4:], 'not little-endian CDR'),
             (data[:20], 'string beyond the message'),
             (data[:offsets['velocity'] + 4], 'JointState velocity beyond the message'),
             (data[:offsets['position'] + 4], 'JointState position beyond the message')]
    frame_end = 12 + 4 + len('gantry') + 1
    frame_end += -(frame_end - 4) % 4
    huge = data[:frame_end] + struct.pack('<I', 10**6) + data[frame_end + 4:]
    cases.append((huge, 'more names than the message holds'))
    for bad, reason in cases:
        with pytest.raises(ValueError) as error:
            find_joint_state_fields(bad, 'gantry_joint')
        assert str(error.value) == reason, reason
    # As many names declared as the message has 4-byte words: allowed by the count check,
    # the names (empty, 8 bytes each) then run out.
    empty_names = b'\x01\x00\x00\x00\x00\x00\x00\x00' * 5
    length = frame_end + 4 + len(empty_names)
    as_many = data[:frame_end] + struct.pack('<I', length // 4) + empty_names
    assert len(as_many) == 4 * (length // 4)
    with pytest.raises(struct.error):
        joint_state_names(as_many)
