"""
rosbag2-style MCAP files: profile ros2, ros2msg schemas, CDR messages, chunked.

Two ways in: :meth:`BagWriter.write` takes one serialized message (live
recording), :meth:`BagWriter.write_block` takes n samples of fixed-layout
messages built as one numpy array (offline replay, simulation). Chunks are
compressed on the worker threads and written in order by one I/O thread,
each with its message indexes and flushed at once, so a process killed at
any moment loses at most the chunks not yet written (the one being filled
and those in flight). The framing
records come from the ``mcap`` package; only message records and message
indexes are packed here, with numpy.
"""

from collections import defaultdict, deque
from concurrent.futures import ThreadPoolExecutor
import struct
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, ChunkIndex, DataEnd, Footer, Header, Schema, Statistics,
                          SummaryOffset)
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
        self.fields = {name: self.array[name] for name in names}   # views, made once
        self._offsets = {}

    def record_offsets_for(self, count):
        """{channel: offsets of its records} within a chunk of ``count`` samples (cached)."""
        if count not in self._offsets:
            base = np.arange(count, dtype=np.uint64) * np.uint64(self.group_size)
            self._offsets[count] = {channel: base + np.uint64(offset) for channel, offset
                                    in zip(self.channels, self.record_offsets)}
        return self._offsets[count]

    def set_time(self, log_time, count=None):
        """Set log and publish time (ns) of every message of the first ``count`` samples."""
        count = self.n if count is None else count
        for g in range(len(self.channels)):
            self.fields[f'{g}.log'][:count] = log_time[:count]
            self.fields[f'{g}.pub'][:count] = log_time[:count]


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
        self._io = ThreadPoolExecutor(max_workers=1, thread_name_prefix='bag_writer')
        self._io_jobs = deque()
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

    def write_block(self, block, log_time, count=None):
        """
        Add the first ``count`` samples of a :class:`MessageBlock` (default all).

        ``log_time`` (count,) ns, non-decreasing, is set on the block. The bytes
        are copied: the block can be refilled as soon as this returns, while
        its chunks are compressed on the worker threads and written in order by
        the writer's I/O thread.
        """
        self._flush_pending()
        count = block.n if count is None else count
        log_time = np.asarray(log_time, dtype=np.uint64)
        block.set_time(log_time, count)
        per_chunk = max(1, self._chunk_bytes // block.group_size)
        for start in range(0, count, per_chunk):
            stop = min(start + per_chunk, count)
            records = block.bytes[start * block.group_size:stop * block.group_size].tobytes()
            times = log_time[start:stop]
            index = {channel: (times, offsets)
                     for channel, offsets in block.record_offsets_for(stop - start).items()}
            for channel in block.channels:
                self._counts[channel] += stop - start
            self._submit(records, index, int(times[0]), int(times[-1]))

    def close(self):
        """Write the last chunk, the summary and the footer; close the file."""
        if self._closed:
            return
        self._flush_pending()
        self._wait_for_io()
        self._io.shutdown()
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
        self._submit(bytes(self._pending), index, *self._pending_times)
        self._pending = bytearray()
        self._pending_index = defaultdict(list)
        self._pending_times = [None, None]

    def _submit(self, records, index, start_time, end_time):
        """Compress a chunk on a worker thread; write it, in order, on the I/O thread."""
        packed = pool().submit(self._pack, records)
        self._io_jobs.append(self._io.submit(self._write_chunk, packed, records, index,
                                             start_time, end_time))
        while len(self._io_jobs) > 32:          # bound the memory held by chunks in flight
            self._io_jobs.popleft().result()

    def _pack(self, records):
        return self._compress(records), zlib.crc32(records)

    def _wait_for_io(self):
        while self._io_jobs:
            self._io_jobs.popleft().result()

    def _write_chunk(self, packed, records, index, start_time, end_time):
        data, crc = packed.result()
        # The Chunk record, framed here so that its megabyte of data is written once,
        # not copied through mcap's RecordBuilder.
        compression = self._compression.encode()
        header = struct.pack(f'<BQQQQII{len(compression)}sQ', Opcode.CHUNK,
                             8 + 8 + 8 + 4 + 4 + len(compression) + 8 + len(data), start_time,
                             end_time, len(records), crc, len(compression), compression,
                             len(data))
        chunk_start = self._stream.tell()
        self._stream.write(header)
        self._stream.write(data)
        chunk_length = len(header) + len(data)
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
            chunk_start_offset=chunk_start, chunk_length=chunk_length,
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
