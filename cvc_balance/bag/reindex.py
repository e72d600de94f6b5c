"""
``cvc-balance reindex BAG``: a damaged or killed recording mended, never at the cost of a message.

A recording killed by SIGKILL or a power cut ends inside a chunk, with no summary and no
footer: rosbags and the ``mcap`` library's indexed reader then read nothing. A byte
flipped in a record's length field stops a reader that walks the file. Reindexing reads
the bag with this project's reader (:class:`~cvc_balance.bag.mcap_reader.Bag`: every
chunk whose CRC holds, past damaged records) and writes a new file of what it read: the
header, every Metadata record, the schemas and channels, each readable chunk as it was
compressed (its message indexes made from its records), messages found outside chunks
gathered into chunks of their own, attachments; then DataEnd, the summary (schemas,
channels, statistics, metadata, attachment and chunk indexes, summary offsets) and the
footer. A chunk that fails its CRC or does not decompress is not copied (said).

Nothing is lost: the result goes beside the bag (``run.mcap`` -> ``run.reindexed.mcap``,
a rosbag2 directory ``run`` -> ``run.reindexed``; a name not taken), or to ``-o``, or
over the bag only with ``in_place``; and it is refused, the bag left as it is, when a
standard reader (the ``mcap`` library's indexed reader with CRCs checked, rosbags) reads
more messages of a topic from the original than the result keeps, or when the result
read back by those readers does not give what was written. A bag that is already
whole (no damage, a complete summary) is not written again.

A rosbag2 directory has each of its MCAP files reindexed and its ``metadata.yaml`` made
again (from the files: topics, types, offered QoS, counts, times), keeping the old one's
``custom_data`` (else that of the files' ``cvc_balance`` Metadata record).
"""

from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass, field
import io
from pathlib import Path
import struct

from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (AttachmentIndex, Channel, ChunkIndex, DataEnd, Footer, Header,
                          MessageIndex, MetadataIndex, Statistics, SummaryOffset)
from mcap.writer import MCAP0_MAGIC
import numpy as np

from cvc_balance.bag.mcap_reader import (Bag, BagError, column, crc32, MESSAGE_HEADER,
                                         OP_CHANNEL, OP_MESSAGE, OP_SCHEMA, record_table)
from cvc_balance.bag.mcap_writer import _compressor, TopicWritten
from cvc_balance.bag.rosbag2 import MAX_METADATA_BYTES, METADATA
from cvc_balance.bag.rosbag2_metadata import (bag_metadata, CUSTOM_DATA_RECORD, metadata_yaml,
                                              offered)
from cvc_balance.files import created_when_done, replaced_when_done
from cvc_balance.physics.documents import read_document

LOOSE_CHUNK = 1 << 20
"""Bytes of messages found outside chunks gathered into one (uncompressed) chunk."""
SUFFIX = '.reindexed'
"""Put before a file's suffix (or after a directory's name) for the result beside it."""
_LIBRARY = 'cvc_balance reindex'


class RepairRefused(BagError):
    """A repair that would keep fewer messages than a standard reader reads; says which."""


@dataclass
class Reindexed:
    """What reindexing a file found and wrote."""

    path: str
    output: str = ''              # where the result went ('' when nothing was written)
    chunks: int = 0
    messages: int = 0
    dropped_chunks: int = 0
    problems: list = field(default_factory=list)
    already_whole: bool = False
    topics: list = field(default_factory=list)     # [TopicWritten]
    times: tuple = (None, None)
    custom_data: dict = field(default_factory=dict)
    readers: dict = field(default_factory=dict)    # reader -> messages it reads of the original


def beside(path):
    """Return the default output of reindexing ``path``: run.mcap -> run.reindexed.mcap."""
    path = Path(path)
    if path.is_dir():
        return path.with_name(path.name + SUFFIX)
    return path.with_name(path.stem + SUFFIX + path.suffix)


def reindex(path, output=None, in_place=False):
    """
    Reindex the bag at ``path`` (a .mcap file or rosbag2 directory); return [Reindexed].

    The result goes to ``output``, or over ``path`` with ``in_place``, or else beside
    it under a name not taken (:func:`beside`; ``Reindexed.output`` says which). Raises
    :class:`RepairRefused` (the bag untouched, nothing written) when a standard reader
    reads more of the original than the result keeps.
    """
    path = Path(path)
    if path.is_dir():
        return _reindex_directory(path, output, in_place)
    if output is not None and Path(output).is_dir():
        raise BagError(f'{output}: is a directory; reindex a .mcap file into a .mcap file')
    report = Reindexed(str(path))
    bag = Bag(path)
    if _whole(bag):
        report.already_whole = True
        _describe(report, bag)
        return [report]
    with ExitStack() as stack:
        target, place = _target(stack, path, output, in_place)
        _write_repaired(bag, target, report)
        _check(path, target, report)
    report.output = str(place())
    return [report]


def _target(stack, path, output, in_place):
    """Return (temporary path to write, function giving where it went once done)."""
    if in_place or output is not None:
        final = path if in_place else Path(output)
        return stack.enter_context(replaced_when_done(final)), lambda: final
    new = stack.enter_context(created_when_done(beside(path)))
    return new.temporary, lambda: new.path


def _whole(bag):
    """
    Whether ``bag`` (a Bag) needs no reindexing: no damage, a summary indexing it all.

    Every chunk is decompressed and its CRC checked (problems go to ``bag.problems``).
    """
    summary = bag.summary_records
    if not (bag.finished and not bag.problems and summary[Opcode.STATISTICS] == 1 and
            summary[Opcode.CHUNK_INDEX] == len(bag.chunks) and
            summary[Opcode.METADATA_INDEX] == len(bag.metadata) and
            summary[Opcode.ATTACHMENT_INDEX] == len(bag.attachments)):
        return False
    bag.check_chunks()
    return not bag.problems


def _describe(report, bag):
    """Fill ``report`` with the topics and counts of a whole bag (from its chunks' indexes)."""
    counts = Counter()
    for chunk in bag.chunks:
        for channel, offsets in (chunk.indexes or {}).items():
            counts[channel] += len(offsets)
    report.chunks = len(bag.chunks)
    report.messages = sum(counts.values())
    report.topics = _topics(bag, counts)
    report.custom_data = dict(_custom_data(bag))


def _reindex_directory(directory, output, in_place):
    files = sorted(directory.glob('*.mcap'))
    if not files:
        raise BagError(f'{directory}: no .mcap files to reindex (sqlite3 bags: use ros2 bag '
                       'reindex)')
    old_custom = _yaml_custom_data(directory / METADATA)
    bags = [Bag(f) for f in files]
    reports = [Reindexed(str(f)) for f in files]
    if (directory / METADATA).is_file() and all(_whole(b) for b in bags):
        for report, bag in zip(reports, bags):
            report.already_whole = True
            _describe(report, bag)
        return reports
    with ExitStack() as stack:
        if in_place or output is not None:
            final = directory if in_place else Path(output)
            staging = stack.enter_context(replaced_when_done(final))
            place = lambda: final        # noqa: E731
        else:
            new = stack.enter_context(created_when_done(beside(directory)))
            staging, place = new.temporary, lambda: new.path
        staging.mkdir()
        for bag, report, source in zip(bags, reports, files):
            _write_repaired(bag, staging / source.name, report)
            _check(source, staging / source.name, report)
        custom = old_custom or next((r.custom_data for r in reports if r.custom_data), {})
        text = metadata_yaml(_directory_metadata(reports, custom))
        (staging / METADATA).write_text(text, encoding='utf-8')
    where = str(place())
    for report in reports:
        report.output = str(Path(where) / Path(report.path).name)
    return reports


def _yaml_custom_data(path):
    """custom_data of a metadata.yaml ({} if none or unreadable)."""
    try:
        document = read_document(path, MAX_METADATA_BYTES, as_text=True)   # strings
        data = document['rosbag2_bagfile_information'].get('custom_data')
    except Exception:  # absent, unreadable, not rosbag2 metadata: nothing to keep
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def _directory_metadata(reports, custom_data):
    """rosbag2's metadata of a directory's reindexed files: every file listed, topics summed."""
    topics, counts = {}, Counter()
    for report in reports:
        for topic in report.topics:
            topics.setdefault(topic.topic, topic)
            counts[topic.topic] += topic.count
    files = [(Path(r.path).name, *r.times, sum(t.count for t in r.topics)) for r in reports]
    return bag_metadata(files, [t._replace(count=counts[name]) for name, t in topics.items()],
                        custom_data)


def _custom_data(bag):
    """Return the custom data of a bag's ``cvc_balance`` Metadata record ({}: none)."""
    return next((values for _, name, values, _ in bag.metadata if name == CUSTOM_DATA_RECORD),
                {})


def _topics(bag, counts):
    """[TopicWritten] of the bag's channels, with ``counts`` {channel id: messages}."""
    out = []
    for channel in bag.channels.values():
        raw = bag.definitions.get((OP_CHANNEL, channel.id), b'')
        try:
            qos = Channel.read(ReadDataStream(io.BytesIO(raw[9:]))).metadata.get(
                'offered_qos_profiles', '')
        except Exception:   # a damaged channel record: its QoS unknown (reliable, volatile)
            qos = ''
        best_effort, latched = offered(qos)
        out.append(TopicWritten(channel.topic, channel.msg_type, counts[channel.id],
                                latched, best_effort))
    return out


class _Out:
    """The repaired file being written: records appended, their offsets known."""

    def __init__(self, stream):
        self.stream, self.position = stream, 0

    def write(self, *parts):
        start = self.position
        for part in parts:
            self.stream.write(part)
            self.position += len(part)
        return start

    def record(self, record):
        builder = RecordBuilder()
        record.write(builder)
        return self.write(builder.end())


def _write_repaired(bag, target, report):
    """Write what ``bag`` reads, whole and indexed, to ``target``; fill ``report``."""
    data = bag.data
    counts, times = Counter(), [None, None]
    chunk_indexes, metadata_indexes, attachment_indexes = [], [], []
    with open(target, 'xb') as stream:
        out = _Out(stream)
        out.write(MCAP0_MAGIC)
        if bag.header is not None:
            out.write(bag.header)
        else:
            out.record(Header(profile='ros2', library=_LIBRARY))
            report.problems.append('header unreadable: a new one written (profile ros2)')
        for _, name, _, raw in bag.metadata:
            metadata_indexes.append(MetadataIndex(offset=out.write(raw), length=len(raw),
                                                  name=name))
        definitions = [raw for (opcode, _), raw in sorted(bag.definitions.items())]
        for raw in definitions:
            out.write(raw)
        known = set(bag.channels)
        for chunk, records in bag.decoded_chunks():
            if records is None:           # unreadable: said by the reader
                report.dropped_chunks += 1
                continue
            index = _message_index(records, known)
            compressed, crc = chunk.data, chunk.crc
            if index is None:             # its whole records before the damage, repacked
                records, kept, dropped = _salvaged(records, known)
                if not kept:
                    report.dropped_chunks += 1
                    report.problems.append(f'chunk at byte {chunk.offset}: no whole message '
                                           'of a known channel in it: not copied')
                    continue
                report.problems.append(f'chunk at byte {chunk.offset}: {kept} of its messages '
                                       f'copied, {dropped} records damaged or of channels no '
                                       'record defines left out')
                compress = _compressor(chunk.compression)
                compressed = records if compress is None else compress(records)
                crc = crc32(records)
                index = _message_index(records, known)
            chunk_indexes.append(_write_chunk(out, chunk.compression, compressed,
                                              len(records), crc, index, counts, times))
        for records in _loose_chunks(bag, known):
            index = _message_index(records, known)
            chunk_indexes.append(_write_chunk(out, '', records, len(records), 0, index,
                                              counts, times))
        for offset, length in bag.attachments:
            attachment_indexes.append(_attachment_index(out, data[offset:offset + length]))
        out.record(DataEnd(data_section_crc=0))
        summary_start = out.position
        _summary(out, bag, definitions, counts, times, chunk_indexes, metadata_indexes,
                 attachment_indexes, summary_start)
    report.problems = bag.problems + report.problems
    report.chunks = len(chunk_indexes)
    report.messages = sum(counts.values())
    report.topics = _topics(bag, counts)
    report.times = tuple(times)
    report.custom_data = dict(_custom_data(bag))


def _message_index(records, known):
    """
    Return {channel: [(log time, offset)]} of a chunk's messages, or None.

    None when the records do not fill the chunk exactly, or a message names a
    channel no Channel record defines (readers would stop there).
    """
    buffer = np.frombuffer(records, np.uint8)
    offsets, opcodes, lengths, end = record_table(buffer)
    if end != len(buffer):
        return None
    messages = offsets[(opcodes == OP_MESSAGE)]
    if np.any(lengths[opcodes == OP_MESSAGE] < MESSAGE_HEADER - 9):
        return None
    channels = column(buffer, messages + 9, '<u2')
    log_times = column(buffer, messages + 15, '<u8')
    index = {}
    for channel in np.unique(channels).tolist():
        if channel not in known:
            return None
        mine = channels == channel
        index[channel] = list(zip(log_times[mine].tolist(), messages[mine].tolist()))
    return index


def _salvaged(records, known):
    """
    Return (records, messages kept, records left out) of a damaged chunk's records.

    Its whole records up to where one runs past its end, without the messages of
    channels no Channel record defines.
    """
    buffer = np.frombuffer(records, np.uint8)
    offsets, opcodes, lengths, _ = record_table(buffer)
    kept, out = 0, bytearray()
    for offset, opcode, length in zip(offsets.tolist(), opcodes.tolist(), lengths.tolist()):
        if opcode == OP_MESSAGE:
            if length < MESSAGE_HEADER - 9 or \
                    struct.unpack_from('<H', records, offset + 9)[0] not in known:
                continue
            kept += 1
        out += records[offset:offset + 9 + length]
    total = int(np.count_nonzero(opcodes == OP_MESSAGE)) + (len(out) < len(records))
    return bytes(out), kept, total - kept


def _write_chunk(out, compression, data, uncompressed_size, crc, index, counts, times):
    """Write a chunk record and its message indexes; return its ChunkIndex."""
    stamps = [t for entries in index.values() for t, _ in entries]
    start, end = (min(stamps), max(stamps)) if stamps else (0, 0)
    name = compression.encode()
    header = struct.pack(f'<BQQQQII{len(name)}sQ', Opcode.CHUNK,
                         8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(data), start, end,
                         uncompressed_size, crc, len(name), name, len(data))
    chunk_start = out.write(header, data)
    chunk_length = len(header) + len(data)
    offsets = {}
    for channel, entries in index.items():
        offsets[channel] = out.record(MessageIndex(channel_id=channel, records=entries))
        counts[channel] += len(entries)
    if stamps:
        times[0] = start if times[0] is None else min(times[0], start)
        times[1] = end if times[1] is None else max(times[1], end)
    return ChunkIndex(message_start_time=start, message_end_time=end,
                      chunk_start_offset=chunk_start, chunk_length=chunk_length,
                      message_index_offsets=offsets,
                      message_index_length=out.position - chunk_start - chunk_length,
                      compression=compression, compressed_size=len(data),
                      uncompressed_size=uncompressed_size)


def _loose_chunks(bag, known):
    """Yield uncompressed chunk records of the messages found outside chunks (known channels)."""
    data, records = bag.data, bytearray()
    for channel, offset in sorted(bag.loose_messages(), key=lambda pair: pair[1]):
        if channel not in known:
            continue
        length, = struct.unpack_from('<Q', data, offset + 1)
        records += data[offset:offset + 9 + length]
        if len(records) >= LOOSE_CHUNK:
            yield bytes(records)
            records = bytearray()
    if records:
        yield bytes(records)


def _attachment_index(out, raw):
    """Copy an Attachment record; return its AttachmentIndex."""
    log_time, create_time = struct.unpack_from('<QQ', raw, 9)
    at = 25
    name_length, = struct.unpack_from('<I', raw, at)
    name = bytes(raw[at + 4:at + 4 + name_length]).decode('utf-8', 'replace')
    at += 4 + name_length
    media_length, = struct.unpack_from('<I', raw, at)
    media_type = bytes(raw[at + 4:at + 4 + media_length]).decode('utf-8', 'replace')
    at += 4 + media_length
    data_size, = struct.unpack_from('<Q', raw, at)
    return AttachmentIndex(offset=out.write(raw), length=len(raw), log_time=log_time,
                           create_time=create_time, data_size=data_size, name=name,
                           media_type=media_type)


def _summary(out, bag, definitions, counts, times, chunk_indexes, metadata_indexes,
             attachment_indexes, summary_start):
    """Write the summary section, its offsets, the footer and the closing magic."""
    groups = []

    def group(opcode, records):
        start = out.position
        for record in records:
            if isinstance(record, bytes):
                out.write(record)
            else:
                out.record(record)
        if out.position > start:
            groups.append(SummaryOffset(group_opcode=opcode, group_start=start,
                                        group_length=out.position - start))
    schemas = [raw for raw in definitions if raw[0] == OP_SCHEMA]
    channels = [raw for raw in definitions if raw[0] == OP_CHANNEL]
    group(Opcode.SCHEMA, schemas)
    group(Opcode.CHANNEL, channels)
    group(Opcode.STATISTICS, [Statistics(
        message_count=sum(counts.values()), schema_count=len(schemas),
        channel_count=len(channels), attachment_count=len(attachment_indexes),
        metadata_count=len(metadata_indexes), chunk_count=len(chunk_indexes),
        message_start_time=times[0] or 0, message_end_time=times[1] or 0,
        channel_message_counts=dict(counts))])
    group(Opcode.METADATA_INDEX, metadata_indexes)
    group(Opcode.ATTACHMENT_INDEX, attachment_indexes)
    group(Opcode.CHUNK_INDEX, chunk_indexes)
    offsets_start = out.position
    for offset in groups:
        out.record(offset)
    out.record(Footer(summary_start=summary_start, summary_offset_start=offsets_start,
                      summary_crc=0))
    out.write(MCAP0_MAGIC)


def standard_counts(path):
    """
    Return {reader: Counter(topic: messages)} that standard readers read of an MCAP file.

    The ``mcap`` library's reader (its summary's indexes where there is one, else the
    file in order) with CRCs checked, and rosbags. What a reader read before it stopped
    counts (a damaged file stops them part way).
    """
    from mcap.reader import make_reader
    counts = {'the mcap library (CRCs checked)': Counter(), 'rosbags': Counter()}
    mcap = counts['the mcap library (CRCs checked)']
    try:
        with open(path, 'rb') as stream:
            reader = make_reader(stream, validate_crcs=True)
            for _, channel, _ in reader.iter_messages(log_time_order=False):
                mcap[channel.topic] += 1
    except Exception:  # the library's many errors on damaged files: what it read counts
        pass
    mine = counts['rosbags']
    try:
        from rosbags.highlevel import AnyReader
        with AnyReader([Path(path)]) as reader:
            for connection, _, _ in reader.messages():
                mine[connection.topic] += 1
    except Exception:  # as above, rosbags' errors
        pass
    return counts


def _check(original, repaired, report):
    """Refuse a repair that keeps less than a standard reader reads, or reads back wrong."""
    kept = Counter()
    for topic in report.topics:
        kept[topic.topic] += topic.count
    readers = standard_counts(original)
    report.readers = {name: sum(c.values()) for name, c in readers.items()}
    for name, counted in readers.items():
        short = {topic: (n, kept[topic]) for topic, n in counted.items() if n > kept[topic]}
        if short:
            worst = ', '.join(f'{t} {n} against {k}' for t, (n, k) in sorted(short.items())[:3])
            raise RepairRefused(
                f'{original}: not reindexed: {name} reads {sum(counted.values())} messages of '
                f'it, the repair would keep {report.messages} ({worst}); the bag is left as '
                'it is (read it with that reader, or copy what it reads)')
    for name, back in standard_counts(repaired).items():
        if back != +kept:
            raise BagError(f'{original}: not reindexed: {name} reads {sum(back.values())} '
                           f'messages of the repaired file, {report.messages} written (a bug: '
                           'please report it); the bag is left as it is')
