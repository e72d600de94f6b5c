"""
CDR (XCDR1, little endian) encoding of the messages cvc_balance writes.

rclpy serialises a message in about 11 us; a WrenchStamped has a fixed
layout, so one ``struct.pack`` does it in well under 1 us, and ``publish``
of the bytes costs about 3 us. Padding bytes are zero (rmw leaves them
uninitialised: compare decoded fields, never raw bytes). Alignment is
counted from the end of the 4-byte encapsulation header, as CDR does.
"""

import struct

ENCAPSULATION_LE = b'\x00\x01\x00\x00'
"""CDR, little endian, no options."""


def _string_field(text):
    """Encode a CDR string: uint32 length including the NUL, the bytes, the NUL."""
    data = text.encode('utf-8') + b'\x00'
    return struct.pack('<I', len(data)) + data


class WrenchStampedEncoder:
    """
    geometry_msgs/msg/WrenchStamped as CDR bytes, for one frame_id.

    Layout: stamp (int32 sec, uint32 nanosec), frame_id (string), then
    force (3 float64) and torque (3 float64), 8-byte aligned.
    """

    def __init__(self, frame_id):
        """Prepare the fixed part of the message for ``frame_id``."""
        self.frame_id = frame_id
        frame = _string_field(frame_id)
        pad = -(8 + len(frame)) % 8
        self._struct = struct.Struct(f'<4siI{len(frame)}s{pad}x6d')
        self._frame = frame

    def encode(self, sec, nanosec, force, torque):
        """Return the serialized message: stamp (s, ns), force (N), torque (N m)."""
        return self._struct.pack(ENCAPSULATION_LE, sec, nanosec, self._frame, *force, *torque)


class CdrLayout:
    """
    A message of fixed shape as a byte template plus the offsets of its variable fields.

    Built field by field in CDR order; the template holds the constant parts
    (encapsulation, strings, sequence lengths, zero padding) and ``fields``
    maps a name to (offset, numpy dtype string) of each variable number, so
    that n messages are an (n, size) byte array filled by numpy.
    """

    def __init__(self):
        """Start with the encapsulation header."""
        self._data = bytearray(ENCAPSULATION_LE)
        self.fields = {}

    @property
    def size(self):
        """Bytes of one message."""
        return len(self._data)

    @property
    def template(self):
        """Return the constant bytes of one message."""
        return bytes(self._data)

    def _align(self, alignment):
        self._data.extend(b'\x00' * (-(len(self._data) - 4) % alignment))

    def number(self, name, fmt):
        """Add a variable field called ``name``: '<i4', '<u4' or '<f8'."""
        size = struct.calcsize(fmt[0] + {'i4': 'i', 'u4': 'I', 'f8': 'd'}[fmt[1:]])
        self._align(size)
        self.fields[name] = (len(self._data), fmt)
        self._data.extend(b'\x00' * size)

    def constant(self, fmt, value):
        """Add a constant number (e.g. a sequence length)."""
        size = struct.calcsize(fmt)
        self._align(size)
        self._data.extend(struct.pack(fmt, value))

    def string(self, text):
        """Add a constant string."""
        self._align(4)
        self._data.extend(_string_field(text))

    def stamp(self):
        """Add builtin_interfaces/Time as fields 'sec', 'nanosec'."""
        self.number('sec', '<i4')
        self.number('nanosec', '<u4')


def wrench_stamped_layout(frame_id):
    """geometry_msgs/msg/WrenchStamped: fields sec, nanosec, force_x..z, torque_x..z."""
    layout = CdrLayout()
    layout.stamp()
    layout.string(frame_id)
    for part in ('force', 'torque'):
        for axis in 'xyz':
            layout.number(f'{part}_{axis}', '<f8')
    return layout


def joint_state_layout(frame_id, names):
    """sensor_msgs/msg/JointState with one position and velocity per joint, no effort."""
    layout = CdrLayout()
    layout.stamp()
    layout.string(frame_id)
    layout.constant('<I', len(names))
    for name in names:
        layout.string(name)
    for sequence in ('position', 'velocity'):
        layout.constant('<I', len(names))
        for i in range(len(names)):
            layout.number(f'{sequence}_{i}', '<f8')
    layout.constant('<I', 0)   # effort: empty
    return layout


def string_message(text):
    """std_msgs/msg/String as CDR bytes."""
    return ENCAPSULATION_LE + _string_field(text)


def read_string_message(data):
    """Decode std_msgs/msg/String CDR bytes (little endian) to text."""
    if data[:4] != ENCAPSULATION_LE:
        raise ValueError('not little-endian CDR')
    (length,) = struct.unpack_from('<I', data, 4)
    if length < 1 or 8 + length > len(data):
        raise ValueError('string length beyond the message')
    return data[8:8 + length - 1].decode('utf-8')


class _CdrCursor:
    """Reads little-endian CDR fields from ``data``, aligned from the end of the header."""

    def __init__(self, data, position):
        self.data, self.position = data, position

    def align(self, n):
        self.position += -(self.position - 4) % n

    def u32(self):
        self.align(4)
        (value,) = struct.unpack_from('<I', self.data, self.position)
        self.position += 4
        return value

    def string(self):
        length = self.u32()
        if length < 1 or self.position + length > len(self.data):
            raise ValueError('string beyond the message')
        text = bytes(self.data[self.position:self.position + length - 1]).decode('utf-8')
        self.position += length
        return text


def joint_state_names(data):
    """
    Return (joint names, end of the name list) of one JointState's CDR bytes.

    Raises ValueError (or struct.error, UnicodeDecodeError) if the bytes are no
    little-endian CDR JointState.
    """
    if data[:4] != ENCAPSULATION_LE:
        raise ValueError('not little-endian CDR')
    cursor = _CdrCursor(data, 12)                  # after encapsulation and stamp
    cursor.string()                                # frame_id
    count = cursor.u32()
    if 4 * count > len(data):
        raise ValueError('more names than the message holds')
    names = [cursor.string() for _ in range(count)]
    return names, cursor.position


def find_joint_state_fields(data, joint):
    """
    Offsets of stamp, position and velocity of ``joint`` in one JointState's CDR bytes.

    Returns (offsets {'sec', 'nanosec', 'position', 'velocity', 'position_count',
    'velocity_count'}, end of the name list) or None when the message lacks the
    joint, its position or velocity; raises ValueError (or struct.error) on a
    message too short for what it declares.
    """
    names, names_end = joint_state_names(data)
    if joint not in names:
        return None
    index = names.index(joint)
    offsets = {'sec': 4, 'nanosec': 8}
    cursor = _CdrCursor(data, names_end)
    for sequence in ('position', 'velocity'):
        cursor.align(4)
        offsets[f'{sequence}_count'] = cursor.position   # the layout depends on the counts too
        count = cursor.u32()
        if count:
            cursor.align(8)
        if index >= count:
            return None
        offsets[sequence] = cursor.position + 8 * index
        cursor.position += 8 * count
        if cursor.position > len(data):
            raise ValueError(f'JointState {sequence} beyond the message')
    return offsets, names_end


_STAMP_AND_LENGTH = struct.Struct('<iII')
_WRENCH = struct.Struct('<6d')


def read_wrench_stamped(data):
    """
    Decode geometry_msgs/msg/WrenchStamped CDR bytes: (sec, nanosec, force, torque).

    ``force`` (N) and ``torque`` (N m) are 3-tuples. Raises ValueError on bytes that are
    no little-endian CDR WrenchStamped. About 1 us, against rclpy's 20 us to make the
    message object.
    """
    if data[:4] != ENCAPSULATION_LE or len(data) < 64:
        raise ValueError('not a little-endian CDR WrenchStamped')
    sec, nanosec, length = _STAMP_AND_LENGTH.unpack_from(data, 4)
    position = 16 + length
    position += -(position - 4) % 8
    if length < 1 or position + 48 > len(data):
        raise ValueError('WrenchStamped frame_id beyond the message')
    values = _WRENCH.unpack_from(data, position)
    return sec, nanosec, values[:3], values[3:]


_TIME = struct.Struct('<iI')


def read_time_reference(data):
    """
    Decode sensor_msgs/msg/TimeReference CDR bytes: its ``time_ref`` (sec, nanosec).

    The header (stamp, frame_id) comes first, then time_ref (aligned to 4), then the
    source string. Raises ValueError on bytes that are no little-endian CDR
    TimeReference.
    """
    if data[:4] != ENCAPSULATION_LE or len(data) < 16:
        raise ValueError('not a little-endian CDR TimeReference')
    (length,) = struct.unpack_from('<I', data, 12)
    position = 16 + length
    position += -(position - 4) % 4
    if length < 1 or position + 8 > len(data):
        raise ValueError('TimeReference frame_id beyond the message')
    return _TIME.unpack_from(data, position)


class JointStateReader:
    """
    One joint's stamp, position and velocity from JointState CDR bytes, without rclpy.

    The offsets are found once per message layout (frame, joint names and sequence
    lengths, as :func:`find_joint_state_fields`) and reused while the messages keep it:
    about 1.5 us a message against rclpy's 15 us to make the message object.
    """

    def __init__(self, joint):
        """Read ``joint`` (a name in JointState.name)."""
        self.joint = joint
        self._key = None            # (length, bytes from the frame_id to the counts)
        self._offsets = None

    def read(self, data):
        """
        Return (sec, nanosec, position, velocity), or None when the joint is not there.

        None also when the joint has no position or velocity (:func:`joint_state_names`
        says which joints the message has). Raises ValueError (struct.error,
        UnicodeDecodeError) on bytes that are no little-endian CDR JointState.
        """
        key, offsets = self._key, self._offsets
        if key is None or len(data) != key[0] or data[12:key[1]] != key[2] or \
                data[offsets['position_count']:offsets['position_count'] + 4] != key[3] or \
                data[offsets['velocity_count']:offsets['velocity_count'] + 4] != key[4]:
            found = find_joint_state_fields(data, self.joint)
            if found is None:
                return None
            offsets, names_end = found
            counts = [bytes(data[offsets[f'{s}_count']:offsets[f'{s}_count'] + 4])
                      for s in ('position', 'velocity')]
            self._key = (len(data), names_end, bytes(data[12:names_end]), *counts)
            self._offsets = offsets
        sec, nanosec = struct.unpack_from('<iI', data, 4)
        (position,) = struct.unpack_from('<d', data, offsets['position'])
        (velocity,) = struct.unpack_from('<d', data, offsets['velocity'])
        return sec, nanosec, position, velocity
