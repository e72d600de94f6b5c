"""
rosbag2-style MCAP files: profile ros2, ros2msg schemas, CDR messages, chunked.

Two ways in: :meth:`BagWriter.write` takes one serialized message (live
recording), :meth:`BagWriter.write_block` takes n samples of fixed-layout
messages built in a numpy buffer (offline replay, simulation). Chunks are
compressed (and their CRC taken) on the writer's worker threads, straight
from the buffer they were built in, and written in order by one I/O thread
with one system call per chunk (chunk record and its message indexes), so a
process killed at any moment loses at most the chunks not yet written (the
one being filled and those in flight). Buffers are reused, and the page cache
of written chunks is let go once they are on disk: on virtual machines that
hand freed memory back to the host, touching new pages costs more than
compressing them. The framing records come from the ``mcap`` package; only
chunks, message records and message indexes are packed here.

As Jazzy's rosbag2 writes a file: each file carries rosbag2's ``rosbag2`` Metadata
record (:mod:`cvc_balance.bag.rosbag2_metadata`) right after the header and again,
complete, when it is closed; schemas are rosbag2's texts (:mod:`cvc_balance.messages.
msg_schema`); each channel has ``offered_qos_profiles`` (in the form both rosbag2 and
Foxglove read: :func:`~cvc_balance.bag.rosbag2_metadata.channel_qos`) and
``topic_type_hash``.
"""

from collections import defaultdict, deque
from concurrent.futures import ThreadPoolExecutor
import os
import stat
import struct
import threading
from typing import NamedTuple

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, ChunkIndex, DataEnd, Footer, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.writer import MCAP0_MAGIC
import numpy as np

from cvc_balance.bag.mcap_reader import BagError, crc32
from cvc_balance.bag.rosbag2_metadata import (bag_metadata, channel_qos, CUSTOM_DATA_RECORD,
                                              RECORD, record_values)
from cvc_balance.messages.msg_schema import schema_text, type_hash

PROFILE = 'ros2'
LIBRARY = 'cvc_balance'
MESSAGE_HEADER = 31   # opcode 1, length 8, channel 2, sequence 4, log time 8, publish time 8
INDEX_HEADER = 15     # opcode 1, length 8, channel 2, byte length of the entries 4
ZSTD_LEVEL = 1
"""zstd level of the chunks unless the writer is given one (libmcap's default too)."""
BUFFERS = 8
"""Buffers a :class:`MessageBlock` rotates through: one filled while the others are packed."""
CACHED = 8
"""Chunks last written whose pages stay in the page cache (see BagWriter._let_go)."""
_MESSAGE_RECORD = struct.Struct('<BQHIQQ')
_INDEX_HEADER = np.dtype([('op', 'u1'), ('len', '<u8'), ('ch', '<u2'), ('n', '<u4')])


def _compressor(name, level=None):
    if name == 'zstd':
        import zstandard
        local = threading.local()   # a compressor must not be shared between threads

        def compress(data):
            if not hasattr(local, 'compressor'):
                local.compressor = zstandard.ZstdCompressor(
                    level=ZSTD_LEVEL if level is None else level)
            return local.compressor.compress(data)
        return compress
    if name == 'lz4':
        import lz4.frame
        return lambda data: lz4.frame.compress(data, compression_level=level or 0,
                                               store_size=True)
    if name == '':
        return None
    raise ValueError(f'unknown compression {name!r} (zstd, lz4 or none)')


class MessageBuffer:
    """One buffer of a :class:`MessageBlock`: n samples' records and views of their fields."""

    def __init__(self, block):
        """Make the buffer: the block's template n times."""
        self.block = block
        self.bytes = np.tile(block.template, block.n)
        self.array = self.bytes.view(block.dtype)
        self.fields = {name: self.array[name] for name in block.dtype.names}
        self._views = {}

    def put(self, names, values, count, dtype=None):
        """
        Set fields ``names`` of the first ``count`` samples to ``values``.

        ``values`` is one row per field, (len(names), count), or one (count,)
        row for all of them. ``dtype`` (default the first field's) is the type
        stored at each field's offset, e.g. '<u8' over a stamp's sec and
        nanosec. Rows go to fields evenly spaced in the block (consecutive
        fields of one type) in one strided copy, others field by field.
        """
        key = (tuple(names), dtype)
        if key not in self._views:
            n, size, layout = self.block.n, self.block.group_size, self.block.dtype.fields
            dtype = np.dtype(dtype or layout[names[0]][0])
            offsets = [layout[name][1] for name in names]
            step = offsets[1] - offsets[0] if len(offsets) > 1 else dtype.itemsize
            together = None
            if all(b - a == step for a, b in zip(offsets, offsets[1:])):
                together = np.ndarray((len(names), n), dtype, self.bytes, offsets[0],
                                      (step, size))
            self._views[key] = (together, [np.ndarray((n,), dtype, self.bytes, offset, (size,))
                                           for offset in offsets])
        together, apart = self._views[key]
        if np.ndim(values) == 1:
            for column in apart:
                column[:count] = values
        elif together is not None:
            together[:, :count] = values
        else:
            for column, row in zip(apart, values):
                column[:count] = row

    def set_time(self, log_time, count):
        """Set log and publish time (ns) of every message of the first ``count`` samples."""
        log_time = np.asarray(log_time[:count])
        parts = range(len(self.block.channels))
        for stamp in ('log', 'pub'):
            self.put([f'{g}.{stamp}' for g in parts], log_time, count)


class MessageBlock:
    """
    n samples of G fixed-layout messages each, as MCAP message records.

    ``parts`` is a list of (channel id, CdrLayout); sample i's G records lie
    one after the other. Set each part's fields ``fields[f'{g}.{field}']``
    (g = part index; or :meth:`put` several at once), then hand the block to
    :meth:`BagWriter.write_block`, which sets the log times.

    The block rotates through up to ``buffers`` :class:`MessageBuffer`, made
    when first needed: after ``write_block`` the fields are those of another
    buffer, which holds what was last written to it (the constant bytes of the
    template never change), so set every variable field before each write.
    """

    def __init__(self, parts, n, buffers=BUFFERS):
        """Lay out the block for ``n`` samples; its buffers are made when first needed."""
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
        self.template = np.frombuffer(bytes(template), np.uint8)
        self.dtype = np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                               'itemsize': self.group_size})
        self._max_buffers = max(1, buffers)
        self._made, self._free, self._busy = 0, deque(), deque()
        self._current = None
        self._offsets = {}

    @property
    def bytes(self):
        """Return the current buffer, uint8 (n * group_size,)."""
        return self.buffer().bytes

    @property
    def array(self):
        """Return the current buffer as a structured array of n samples."""
        return self.buffer().array

    @property
    def fields(self):
        """Return {'g.field': view of that field of the n samples} of the current buffer."""
        return self.buffer().fields

    def put(self, names, values, count, dtype=None):
        """Set fields of the current buffer (see :meth:`MessageBuffer.put`)."""
        self.buffer().put(names, values, count, dtype)

    def record_offsets_for(self, count):
        """{channel: offsets of its records} within a chunk of ``count`` samples (cached)."""
        if count not in self._offsets:
            base = np.arange(count, dtype=np.uint64) * np.uint64(self.group_size)
            self._offsets[count] = {channel: base + np.uint64(offset) for channel, offset
                                    in zip(self.channels, self.record_offsets)}
        return self._offsets[count]

    def hand_over(self, future):
        """Leave the current buffer to the writer until ``future`` is done; take another."""
        self._busy.append((future, self.buffer()))
        self._current = None

    def buffer(self):
        """Return the current :class:`MessageBuffer` (a free one, waited for if need be)."""
        if self._current is None:
            while self._busy and self._busy[0][0].done():
                self._free.append(self._busy.popleft()[1])
            if self._free:
                self._current = self._free.popleft()
            elif self._made < self._max_buffers:
                self._current = MessageBuffer(self)
                self._made += 1
            else:
                future, self._current = self._busy.popleft()
                future.result()
        return self._current


class BagWriter:
    """Write a rosbag2-compatible MCAP file (see the module's description)."""

    def __init__(self, path, compression='zstd', chunk_bytes=1 << 20, level=None,
                 custom_data=None, exclusive=False, file_name=None):
        """
        Open ``path`` for writing; ``compression`` 'zstd', 'lz4' or ''.

        ``level`` is the compressor's level (default: zstd :data:`ZSTD_LEVEL`,
        lz4 0); ``chunk_bytes`` the uncompressed size of a chunk. Right after the
        header (so a truncated recording keeps them), in one system call: rosbag2's
        ``rosbag2`` Metadata record as it is when a file is opened, and with
        ``custom_data`` ({key: value} strings, e.g. the machine's identity,
        :mod:`cvc_balance.bag.machine`) a Metadata record named ``cvc_balance`` of
        it; both indexed in the summary, the custom data in rosbag2's record too.
        ``file_name``: the file's name in rosbag2's metadata (default: its own).
        ``exclusive``: the file is created, never an existing one replaced (recordings,
        written in place): a :class:`~cvc_balance.bag.mcap_reader.BagError` if the
        name is taken (a file, a link, a directory).
        """
        self.path = str(path)
        if exclusive:
            try:
                self._file = open(self.path, 'xb', buffering=0)    # O_CREAT | O_EXCL
            except FileExistsError:
                raise BagError(f'{self.path}: exists; a recording never replaces a file '
                               '(give a name not taken)') from None
        else:
            _remove_old(self.path)
            self._file = open(self.path, 'wb', buffering=0)
        self._fd = self._file.fileno()
        self._position = 0
        self._file_lock = threading.Lock()
        self._written = deque()
        self._compression = compression
        self._compress = _compressor(compression, level)
        self._chunk_bytes = chunk_bytes
        self._schemas, self._channels, self._chunk_indexes = {}, {}, []
        self._offered = {}     # channel id -> TopicWritten (without its count)
        self._counts = defaultdict(int)
        self._times = [None, None]
        self._chunk_count = 0
        self._pending = bytearray()
        self._pending_index = defaultdict(list)
        self._pending_times = [None, None]
        # Its own threads, not workers.pool(): the reader's decompress-ahead jobs queue
        # there, and a replay's first run took 0.80-0.93 s instead of 0.77 s.
        self._workers = ThreadPoolExecutor(max_workers=os.cpu_count() or 1,
                                           thread_name_prefix='bag_pack')
        self._io = ThreadPoolExecutor(max_workers=1, thread_name_prefix='bag_writer')
        self._io_jobs = deque()
        self._index_templates = {}
        self.file_name = file_name or os.path.basename(self.path)
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self._write_all([MCAP0_MAGIC])
        self._emit(Header(profile=PROFILE, library=LIBRARY))
        self._metadata_indexes = []
        first = [Metadata(name=RECORD, metadata=record_values(self.bag_metadata()))]
        if self.custom_data:
            first.append(Metadata(name=CUSTOM_DATA_RECORD, metadata=dict(self.custom_data)))
        self._emit_metadata(first)
        self._closed = False

    def bag_metadata(self):
        """Return rosbag2's BagMetadata of what was written so far (see rosbag2_metadata)."""
        topics, (first, last) = self.written()
        files = [(self.file_name, first, last, sum(t.count for t in topics))]
        return bag_metadata(files, topics, self.custom_data)

    def add_channel(self, topic, msg_type, latched=False, best_effort=False):
        """Register ``topic`` of ``msg_type`` ('pkg/msg/Type'); return its channel id."""
        if msg_type not in self._schemas:
            schema = Schema(id=len(self._schemas) + 1, name=msg_type, encoding='ros2msg',
                            data=schema_text(msg_type).encode())
            self._schemas[msg_type] = schema
            self._emit(schema)
        metadata = {'offered_qos_profiles': channel_qos(best_effort, latched)}
        if type_hash(msg_type):         # as rosbag2 (Jazzy) writes it
            metadata['topic_type_hash'] = type_hash(msg_type)
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding='cdr',
                          metadata=metadata, schema_id=self._schemas[msg_type].id)
        self._channels[channel.id] = channel
        self._offered[channel.id] = TopicWritten(topic, msg_type, 0, latched, best_effort)
        self._emit(channel)
        return channel.id

    def written(self):
        """Return ([TopicWritten] per channel, (first, last) log time ns) written so far."""
        topics = [t._replace(count=self._counts[channel]) for channel, t in self._offered.items()]
        return topics, tuple(self._times)

    def block(self, parts):
        """Return a :class:`MessageBlock` of ``parts`` holding one chunk's samples."""
        block = MessageBlock(parts, 1)
        block.n = max(1, self._chunk_bytes // block.group_size)
        return block

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

    def write_block(self, block, log_time, count=None, fill=None):
        """
        Add the first ``count`` samples of a :class:`MessageBlock` (default all).

        ``log_time`` (count,) ns, non-decreasing, is set on the block. The
        buffer is not copied: it goes to the worker threads, which compress
        its chunks and write them in order, and the block takes another buffer
        for the next fill (:meth:`MessageBlock.hand_over`). ``fill(buffer)``, if
        given, sets the buffer's fields on a worker thread first (instead of the
        caller before the call): several buffers are then filled at once.
        """
        self._flush_pending()
        count = block.n if count is None else count
        if count == 0:
            # Nothing to write, nor to fill: a fill left running on a worker raced the next
            # block's fill of the same buffer (seen: a sample with the values before).
            return
        log_time = np.array(log_time[:count], dtype=np.uint64)   # kept until written
        buffer = block.buffer()
        data = buffer.bytes.data
        per_chunk = max(1, self._chunk_bytes // block.group_size)
        spans = [(start, min(start + per_chunk, count)) for start in range(0, count, per_chunk)]
        chunks = [data[a * block.group_size:b * block.group_size] for a, b in spans]
        if fill is None:
            buffer.set_time(log_time, count)
            packed = [self._workers.submit(self._pack, records) for records in chunks]
        else:
            def fill_and_pack():
                fill(buffer)
                buffer.set_time(log_time, count)
                return [self._pack(records) for records in chunks]
            together = self._workers.submit(fill_and_pack)
            packed = [_Part(together, i) for i in range(len(chunks))]
        job = None
        for (start, stop), records, part in zip(spans, chunks, packed):
            times = log_time[start:stop]
            for channel in block.channels:
                self._counts[channel] += stop - start
            job = self._queue_write(part, len(records), (block, stop - start, times),
                                    int(times[0]), int(times[-1]))
        if job is not None:
            block.hand_over(job)

    def close(self):
        """Write the last chunk, the summary and the footer; close the file."""
        if self._closed:
            return
        self._flush_pending()
        self._wait_for_io()
        self._io.shutdown()
        self._workers.shutdown()
        # rosbag2's record again, complete: rosbag2 reads the last one (ros2 bag info).
        self._emit_metadata([Metadata(name=RECORD, metadata=record_values(self.bag_metadata()))])
        self._emit(DataEnd(data_section_crc=0))
        summary_start = self._position
        summary, offsets = RecordBuilder(), []
        groups = ((Opcode.SCHEMA, self._schemas.values()),
                  (Opcode.CHANNEL, self._channels.values()),
                  (Opcode.STATISTICS, [self._statistics()]),
                  (Opcode.METADATA_INDEX, self._metadata_indexes),
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
        self._write_all([summary.end()])
        self._emit(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                          summary_crc=0))
        self._write_all([MCAP0_MAGIC])
        self._file.close()
        self._closed = True

    def __enter__(self):
        """Use as a context manager: closed (finalised) on exit."""
        return self

    def __exit__(self, *exc):
        """Finalise the file."""
        self.close()

    # -- internals -------------------------------------------------------------------

    def _write_all(self, parts):
        """
        Write ``parts`` (bytes-like) at the end of the file in one system call.

        Returns where they start. Records come from two threads (framing from
        the caller's, chunks from the I/O thread): each goes out whole.
        """
        views = [memoryview(p).cast('B') for p in parts]
        total = sum(len(v) for v in views)
        with self._file_lock:
            start = self._position
            left = total - os.writev(self._fd, views)
            while left:                   # a short write (rare for files): the rest
                done = sum(len(v) for v in views) - left
                while done >= len(views[0]):
                    done -= len(views.pop(0))
                views[0] = views[0][done:]
                left -= os.writev(self._fd, views)
            self._position += total
        return start

    def _let_go(self, start, length):
        """
        Start writing a chunk out to disk; drop the page cache of one written CACHED chunks ago.

        A bag is written once: its pages need not stay cached, and on virtual
        machines whose freed memory goes back to the host, new page-cache pages
        cost more than compressing the data. Pages not yet written out stay
        cached (nothing waits for the disk).
        """
        if not hasattr(os, 'posix_fadvise'):
            return
        os.posix_fadvise(self._fd, start, length, os.POSIX_FADV_DONTNEED)   # write-out starts
        self._written.append((start, length))
        if len(self._written) > CACHED:
            start, length = self._written.popleft()
            os.posix_fadvise(self._fd, start, length, os.POSIX_FADV_DONTNEED)   # clean: dropped

    def _emit(self, record):
        """Write one framing record; return where it starts."""
        builder = RecordBuilder()
        record.write(builder)
        return self._write_all([builder.end()])

    def _emit_metadata(self, records):
        """Write Metadata records in one system call (a kill keeps all or none); index them."""
        built = []
        for record in records:
            builder = RecordBuilder()
            record.write(builder)
            built.append(builder.end())
        start = self._write_all(built)
        for record, raw in zip(records, built):
            self._metadata_indexes.append(MetadataIndex(offset=start, length=len(raw),
                                                        name=record.name))
            start += len(raw)

    def _flush_pending(self):
        if not self._pending:
            return
        index = {channel: (np.array([t for t, _ in entries], dtype=np.uint64),
                           np.array([o for _, o in entries], dtype=np.uint64))
                 for channel, entries in self._pending_index.items()}
        self._submit(self._pending, index, *self._pending_times)
        self._pending = bytearray()
        self._pending_index = defaultdict(list)
        self._pending_times = [None, None]

    def _submit(self, records, index, start_time, end_time):
        """Compress a chunk on a worker thread; write it, in order, on the I/O thread."""
        return self._queue_write(self._workers.submit(self._pack, records), len(records),
                                 index, start_time, end_time)

    def _queue_write(self, packed, size, index, start_time, end_time):
        """Write a chunk (``packed``: its future (data, CRC)) on the I/O thread, in order."""
        job = self._io.submit(self._write_chunk, packed, size, index, start_time, end_time)
        self._io_jobs.append(job)
        while len(self._io_jobs) > 32:          # bound the memory held by chunks in flight
            self._io_jobs.popleft().result()
        return job

    def _pack(self, records):
        crc = crc32(records)
        return (records if self._compress is None else self._compress(records)), crc

    def _wait_for_io(self):
        while self._io_jobs:
            self._io_jobs.popleft().result()

    def _index_records(self, index):
        """Message Index records of a chunk: (bytes, {channel: offset within them})."""
        if isinstance(index, dict):             # from write(): per channel times, offsets
            parts, where, position = [], {}, 0
            for channel, (times, offsets) in index.items():
                body = np.empty(len(times), dtype=[('t', '<u8'), ('o', '<u8')])
                body['t'], body['o'] = times, offsets
                header = np.array([(Opcode.MESSAGE_INDEX, 6 + body.nbytes, channel,
                                    body.nbytes)], dtype=_INDEX_HEADER)
                where[channel] = position
                parts += [header.tobytes(), body.tobytes()]
                position += INDEX_HEADER + body.nbytes
            return b''.join(parts), where
        block, count, times = index             # from write_block: one time per sample
        key = (id(block), count)
        if key not in self._index_templates:
            size = INDEX_HEADER + 16 * count
            template = np.zeros(size * len(block.channels), np.uint8)
            where = {}
            for i, (channel, offsets) in enumerate(block.record_offsets_for(count).items()):
                template[i * size:i * size + INDEX_HEADER].view(_INDEX_HEADER)[0] = (
                    Opcode.MESSAGE_INDEX, 6 + 16 * count, channel, 16 * count)
                template[i * size + INDEX_HEADER:(i + 1) * size].view('<u8')[1::2] = offsets
                where[channel] = i * size
            self._index_templates[key] = (block, template, where)   # block: keeps id unique
        _, template, where = self._index_templates[key]
        records = template.copy()
        np.ndarray((len(where), count), '<u8', records, INDEX_HEADER,
                   (INDEX_HEADER + 16 * count, 16))[...] = times
        return records, where

    def _write_chunk(self, packed, size, index, start_time, end_time):
        data, crc = packed.result()
        compression = self._compression.encode()
        header = struct.pack(f'<BQQQQII{len(compression)}sQ', Opcode.CHUNK,
                             8 + 8 + 8 + 4 + 4 + len(compression) + 8 + len(data), start_time,
                             end_time, size, crc, len(compression), compression, len(data))
        index_records, where = self._index_records(index)
        # Chunk and message indexes in one system call: a finished chunk survives a kill.
        chunk_start = self._write_all([header, data, index_records])
        chunk_length = len(header) + len(data)
        self._let_go(chunk_start, chunk_length + len(index_records))
        index_start = chunk_start + chunk_length
        self._chunk_count += 1
        _extend(self._times, start_time, end_time)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time,
            chunk_start_offset=chunk_start, chunk_length=chunk_length,
            message_index_offsets={channel: index_start + offset
                                   for channel, offset in where.items()},
            message_index_length=len(index_records), compression=self._compression,
            compressed_size=len(data), uncompressed_size=size))

    def _statistics(self):
        start, end = self._times
        return Statistics(message_count=sum(self._counts.values()),
                          schema_count=len(self._schemas), channel_count=len(self._channels),
                          attachment_count=0, metadata_count=len(self._metadata_indexes),
                          chunk_count=self._chunk_count,
                          message_start_time=start or 0, message_end_time=end or 0,
                          channel_message_counts=dict(self._counts))


class _Part:
    """Chunk ``i`` of a job that packs several: ``result()`` is its (data, CRC)."""

    def __init__(self, job, i):
        self.job, self.i = job, i

    def result(self):
        """Return (data, CRC) of the chunk, waiting for the job."""
        return self.job.result()[self.i]


class TopicWritten(NamedTuple):
    """A channel of a written bag: topic, type, messages written, offered QoS."""

    topic: str
    msg_type: str
    count: int
    latched: bool
    best_effort: bool


def _remove_old(path):
    """
    Remove an existing regular file at ``path`` (one link, not a symlink) before writing.

    Replaced, not truncated: ext4 writes a truncated and rewritten file out to disk
    when it is closed (auto_da_alloc), a tenth of a second for a replay's output.
    """
    try:
        status = os.lstat(path)
    except OSError:
        return
    if stat.S_ISREG(status.st_mode) and status.st_nlink == 1:
        os.unlink(path)


def _extend(span, start, end):
    span[0] = start if span[0] is None else min(span[0], start)
    span[1] = end if span[1] is None else max(span[1], end)
