"""
Read MCAP bags fast and forgivingly: whole chunks parsed with numpy.

The top-level records are walked once (a few per chunk); a file that ends
inside a record (a recording killed mid-chunk) or a chunk that does not
decompress is reported in ``Bag.problems`` and the rest is still used.
Messages of a channel are located through the message indexes written after
each chunk (or, without them, by walking the chunk's records), and fields of
fixed-layout messages are gathered for all messages of a chunk at once.
"""

from collections import deque
from dataclasses import dataclass, field
import mmap
import os
import struct
import threading

import numpy as np

from cvc_balance.messages.cdr import ENCAPSULATION_LE, find_joint_state_fields, read_string_message

try:    # ISA-L's CRC-32 (zlib's polynomial) runs ~15 times faster than zlib's here
    from isal.isal_zlib import crc32
except ImportError:                                  # pragma: no cover
    from zlib import crc32

MAGIC = b'\x89MCAP0\r\n'
OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_DATA_END = 0x06, 0x07, 0x0F
MESSAGE_HEADER = 31
AHEAD = 4
"""Chunks decompressed ahead of the one being parsed."""
_U64 = struct.Struct('<Q')
_local = threading.local()   # a decompressor per thread


class BagError(ValueError):
    """A bag that cannot be used at all; ``str()`` says why in one line."""


@dataclass
class ChannelInfo:
    """A channel of the bag: topic, message type, encoding."""

    id: int
    topic: str
    msg_type: str
    encoding: str


@dataclass
class ChunkInfo:
    """A chunk's place in the file and its message indexes (channel -> offsets)."""

    offset: int
    compression: str
    data: memoryview
    uncompressed_size: int
    crc: int
    indexes: dict = field(default_factory=dict)


class Bag:
    """An MCAP file's channels and chunks; messages are decoded on request."""

    def __init__(self, path):
        """Read and index ``path``; raises :class:`BagError` if it is no MCAP file."""
        self.path = str(path)
        try:
            with open(self.path, 'rb') as stream:
                # Mapped, not read: the file's pages are shared with the page cache.
                size = os.fstat(stream.fileno()).st_size
                self._bytes = mmap.mmap(stream.fileno(), size, access=mmap.ACCESS_READ) \
                    if size else b''
        except OSError as error:
            raise BagError(f'{self.path}: cannot read bag: {error.strerror}') from None
        self.problems = []
        self.schemas, self.channels, self.chunks = {}, {}, []
        self._loose = []         # (channel, offset in file) of messages outside chunks
        self._unreadable = set()   # chunks already reported
        self._walk()

    # -- structure -------------------------------------------------------------------

    def _walk(self):
        data = self._bytes
        if data[:8] != MAGIC:
            raise BagError(f'{self.path}: not an MCAP file (no MCAP magic at the start)')
        position, size, finished = 8, len(data), False
        while position < size:
            if position + 9 > size:
                self.problems.append(f'file ends inside a record header at byte {position} '
                                     '(truncated recording?)')
                break
            opcode, length = struct.unpack_from('<BQ', data, position)
            start = position + 9
            if start + length > size:
                self.problems.append(f'file ends inside a record (opcode 0x{opcode:02x}) '
                                     f'at byte {position} of {size} (truncated recording?)')
                break
            try:
                self._record(opcode, start, length)
            except (struct.error, UnicodeDecodeError, ValueError) as error:
                self.problems.append(f'corrupt record (opcode 0x{opcode:02x}) at byte '
                                     f'{position}: {error}; stopped reading there')
                break
            position = start + length
            if opcode in (OP_DATA_END, OP_FOOTER):
                finished = True
                break
        if not finished and not self.problems:
            self.problems.append('file has no end of data (truncated recording?)')

    def _record(self, opcode, start, length):
        data = self._bytes
        if opcode == OP_SCHEMA:
            schema_id, = struct.unpack_from('<H', data, start)
            name, position = _string(data, start + 2)
            self.schemas[schema_id] = name
        elif opcode == OP_CHANNEL:
            channel_id, schema_id = struct.unpack_from('<HH', data, start)
            topic, position = _string(data, start + 4)
            encoding, position = _string(data, position)
            self.channels[channel_id] = ChannelInfo(channel_id, topic,
                                                    self.schemas.get(schema_id, ''), encoding)
        elif opcode == OP_CHUNK:
            position = start + 8 + 8
            size, crc = struct.unpack_from('<QI', data, position)
            compression, position = _string(data, position + 12)
            records_length, = struct.unpack_from('<Q', data, position)
            records = memoryview(data)[position + 8:position + 8 + records_length]
            if position + 8 + records_length > start + length:
                raise ValueError('chunk data beyond its record')
            self.chunks.append(ChunkInfo(start - 9, compression, records, size, crc))
        elif opcode == OP_MESSAGE_INDEX and self.chunks:
            channel_id, body = struct.unpack_from('<HI', data, start)
            pairs = np.frombuffer(data, dtype=[('t', '<u8'), ('o', '<u8')], count=body // 16,
                                  offset=start + 6)
            self.chunks[-1].indexes[channel_id] = pairs['o']
        elif opcode == OP_MESSAGE:
            channel_id, = struct.unpack_from('<H', data, start)
            self._loose.append((channel_id, start - 9))

    def topics(self):
        """Return {topic: message type} of the bag's channels."""
        return {c.topic: c.msg_type for c in self.channels.values()}

    def channel(self, topic, msg_type):
        """Return the channel of ``topic`` (a name or its last part) with ``msg_type``."""
        wanted = topic.strip('/')
        found = [c for c in self.channels.values()
                 if c.topic.strip('/') == wanted or c.topic.endswith('/' + wanted)]
        if not found:
            return None
        for c in found:
            if c.msg_type != msg_type:
                raise BagError(f'{self.path}: topic {c.topic} has type {c.msg_type}, '
                               f'expected {msg_type}')
        return found[0]

    # -- message access ----------------------------------------------------------------

    def _decoded_chunks(self, numbers):
        """
        Yield (number, records or None) of chunks ``numbers``, in order.

        The next few chunks are decompressed (and checked) on the worker threads
        while the caller parses the current one.
        """
        from cvc_balance.physics.workers import pool
        numbers, ahead = iter(numbers), deque()
        while True:
            while len(ahead) < AHEAD:
                number = next(numbers, None)
                if number is None:
                    break
                ahead.append((number, pool().submit(_decode, self.chunks[number])))
            if not ahead:
                return
            number, job = ahead.popleft()
            records, error = job.result()
            if error is not None and number not in self._unreadable:
                self._unreadable.add(number)
                self.problems.append(f'chunk at byte {self.chunks[number].offset} unreadable '
                                     f'({error}); skipped')
            yield number, records

    def message_offsets(self, channel):
        """Yield (records as uint8 array, offsets of this channel's message records)."""
        # Indexed chunks without messages of this channel are not even decompressed.
        wanted = [number for number, chunk in enumerate(self.chunks)
                  if channel.id in chunk.indexes or not chunk.indexes]
        for number, records in self._decoded_chunks(wanted):
            chunk = self.chunks[number]
            if records is None:
                continue
            buffer = np.frombuffer(records, dtype=np.uint8)
            offsets = chunk.indexes.get(channel.id)
            if offsets is None:
                offsets = _walk_chunk(records, channel.id)
            if len(offsets) and int(offsets.max()) + MESSAGE_HEADER > len(records):
                self.problems.append(f'chunk at byte {chunk.offset}: message index beyond the '
                                     'chunk; skipped')
                continue
            if len(offsets):
                yield buffer, offsets.astype(np.int64)
        if self._loose:
            buffer = np.frombuffer(self._bytes, dtype=np.uint8)
            offsets = np.array([o for c, o in self._loose if c == channel.id], dtype=np.int64)
            if len(offsets):
                yield buffer, offsets

    def message_count(self, channel):
        """Return the number of messages of ``channel`` the message indexes list."""
        return sum(len(chunk.indexes.get(channel.id, ())) for chunk in self.chunks) + \
            sum(1 for c, _ in self._loose if c == channel.id)

    def messages(self, channel):
        """Return [(log time ns, bytes)] of a channel, in file order (for few messages)."""
        out = []
        for buffer, offsets in self.message_offsets(channel):
            data = buffer.tobytes()          # once per chunk, then plain slices
            for offset in offsets.tolist():
                (length,), (log_time,) = (_U64.unpack_from(data, offset + 1),
                                          _U64.unpack_from(data, offset + 15))
                out.append((log_time, data[offset + MESSAGE_HEADER:offset + 9 + length]))
        return out


def _decode(chunk):
    """Return (records, None) of a chunk, decompressed and checked, or (None, error)."""
    try:
        if chunk.compression == '':
            records = chunk.data
        elif chunk.compression == 'zstd':
            import zstandard
            if not hasattr(_local, 'zstd'):
                _local.zstd = zstandard.ZstdDecompressor()
            records = _local.zstd.decompress(chunk.data,
                                             max_output_size=chunk.uncompressed_size)
        elif chunk.compression == 'lz4':
            import lz4.frame
            records = lz4.frame.decompress(chunk.data)
        else:
            raise ValueError(f'unknown compression {chunk.compression!r}')
        if len(records) != chunk.uncompressed_size:
            raise ValueError('size differs from the chunk header')
        if chunk.crc and crc32(records) != chunk.crc:
            raise ValueError('CRC mismatch')
    except Exception as error:  # any codec's error: the chunk is lost, the rest is used
        return None, error
    return records, None


def _string(data, position):
    length, = struct.unpack_from('<I', data, position)
    return bytes(data[position + 4:position + 4 + length]).decode('utf-8'), position + 4 + length


def _walk_chunk(records, channel_id):
    """Offsets of a channel's message records in a chunk without message indexes."""
    offsets, position = [], 0
    while position + 9 <= len(records):
        opcode, length = struct.unpack_from('<BQ', records, position)
        if opcode == OP_MESSAGE and struct.unpack_from('<H', records, position + 9)[0] == \
                channel_id:
            offsets.append(position)
        position += 9 + length
    return np.array(offsets, dtype=np.int64)


def _stride(at):
    """Return the common step of evenly spaced positions ``at`` (increasing), else None."""
    if len(at) > 1:
        stride = int(at[1] - at[0])
        if stride > 0 and at[-1] - at[0] == stride * (len(at) - 1) and \
                np.all(np.diff(at) == stride):
            return stride
    return None


def alike(buffer, at, spans):
    """
    Whether bytes ``spans`` ((start, stop) pairs) after each position ``at`` match the first's.

    Compared up to eight bytes at a time through strided views when the positions
    are evenly spaced (records of one fixed layout written one after the other),
    else gathered.
    """
    stride = _stride(at)
    for lo, hi in spans:
        if hi <= lo:
            continue
        if stride is None:
            block = buffer[at[:, None] + np.arange(lo, hi)]
            if not np.all(block == block[0]):
                return False
            continue
        width = next(w for w in (8, 4, 2, 1) if w <= hi - lo)
        starts = list(range(lo, hi - width + 1, width))
        if starts[-1] + width < hi:
            starts.append(hi - width)       # the last word overlaps the one before
        for start in starts:
            column = np.ndarray(shape=(len(at),), dtype=f'<u{width}', buffer=buffer,
                                offset=int(at[0]) + start, strides=(stride,))
            if not np.all(column == column[0]):
                return False
    return True


def gather(buffer, offsets, data_offset, dtype, copy=True):
    """
    One field of every message: ``dtype`` at ``data_offset`` in each message's data.

    Records evenly spaced in the chunk (one writer, fixed layout) are read through a
    strided view (returned as it is with ``copy=False``: valid while ``buffer`` is);
    others by gathering their bytes.
    """
    dtype = np.dtype(dtype)
    at = offsets + (MESSAGE_HEADER + data_offset)
    stride = _stride(at)
    if stride is not None:
        view = np.ndarray(shape=(len(at),), dtype=dtype, buffer=buffer, offset=int(at[0]),
                          strides=(stride,))
        return view.copy() if copy else view
    columns = np.arange(dtype.itemsize)
    return buffer[at[:, None] + columns].copy().view(dtype).ravel()


class _Columns:
    """Columns filled part by part into arrays made once (grown if more rows come)."""

    def __init__(self, dtypes, capacity):
        self.arrays = [np.empty(capacity, dtype) for dtype in dtypes]
        self.rows = 0

    def take(self, count):
        """Return views of the next ``count`` rows, to be filled."""
        if self.rows + count > len(self.arrays[0]):
            size = max(2 * len(self.arrays[0]), self.rows + count)
            self.arrays = [np.concatenate([a[:self.rows], np.empty(size - self.rows, a.dtype)])
                           for a in self.arrays]
        views = [a[self.rows:self.rows + count] for a in self.arrays]
        self.rows += count
        return views

    def filled(self):
        """Return the filled part of each column."""
        return [a[:self.rows] for a in self.arrays]


def _lengths(buffer, offsets):
    return gather(buffer, offsets - MESSAGE_HEADER + 1, 0, '<u8') if len(offsets) else offsets


def log_times(buffer, offsets, copy=True):
    """Log times (ns) of the messages at ``offsets`` (``copy`` as in :func:`gather`)."""
    return gather(buffer, offsets - MESSAGE_HEADER + 15, 0, '<u8', copy)


@dataclass
class MotionSamples:
    """Motion samples of a bag: stamp (ns), log time (ns), angle (rad), omega (rad/s)."""

    stamp: np.ndarray
    log_time: np.ndarray
    angle: np.ndarray
    omega: np.ndarray
    rejected: int = 0
    reasons: list = field(default_factory=list)


def joint_samples(bag, channel, joint):
    """
    Stamp, angle and speed of ``joint`` from every JointState of ``channel``.

    Chunks whose messages all share the first one's layout are gathered with
    numpy; others are decoded message by message. Messages without the joint
    (or its position and velocity) are counted as rejected.
    """
    rejected, reasons = 0, []
    # Filled in place, chunk by chunk: sized by the message indexes, where there are some.
    columns = _Columns((np.int64, np.int64, float, float), bag.message_count(channel))
    for buffer, offsets in bag.message_offsets(channel):
        lengths = _lengths(buffer, offsets)
        first = buffer[offsets[0] + MESSAGE_HEADER:offsets[0] + 9 + int(lengths[0])].tobytes()
        found = find_joint_state_fields(first, joint) if first[:4] == ENCAPSULATION_LE else None
        uniform = found is not None and bool(np.all(lengths == lengths[0]))
        if uniform:
            fields, names_end = found
            # All but the stamp alike: encapsulation, frame id and joint names.
            uniform = alike(buffer, offsets + MESSAGE_HEADER, ((0, 4), (12, names_end)))
        if uniform:
            stamp, log_time, angle, omega = columns.take(len(offsets))
            np.multiply(gather(buffer, offsets, fields['sec'], '<i4', copy=False),
                        1_000_000_000, out=stamp, dtype=np.int64)
            stamp += gather(buffer, offsets, fields['nanosec'], '<u4', copy=False)
            log_time[:] = log_times(buffer, offsets, copy=False)
            angle[:] = gather(buffer, offsets, fields['position'], '<f8', copy=False)
            omega[:] = gather(buffer, offsets, fields['velocity'], '<f8', copy=False)
            continue
        rows = []
        for offset, length in zip(offsets.tolist(), lengths.tolist()):
            data = buffer[offset + MESSAGE_HEADER:offset + 9 + length].tobytes()
            try:
                found = find_joint_state_fields(data, joint)
            except (ValueError, struct.error, UnicodeDecodeError):
                found = None
            if found is None:
                rejected += 1
                if len(reasons) < 5:
                    reasons.append(f"joint_states without joint '{joint}' or its position and "
                                   'velocity')
                continue
            f = found[0]
            sec, nanosec = struct.unpack_from('<iI', data, 4)
            rows.append((sec * 1_000_000_000 + nanosec,
                         struct.unpack_from('<Q', buffer, offset + 15)[0],
                         struct.unpack_from('<d', data, f['position'])[0],
                         struct.unpack_from('<d', data, f['velocity'])[0]))
        if rows:
            for column, values in zip(columns.take(len(rows)), zip(*rows)):
                column[:] = values
    stamp, log_time, angle, omega = columns.filled()
    if np.any(log_time[1:] < log_time[:-1]):
        order = np.argsort(log_time, kind='stable')
        stamp, log_time, angle, omega = stamp[order], log_time[order], angle[order], omega[order]
    return MotionSamples(stamp, log_time, angle, omega, rejected, reasons)


def float64_samples(bag, channel):
    """(log time ns, data) of every std_msgs/Float64 of ``channel``."""
    times, values = [], []
    for buffer, offsets in bag.message_offsets(channel):
        times.append(log_times(buffer, offsets).astype(np.int64))
        values.append(gather(buffer, offsets, 4, '<f8'))
    if not times:
        return np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(times), np.concatenate(values)


def wrench_samples(bag, channel):
    """(stamp ns, force (n, 3), torque (n, 3)) of every WrenchStamped of ``channel``."""
    stamps, wrenches = [], []
    for buffer, offsets in bag.message_offsets(channel):
        lengths = _lengths(buffer, offsets)
        sec = gather(buffer, offsets, 4, '<i4').astype(np.int64)
        nanosec = gather(buffer, offsets, 8, '<u4')
        stamps.append(sec * 1_000_000_000 + nanosec)
        # The six float64 are the last 48 bytes of each message, whatever the frame_id.
        ends = offsets + 9 + lengths.astype(np.int64) - 48 - MESSAGE_HEADER
        wrenches.append(np.stack([gather(buffer, ends, 8 * i, '<f8') for i in range(6)], 1))
    if not stamps:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    wrench = np.concatenate(wrenches)
    return np.concatenate(stamps), wrench[:, :3], wrench[:, 3:]


def string_samples(bag, channel):
    """[(log time ns, text)] of a std_msgs/String channel; undecodable ones reported."""
    out = []
    for log_time, data in bag.messages(channel):
        try:
            out.append((log_time, read_string_message(data)))
        except (ValueError, UnicodeDecodeError) as error:
            bag.problems.append(f'{channel.topic}: message at {log_time} ns unreadable '
                                f'({error}); skipped')
    return out
