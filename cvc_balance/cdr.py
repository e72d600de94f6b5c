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
