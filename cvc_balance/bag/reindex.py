"""
``cvc-balance reindex BAG``: give a killed recording back its summary, as ``ros2 bag reindex``.

A recording killed by SIGKILL or a power cut ends inside a chunk, with no summary and no
footer: this project's reader reads it up to its last whole chunk (replay does that on the
fly), but rosbags and the ``mcap`` library's indexed reader read nothing. Reindexing keeps
the file's bytes up to the end of its last whole chunk (with that chunk's message indexes;
a chunk whose CRC fails is kept too and reported), drops the torn record after it, and
appends what a finished file ends with: DataEnd, the summary (schemas and channels,
statistics, a chunk index per chunk, summary offsets) and the footer. A rosbag2 directory
has each of its MCAP files reindexed and its ``metadata.yaml`` written again (from the
files: topics, types, offered QoS, counts, times). The result is written under a temporary
name and moved onto the original (or onto ``-o``) only when complete.
"""

from collections import Counter
from dataclasses import dataclass, field
import mmap
import os
from pathlib import Path
import struct

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, DataEnd, Footer, MessageIndex, Statistics, SummaryOffset
from mcap.writer import MCAP0_MAGIC
import yaml

from cvc_balance.bag.mcap_reader import BagError, crc32
from cvc_balance.bag.mcap_writer import TopicWritten
from cvc_balance.bag.rosbag2 import METADATA, metadata_yaml
from cvc_balance.files import replaced_when_done

_RECORD = struct.Struct('<BQ')
_STRING = struct.Struct('<I')


@dataclass
class Reindexed:
    """What reindexing a file found and wrote."""

    path: str
    kept_bytes: int = 0
    dropped_bytes: int = 0
    chunks: int = 0
    messages: int = 0
    problems: list = field(default_factory=list)
    already_whole: bool = False
    topics: list = field(default_factory=list)     # [TopicWritten]
    times: tuple = (None, None)


def reindex(path, output=None):
    """
    Reindex the bag at ``path`` (a .mcap file or rosbag2 directory); return [Reindexed].

    ``output``: where to write the result (default: over ``path``, once complete).
    """
    path = Path(path)
    if path.is_dir():
        return _reindex_directory(path, Path(output) if output else None)
    if output is not None and Path(output).is_dir():
        raise BagError(f'{output}: is a directory; reindex a .mcap file into a .mcap file')
    with replaced_when_done(output or path) as temporary:
        report = _reindex_file(path, temporary)
        if report.already_whole and output is None:
            temporary.unlink()          # nothing to change: the original stays untouched
    return [report]


def _reindex_directory(directory, output):
    files = sorted(directory.glob('*.mcap'))
    if not files:
        raise BagError(f'{directory}: no .mcap files to reindex (sqlite3 bags: use ros2 bag '
                       'reindex)')
    with replaced_when_done(output or directory) as staging:
        staging.mkdir()
        reports = [_reindex_file(f, staging / f.name) for f in files]
        if len(files) == 1:
            report = reports[0]
            text = metadata_yaml(files[0].name, report.topics, *report.times)
            (staging / METADATA).write_text(text, encoding='utf-8')
        else:           # several files: keep their listing, counts from the files
            (staging / METADATA).write_text(_merged_metadata(directory, reports),
                                            encoding='utf-8')
    return reports


def _merged_metadata(directory, reports):
    """metadata.yaml for several files: the first file's layout, every file listed."""
    texts = [yaml.safe_load(metadata_yaml(Path(r.path).name, r.topics, *r.times))
             ['rosbag2_bagfile_information'] for r in reports]
    info = dict(texts[0])
    counts = Counter()
    for text in texts:
        for entry in text['topics_with_message_count']:
            counts[entry['topic_metadata']['name']] += entry['message_count']
    seen = {}
    for text in texts:
        for entry in text['topics_with_message_count']:
            seen.setdefault(entry['topic_metadata']['name'], entry)
    info['topics_with_message_count'] = [dict(e, message_count=counts[name])
                                         for name, e in seen.items()]
    info['relative_file_paths'] = [Path(r.path).name for r in reports]
    info['files'] = [f for text in texts for f in text['files']]
    info['message_count'] = sum(counts.values())
    starts = [t['starting_time']['nanoseconds_since_epoch'] for t in texts if t['message_count']]
    ends = [t['starting_time']['nanoseconds_since_epoch'] + t['duration']['nanoseconds']
            for t in texts if t['message_count']]
    if starts:
        info['starting_time'] = {'nanoseconds_since_epoch': min(starts)}
        info['duration'] = {'nanoseconds': max(ends) - min(starts)}
    return yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False)


def _reindex_file(path, target):
    report = Reindexed(str(path))
    try:
        with open(path, 'rb') as stream:
            size = os.fstat(stream.fileno()).st_size
            data = mmap.mmap(stream.fileno(), size, access=mmap.ACCESS_READ) if size else b''
    except OSError as error:
        raise BagError(f'{path}: cannot read bag: {error.strerror}') from None
    if data[:8] != MCAP0_MAGIC:
        raise BagError(f'{path}: not an MCAP file (no MCAP magic at the start)')
    walk = _Walk(data, report)
    walk.run()
    if walk.footer_found:
        report.already_whole = True
    with open(target, 'wb') as out:
        out.write(memoryview(data)[:walk.good_end])
        out.write(walk.rebuilt_indexes)
        out.write(_summary(walk, walk.good_end + len(walk.rebuilt_indexes)))
    report.kept_bytes = walk.good_end
    report.dropped_bytes = size - walk.good_end
    report.chunks = len(walk.chunks)
    report.messages = sum(walk.counts.values())
    report.topics = walk.topics()
    first = [c.start_time for c in walk.chunks] + walk.loose_times
    last = [c.end_time for c in walk.chunks] + walk.loose_times
    report.times = (min(first), max(last)) if first else (None, None)
    return report


class _Walk:
    """The top-level records of a (perhaps torn) MCAP file, up to the last whole unit."""

    def __init__(self, data, report):
        self.data, self.report = data, report
        self.schemas, self.channels = {}, {}     # id -> raw record bytes (opcode included)
        self.schema_names, self.channel_info = {}, {}
        self.chunks, self.counts, self.loose_times = [], Counter(), []
        self.good_end, self.footer_found = len(MCAP0_MAGIC), False
        self.torn_indexes = None      # the last chunk, when the file ends in its indexes
        self.rebuilt_indexes = b''    # its message index records, made from its records

    def run(self):
        data, position, size = self.data, len(MCAP0_MAGIC), len(self.data)
        chunk = None
        while position + 9 <= size:
            opcode, length = _RECORD.unpack_from(data, position)
            end = position + 9 + length
            if end > size:
                self.report.problems.append(f'record (opcode 0x{opcode:02x}) at byte '
                                            f'{position} torn by the end of the file: dropped')
                self.torn_indexes = chunk      # its index group may be partial: rebuilt
                break
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                self.footer_found = opcode == Opcode.FOOTER or self._has_footer(end)
                break
            if opcode != Opcode.MESSAGE_INDEX and chunk is not None:
                if not chunk.indexed:
                    self._count_chunk(chunk)       # no indexes after it: count its records
                chunk = None                       # later indexes belong to no chunk
            body = data[position + 9:end]
            if opcode == Opcode.SCHEMA:
                schema_id, = struct.unpack_from('<H', body, 0)
                self.schemas[schema_id] = bytes(data[position:end])
                self.schema_names[schema_id] = _string(body, 2)
            elif opcode == Opcode.CHANNEL:
                channel_id, schema_id = struct.unpack_from('<HH', body, 0)
                topic = _string(body, 4)
                self.channels[channel_id] = bytes(data[position:end])
                self.channel_info[channel_id] = (topic, schema_id, _channel_metadata(body))
            elif opcode == Opcode.CHUNK:
                chunk = self._chunk(position, body, end - position)
                self.chunks.append(chunk)
            elif opcode == Opcode.MESSAGE_INDEX and chunk is not None:
                channel_id, entries = struct.unpack_from('<HI', body, 0)
                chunk.indexes[channel_id] = position - (chunk.offset + chunk.length)
                chunk.index_length = end - (chunk.offset + chunk.length)
                self.counts[channel_id] += entries // 16
                chunk.counted[channel_id] += entries // 16
                chunk.indexed = True
            elif opcode == Opcode.MESSAGE:
                channel_id, _, log_time = struct.unpack_from('<HIQ', body, 0)
                self.counts[channel_id] += 1
                self.loose_times.append(log_time)
            self.good_end = end
            position = end
        else:
            if position < size:
                self.report.problems.append(f'record header at byte {position} torn by the '
                                            'end of the file: dropped')
                self.torn_indexes = chunk
        if self.torn_indexes is None and chunk is not None and not self.footer_found \
                and position >= size:
            self.torn_indexes = chunk      # the file ends in (or right after) its indexes
        if self.torn_indexes is not None:
            self._rebuild_indexes(self.torn_indexes)
        elif chunk is not None and not chunk.indexed:
            self._count_chunk(chunk)

    def _has_footer(self, end):
        return len(self.data) >= end + 9 + 20 + len(MCAP0_MAGIC) and \
            self.data[-len(MCAP0_MAGIC):] == MCAP0_MAGIC

    def _chunk(self, position, body, length):
        start_time, end_time, size, crc = struct.unpack_from('<QQQI', body, 0)
        compression = _string(body, 28)
        at = 32 + len(compression)
        records_length, = struct.unpack_from('<Q', body, at)
        records = body[at + 8:at + 8 + records_length]
        chunk = _Chunk(position, length, start_time, end_time, size, compression,
                       records_length, records, crc)
        return chunk

    def _rebuild_indexes(self, chunk):
        """Replace a chunk's torn index group by message indexes made from its records."""
        self.counts.subtract(chunk.counted)
        self.good_end = chunk.offset + chunk.length
        chunk.indexes, chunk.index_length, chunk.indexed = {}, 0, True
        records = _decompressed(chunk, self.report)
        if records is None:
            return
        entries, position = {}, 0
        while position + 9 <= len(records):
            opcode, length = _RECORD.unpack_from(records, position)
            if opcode == Opcode.MESSAGE:
                channel_id, _, log_time = struct.unpack_from('<HIQ', records, position + 9)
                entries.setdefault(channel_id, []).append((log_time, position))
            position += 9 + length
        builder = RecordBuilder()
        for channel_id, pairs in entries.items():
            chunk.indexes[channel_id] = builder.count
            MessageIndex(channel_id=channel_id, records=pairs).write(builder)
            self.counts[channel_id] += len(pairs)
        self.rebuilt_indexes = builder.end()
        chunk.index_length = len(self.rebuilt_indexes)
        self.report.problems.append(f'message indexes of the last chunk (byte {chunk.offset}) '
                                    'rebuilt from its records')

    def _count_chunk(self, chunk):
        records = _decompressed(chunk, self.report)
        chunk.indexed = True
        if records is None:
            return
        position = 0
        while position + 9 <= len(records):
            opcode, length = _RECORD.unpack_from(records, position)
            if opcode == Opcode.MESSAGE:
                channel_id, = struct.unpack_from('<H', records, position + 9)
                self.counts[channel_id] += 1
            position += 9 + length

    def topics(self):
        """Return [TopicWritten] of the channels, with the messages counted."""
        out = []
        for channel_id, (topic, schema_id, metadata) in self.channel_info.items():
            qos = metadata.get('offered_qos_profiles', '')
            out.append(TopicWritten(topic, self.schema_names.get(schema_id, ''),
                                    self.counts[channel_id], 'durability: 1' in qos,
                                    'reliability: 2' in qos))
        return out


@dataclass
class _Chunk:
    offset: int
    length: int
    start_time: int
    end_time: int
    uncompressed_size: int
    compression: str
    compressed_size: int
    records: memoryview
    crc: int
    indexes: dict = field(default_factory=dict)      # channel -> offset after the chunk
    index_length: int = 0
    indexed: bool = False
    counted: Counter = field(default_factory=Counter)   # messages its indexes list


def _decompressed(chunk, report):
    try:
        if chunk.compression == '':
            records = bytes(chunk.records)
        elif chunk.compression == 'zstd':
            import zstandard
            records = zstandard.ZstdDecompressor().decompress(
                chunk.records, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == 'lz4':
            import lz4.frame
            records = lz4.frame.decompress(chunk.records)
        else:
            raise ValueError(f'unknown compression {chunk.compression!r}')
        if chunk.crc and crc32(records) != chunk.crc:
            raise ValueError('CRC mismatch')
        return records
    except Exception as error:       # any codec's error: kept, reported, not counted
        report.problems.append(f'chunk at byte {chunk.offset} unreadable ({error}): kept '
                               'as it is, its messages not counted')
        return None


def _string(body, at):
    length, = _STRING.unpack_from(body, at)
    return bytes(body[at + 4:at + 4 + length]).decode('utf-8')


def _channel_metadata(body):
    at = 4
    for _ in range(2):                  # topic, message encoding
        at += 4 + _STRING.unpack_from(body, at)[0]
    length, = _STRING.unpack_from(body, at)
    at += 4
    end, metadata = at + length, {}
    while at < end:
        key = _string(body, at)
        at += 4 + len(key.encode())
        value = _string(body, at)
        at += 4 + len(value.encode())
        metadata[key] = value
    return metadata


def _summary(walk, data_end_at):
    """DataEnd, the summary section, its offsets, the footer and the closing magic."""
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    summary_start = data_end_at + builder.count
    groups = []
    start = builder.count
    for raw in walk.schemas.values():
        builder.write(raw)
    groups.append((Opcode.SCHEMA, start))
    start = builder.count
    for raw in walk.channels.values():
        builder.write(raw)
    groups.append((Opcode.CHANNEL, start))
    start = builder.count
    times = [c.start_time for c in walk.chunks] + walk.loose_times
    ends = [c.end_time for c in walk.chunks] + walk.loose_times
    Statistics(message_count=sum(walk.counts.values()), schema_count=len(walk.schemas),
               channel_count=len(walk.channels), attachment_count=0, metadata_count=0,
               chunk_count=len(walk.chunks), message_start_time=min(times, default=0),
               message_end_time=max(ends, default=0),
               channel_message_counts=dict(walk.counts)).write(builder)
    groups.append((Opcode.STATISTICS, start))
    start = builder.count
    for chunk in walk.chunks:
        ChunkIndex(message_start_time=chunk.start_time, message_end_time=chunk.end_time,
                   chunk_start_offset=chunk.offset, chunk_length=chunk.length,
                   message_index_offsets={channel: chunk.offset + chunk.length + offset
                                          for channel, offset in chunk.indexes.items()},
                   message_index_length=chunk.index_length, compression=chunk.compression,
                   compressed_size=chunk.compressed_size,
                   uncompressed_size=chunk.uncompressed_size).write(builder)
    groups.append((Opcode.CHUNK_INDEX, start))
    ends = [start for _, start in groups[1:]] + [builder.count]
    offsets_start = data_end_at + builder.count
    for (opcode, group_start), group_end in zip(groups, ends):
        if group_end > group_start:
            SummaryOffset(group_opcode=opcode, group_start=data_end_at + group_start,
                          group_length=group_end - group_start).write(builder)
    Footer(summary_start=summary_start, summary_offset_start=offsets_start,
           summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC
