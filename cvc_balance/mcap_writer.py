"""
rosbag2-style MCAP files: profile ros2, ros2msg schemas, CDR messages, chunked.

Two ways in: :meth:`BagWriter.write` takes one serialized message (live
recording), :meth:`BagWriter.write_block` takes n samples of fixed-layout
messages built as one numpy array (offline replay, simulation). Each finished
chunk is written and flushed with its message indexes at once, so a process
killed at any moment loses at most the chunk it was filling. The framing
records come from the ``mcap`` package; only message records and message
indexes are packed here, with numpy.
"""

from collections import defaultdict
import struct
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema,
                          Statistics, SummaryOffset)
from mcap.writer import MCAP0_MAGIC
import numpy as np

from cvc_balance.msg_schema import schema_text
from cvc_balance.workers import pool

PROFILE = 'ros2'
LIBRARY = 'cvc_balance'
MESSAGE_HEADER = 31   # opcode 1, length 8, channel 2, sequence 4, log time 8, publish time 8
_MESSAGE_RECORD = struct.Struct('<BQHIQQ')
_QOS = ('- history: 3\n  depth: 0\n  reliability: {reliability}\n  durability: {durability}\n'
        '  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n'
        '  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n'
        '  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n'
        '  avoid_ros_namespace_conventions: false\n')


def _compressor(name):
    if name == 'zstd':
        import zstandard
        # One compressor per call: they must not be shared between threads.
        return lambda data: zstandard.ZstdCompressor(level=1).compress(data)
    if name == 'lz4':
        import lz4.frame
        return lambda data: lz4.frame.compress(data, store_size=True)
    if name == '':
        return bytes
    raise ValueError(f'unknown compression {name!r} (zstd, lz4 or none)')


class MessageBlock:
    """
    n samples of G fixed-layout messages each, as MCAP message records.

    ``parts`` is a list of (channel id, CdrLayout); sample i's G records lie
    one after the other. Set ``array['log_time']`` and each part's fields
    ``array[f'{g}.{field}']`` (g = part index), then hand the block to
    :meth:`BagWriter.write_block`.
    """

    def __init__(self, parts, n):
        """Allocate the block for ``n`` samples, constant bytes filled in."""
        template, names, formats, offsets = bytearray(), [], [], []
        self.channels, self.record_offsets = [], []
        for g, (channel, layout) in enumerate(parts):
            self.channels.append(channel)
            self.record_offsets.append(len(template))
            header = np.zeros(1, dtype=[('op', 'u1'), ('len', '<u8'), ('ch', '<u2'),
                                        ('seq', '<u4'), ('log', '<u8'), ('pub', '<u8')])
            header['op'], header['len'], header['ch'] = (Opcode.MESSAGE,
                                                         MESSAGE_HEADER - 9 + layout.size, channel)
            for stamp_field in ('log', 'pub'):
                names.append(f'{g}.{stamp_field}')
                formats.append('<u8')
                offsets.append(len(template) + (15 if stamp_field == 'log' else 23))
            data_start = len(template) + MESSAGE_HEADER
            template += header.tobytes() + layout.template
            for name, (offset, fmt) in layout.fields.items():
                names.append(f'{g}.{name}')
                formats.append(fmt)
                offsets.append(data_start + offset)
        self.group_size = len(template)
        self.n = n
        self.bytes = np.tile(np.frombuffer(bytes(template), np.uint8), n)
        self.array = self.bytes.view(np.dtype({'names': names, 'formats': formats,
                                               'offsets': offsets,
                                               'itemsize': self.group_size}))

    def set_time(self, log_time):
        """Set log and publish time (ns) of every message of each sample."""
        for g in range(len(self.channels)):
            self.array[f'{g}.log'] = log_time
            self.array[f'{g}.pub'] = log_time


class BagWriter:
    """Write a rosbag2-compatible MCAP file (see the module's description)."""

    def __init__(self, path, compression='zstd', chunk_bytes=1 << 20):
        """Open ``path`` for writing; ``compression`` 'zstd', 'lz4' or ''."""
        self.path = str(path)
        self._stream = open(self.path, 'wb')
        self._compression = compression
        self._compress = _compressor(compression)
        self._chunk_bytes = chunk_bytes
        self._schemas, self._channels, self._chunk_indexes = {}, {}, []
        self._counts = defaultdict(int)
        self._times = [None, None]
        self._chunk_count = 0
        self._pending = bytearray()
        self._pending_index = defaultdict(list)
        self._pending_times = [None, None]
        self._stream.write(MCAP0_MAGIC)
        self._emit(Header(profile=PROFILE, library=LIBRARY))
        self._closed = False

    def add_channel(self, topic, msg_type, latched=False, best_effort=False):
        """Register ``topic`` of ``msg_type`` ('pkg/msg/Type'); return its channel id."""
        if msg_type not in self._schemas:
            schema = Schema(id=len(self._schemas) + 1, name=msg_type, encoding='ros2msg',
                            data=schema_text(msg_type).encode())
            self._schemas[msg_type] = schema
            self._emit(schema)
        qos = _QOS.format(reliability=2 if best_effort else 1, durability=1 if latched else 2)
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding='cdr',
                          metadata={'offered_qos_profiles': qos},
                          schema_id=self._schemas[msg_type].id)
        self._channels[channel.id] = channel
        self._emit(channel)
        return channel.id

    def write(self, channel, log_time, data):
        """Add one serialized message (CDR bytes) at ``log_time`` ns."""
        self._pending_index[channel].append((log_time, len(self._pending)))
        self._pending += _MESSAGE_RECORD.pack(Opcode.MESSAGE, MESSAGE_HEADER - 9 + len(data),
                                              channel, 0, log_time, log_time)
        self._pending += data
        self._counts[channel] += 1
        _extend(self._pending_times, log_time, log_time)
        if len(self._pending) >= self._chunk_bytes:
            self._flush_pending()

    def write_block(self, block, log_time):
        """Add a :class:`MessageBlock`; ``log_time`` (n,) ns, non-decreasing, is set on it."""
        self._flush_pending()
        log_time = np.asarray(log_time, dtype=np.uint64)
        block.set_time(log_time)
        per_chunk = max(1, self._chunk_bytes // block.group_size)
        chunks = []
        for start in range(0, block.n, per_chunk):
            stop = min(start + per_chunk, block.n)
            records = block.bytes[start * block.group_size:stop * block.group_size].tobytes()
            chunks.append((start, stop, records))
        # Compression dominates: the chunks of a block are compressed on all cores.
        compressed = pool().map(self._compress, [records for _, _, records in chunks])
        for (start, stop, records), data in zip(chunks, compressed):
            times = log_time[start:stop]
            base = np.arange(stop - start, dtype=np.uint64) * np.uint64(block.group_size)
            index = {channel: (times, base + np.uint64(offset))
                     for channel, offset in zip(block.channels, block.record_offsets)}
            for channel in block.channels:
                self._counts[channel] += stop - start
            self._write_chunk(records, index, int(times[0]), int(times[-1]), data)

    def close(self):
        """Write the last chunk, the summary and the footer; close the file."""
        if self._closed:
            return
        self._flush_pending()
        self._emit(DataEnd(data_section_crc=0))
        summary_start = self._stream.tell()
        summary, offsets = RecordBuilder(), []
        groups = ((Opcode.SCHEMA, self._schemas.values()),
                  (Opcode.CHANNEL, self._channels.values()),
                  (Opcode.STATISTICS, [self._statistics()]),
                  (Opcode.CHUNK_INDEX, self._chunk_indexes))
        for opcode, records in groups:
            start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=summary.count - start))
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        self._stream.write(summary.end())
        self._emit(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                          summary_crc=0))
        self._stream.write(MCAP0_MAGIC)
        self._stream.close()
        self._closed = True

    def __enter__(self):
        """Use as a context manager: closed (finalised) on exit."""
        return self

    def __exit__(self, *exc):
        """Finalise the file."""
        self.close()

    # -- internals -------------------------------------------------------------------

    def _emit(self, record):
        builder = RecordBuilder()
        record.write(builder)
        self._stream.write(builder.end())

    def _flush_pending(self):
        if not self._pending:
            return
        index = {channel: (np.array([t for t, _ in entries], dtype=np.uint64),
                           np.array([o for _, o in entries], dtype=np.uint64))
                 for channel, entries in self._pending_index.items()}
        records = bytes(self._pending)
        self._write_chunk(records, index, *self._pending_times, self._compress(records))
        self._pending = bytearray()
        self._pending_index = defaultdict(list)
        self._pending_times = [None, None]

    def _write_chunk(self, records, index, start_time, end_time, data):
        chunk = Chunk(message_start_time=start_time, message_end_time=end_time,
                      uncompressed_size=len(records), uncompressed_crc=zlib.crc32(records),
                      compression=self._compression, data=data)
        chunk_start = self._stream.tell()
        builder = RecordBuilder()
        chunk.write(builder)
        chunk_bytes = builder.end()
        self._stream.write(chunk_bytes)
        index_start = self._stream.tell()
        index_offsets, parts = {}, []
        position = index_start
        for channel, (times, offsets) in index.items():
            pairs = np.empty(len(times), dtype=[('t', '<u8'), ('o', '<u8')])
            pairs['t'], pairs['o'] = times, offsets
            body = pairs.tobytes()
            header = np.array([(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel, len(body))],
                              dtype=[('op', 'u1'), ('len', '<u8'), ('ch', '<u2'),
                                     ('n', '<u4')]).tobytes()
            index_offsets[channel] = position
            parts += [header, body]
            position += len(header) + len(body)
        self._stream.write(b''.join(parts))
        self._stream.flush()   # a finished chunk survives a killed process
        self._chunk_count += 1
        _extend(self._times, start_time, end_time)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time,
            chunk_start_offset=chunk_start, chunk_length=len(chunk_bytes),
            message_index_offsets=index_offsets, message_index_length=position - index_start,
            compression=self._compression, compressed_size=len(data),
            uncompressed_size=len(records)))

    def _statistics(self):
        start, end = self._times
        return Statistics(message_count=sum(self._counts.values()),
                          schema_count=len(self._schemas), channel_count=len(self._channels),
                          attachment_count=0, metadata_count=0, chunk_count=self._chunk_count,
                          message_start_time=start or 0, message_end_time=end or 0,
                          channel_message_counts=dict(self._counts))


def _extend(span, start, end):
    span[0] = start if span[0] is None else min(span[0], start)
    span[1] = end if span[1] is None else max(span[1], end)
