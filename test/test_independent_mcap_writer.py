"""
The MCAP writer against the specification's byte layout and against other libraries.

Every file written here is taken apart by hand, record by record as the MCAP specification
lays them out (opcode, uint64 length, body; little-endian fields), and read by the ``mcap``
library (CRCs validated), rosbags (messages decoded) and ``zstandard`` / ``lz4`` (a chunk's
bytes are those libraries' compression of its records). Small bags, in process: each test
takes milliseconds.
"""

import io
import os
import struct
import zlib

from mcap.reader import make_reader
from mcap.records import (Chunk, ChunkIndex, Footer, MessageIndex, MetadataIndex,
                          Statistics)
from mcap.stream_reader import breakup_chunk, StreamReader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.mcap_reader import BagError
from cvc_balance.bag.mcap_writer import BagWriter, MessageBlock
from cvc_balance.messages.cdr import joint_state_layout, string_message, wrench_stamped_layout

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
WRENCH, STRING = 'geometry_msgs/msg/WrenchStamped', 'std_msgs/msg/String'
MAGIC = b'\x89MCAP0\r\n'
# The specification's opcodes.
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = range(1, 9)
STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 0x0B, 0x0C, 0x0D, 0x0E, 0x0F


def records_by_hand(data):
    """Return [(offset, opcode, body)] of a whole file's top-level records, by the spec."""
    assert data[:8] == MAGIC and data[-8:] == MAGIC
    out, position = [], 8
    while position < len(data) - 8:
        opcode, length = struct.unpack_from('<BQ', data, position)
        out.append((position, opcode, data[position + 9:position + 9 + length]))
        position += 9 + length
    assert position == len(data) - 8
    return out


def chunk_by_hand(body):
    """Return (start, end, uncompressed size, crc, compression, records) of a Chunk body."""
    start, end, size, crc, name_length = struct.unpack_from('<QQQII', body)
    compression = body[32:32 + name_length].decode()
    records_length, = struct.unpack_from('<Q', body, 32 + name_length)
    records = body[40 + name_length:]
    assert len(records) == records_length
    return start, end, size, crc, compression, records


def message_record(channel, log_time, data):
    """Return a Message record by hand: sequence 0, publish time = log time."""
    return struct.pack('<BQHIQQ', MESSAGE, 22 + len(data), channel, 0, log_time, log_time) + data


def index_record(channel, entries):
    """Return a Message Index record by hand: [(log time, offset in the chunk's records)]."""
    body = b''.join(struct.pack('<QQ', t, o) for t, o in entries)
    return struct.pack('<BQHI', MESSAGE_INDEX, 6 + len(body), channel, len(body)) + body


def parsed(data):
    """Every top-level record as the mcap library parses it (CRCs validated)."""
    return list(StreamReader(io.BytesIO(data), emit_chunks=True, validate_crcs=True).records)


def wrench_values(data):
    """(sec, nanosec, frame, force xyz, torque xyz) of a WrenchStamped's CDR, by rosbags."""
    m = TYPESTORE.deserialize_cdr(data, WRENCH)
    w = m.wrench
    return (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id,
            (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z))


def test_a_chunk_of_loose_messages_is_the_specifications_bytes(tmp_path):
    """
    Uncompressed messages by write(): the chunk and its indexes, byte for byte by hand.

    Four messages on three channels, log times out of order (the chunk spans their
    minimum to their maximum); the chunk's CRC is zlib's of its records; each channel's
    Message Index lists its messages' log times and offsets in write order, and the chunk
    index points at each.
    """
    path = tmp_path / 'loose.mcap'
    notes = [string_message('first'), string_message('second, longer'), string_message(''),
             string_message('fourth')]
    with BagWriter(path, compression='') as writer:
        a = writer.add_channel('/a', STRING)
        b = writer.add_channel('/b', STRING, latched=True)
        c = writer.add_channel('/c', STRING)
        writer.write(a, 5_000, notes[0])
        writer.write(b, 3_000, notes[1])
        writer.write(a, 9_000, notes[2])
        writer.write(c, 4_000, notes[3])
    data = path.read_bytes()
    records = records_by_hand(data)
    opcodes = [op for _, op, _ in records]
    assert opcodes == [HEADER, METADATA, SCHEMA] + [CHANNEL] * 3 + [CHUNK] + \
        [MESSAGE_INDEX] * 3 + [METADATA, DATA_END, SCHEMA] + [CHANNEL] * 3 + \
        [STATISTICS, METADATA_INDEX, METADATA_INDEX, CHUNK_INDEX] + [SUMMARY_OFFSET] * 5 + \
        [FOOTER]
    first = message_record(a, 5_000, notes[0])
    second = message_record(b, 3_000, notes[1])
    third = message_record(a, 9_000, notes[2])
    fourth = message_record(c, 4_000, notes[3])
    inner = first + second + third + fourth
    (chunk_at, _, chunk), (_, _, index_a), (_, _, index_b), (_, _, index_c) = records[6:10]
    assert chunk_by_hand(chunk) == (3_000, 9_000, len(inner), zlib.crc32(inner), '', inner)
    assert index_a == index_record(a, [(5_000, 0), (9_000, len(first) + len(second))])[9:]
    assert index_b == index_record(b, [(3_000, len(first))])[9:]
    assert index_c == index_record(c, [(4_000, len(inner) - len(fourth))])[9:]
    # The header and the data end, by hand.
    assert records[0][2] == struct.pack('<I', 4) + b'ros2' + struct.pack('<I', 11) + \
        b'cvc_balance'
    assert records[11][2] == struct.pack('<I', 0)
    # The chunk index points at the chunk and at each channel's message index.
    index, = [r for r in parsed(data) if isinstance(r, ChunkIndex)]
    assert (index.message_start_time, index.message_end_time) == (3_000, 9_000)
    assert index.chunk_start_offset == chunk_at
    assert index.chunk_length == 9 + len(chunk)
    assert index.message_index_offsets == {a: records[7][0], b: records[8][0],
                                           c: records[9][0]}
    assert index.message_index_length == records[10][0] - records[7][0]
    assert (index.compression, index.compressed_size, index.uncompressed_size) == \
        ('', len(inner), len(inner))


def indexed_messages(data):
    """
    Check every chunk's message indexes by hand; return how many entries they hold.

    Each entry must point at a Message record of its channel and log time in the
    chunk's records (decompressed by the mcap library), its offset counted by the spec.
    """
    records, checked = parsed(data), 0
    for k, record in enumerate(records):
        if not isinstance(record, Chunk):
            continue
        at, position = {}, 0
        for inner in breakup_chunk(record, validate_crc=True):
            at[position] = inner
            position += 9 + 22 + len(inner.data)
        for index in records[k + 1:]:
            if not isinstance(index, MessageIndex):
                break
            for log_time, offset in index.records:
                assert (at[offset].channel_id, at[offset].log_time) == \
                    (index.channel_id, log_time)
                checked += 1
    return checked


def test_blocks_of_the_same_size_over_other_channels_keep_their_own_indexes(tmp_path):
    """Two blocks of two channels, in either order, written 2 samples at a time."""
    path = tmp_path / 'two_blocks.mcap'
    layout = wrench_stamped_layout('s')
    with BagWriter(path, compression='') as writer:
        a, b = writer.add_channel('/a', WRENCH), writer.add_channel('/b', WRENCH)
        ab = MessageBlock([(a, layout), (b, layout)], 2)
        ba = MessageBlock([(b, layout), (a, layout)], 2)
        for k in range(3):
            writer.write_block(ab, [10 * k, 10 * k + 1])
            writer.write_block(ba, [10 * k + 5, 10 * k + 6])
    assert indexed_messages(path.read_bytes()) == 24


def test_the_summary_and_footer_point_where_the_spec_says(tmp_path):
    """
    Summary offsets name each group's records; the footer the summary and its offsets.

    Two schemas, three channels, metadata with custom data, chunks of write() and of
    write_block(): each Summary Offset's group is exactly the records of its opcode, in
    the summary; each Metadata Index the offset and whole length of its record; the
    statistics count what was written.
    """
    path = tmp_path / 'summary.mcap'
    with BagWriter(path, compression='zstd', chunk_bytes=600,
                   custom_data={'machine_id': 'g-7', 'rotor': 3}) as writer:
        note = writer.add_channel('/note', STRING, latched=True)
        w1, w2 = writer.add_channel('/w1', WRENCH), writer.add_channel('/w2', WRENCH)
        for k in range(7):
            writer.write(note, 1_000 + k, string_message(f'note {k}'))
        block = MessageBlock([(w1, wrench_stamped_layout('a')), (w2, wrench_stamped_layout('b'))],
                             5)
        writer.write_block(block, np.arange(5, dtype=np.uint64) * 10 + 2_000)
    data = path.read_bytes()
    records = records_by_hand(data)
    footer_at, footer_op, footer = records[-1]
    assert footer_op == FOOTER
    summary_start, offsets_start, crc = struct.unpack('<QQI', footer)
    assert crc == 0
    starts = [offset for offset, _, _ in records]
    data_end = starts[[op for _, op, _ in records].index(DATA_END)]
    assert summary_start == data_end + 9 + 4
    summary = [r for r in records if summary_start <= r[0] < footer_at]
    assert [op for _, op, _ in summary if op != SUMMARY_OFFSET][:7] == \
        [SCHEMA, SCHEMA, CHANNEL, CHANNEL, CHANNEL, STATISTICS, METADATA_INDEX]
    offsets = [r for r in summary if r[1] == SUMMARY_OFFSET]
    assert offsets_start == offsets[0][0] and len(offsets) == 5
    groups = {}
    for _, _, body in offsets:
        opcode, start, length = struct.unpack('<BQQ', body)
        inside = [op for at, op, _ in summary if start <= at < start + length]
        assert inside and set(inside) == {opcode}
        assert [op for _, op, _ in summary].count(opcode) == len(inside)
        assert start + length in starts           # the group ends where a record starts
        groups[opcode] = len(inside)
    assert groups == {SCHEMA: 2, CHANNEL: 3, STATISTICS: 1, METADATA_INDEX: 3,
                      CHUNK_INDEX: [op for _, op, _ in records].count(CHUNK)}
    by_offset = {offset: (op, body) for offset, op, body in records}
    names = []
    for record in parsed(data):
        if isinstance(record, MetadataIndex):
            op, body = by_offset[record.offset]
            assert op == METADATA and record.length == 9 + len(body)
            name_length, = struct.unpack_from('<I', body)
            assert body[4:4 + name_length].decode() == record.name
            names.append(record.name)
        if isinstance(record, Statistics):
            assert (record.message_count, record.schema_count, record.channel_count,
                    record.attachment_count, record.metadata_count) == (17, 2, 3, 0, 3)
            assert record.channel_message_counts == {note: 7, w1: 5, w2: 5}
            assert (record.message_start_time, record.message_end_time) == (1_000, 2_040)
            assert record.chunk_count == [op for _, op, _ in records].count(CHUNK) >= 3
        if isinstance(record, Footer):
            assert (record.summary_start, record.summary_offset_start) == \
                (summary_start, offsets_start)
    assert names == ['rosbag2', 'cvc_balance', 'rosbag2']
    assert indexed_messages(data) == 17


def test_metadata_records_say_what_the_file_holds(tmp_path):
    """
    rosbag2's records when the file is opened and closed, and the custom data's.

    Read by the mcap library through the metadata indexes; the YAML by PyYAML. The file's
    name is the one given; custom values are written as strings.
    """
    path = tmp_path / 'meta.mcap'
    with BagWriter(path, custom_data={'machine_id': 'g-7', 'rotor': 3},
                   file_name='run_0.mcap') as writer:
        note = writer.add_channel('/note', STRING, latched=True)
        w = writer.add_channel('/w', WRENCH, best_effort=True)
        writer.write(note, 7_000_000_000, string_message('x'))
        writer.write(note, 6_000_000_000, string_message('y'))
        writer.write(w, 6_500_000_000, bytes(84))
        assert writer.file_name == 'run_0.mcap'
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        records = [(m.name, m.metadata) for m in reader.iter_metadata()]
        channels = reader.get_summary().channels
    assert [name for name, _ in records] == ['rosbag2', 'cvc_balance', 'rosbag2']
    assert records[1][1] == {'machine_id': 'g-7', 'rotor': '3'}
    opened, closed = (yaml.safe_load(values['serialized_metadata'])
                      for name, values in records if name == 'rosbag2')
    assert opened['message_count'] == 0 and opened['relative_file_paths'] == ['run_0.mcap']
    # (a YAML plain 3, as rosbag2's emitter writes the string '3')
    assert opened['custom_data'] == closed['custom_data'] == {'machine_id': 'g-7', 'rotor': 3}
    assert closed['message_count'] == 3
    assert closed['starting_time'] == {'nanoseconds_since_epoch': 6_000_000_000}
    assert closed['duration'] == {'nanoseconds': 1_000_000_000}
    assert closed['files'] == [{'path': 'run_0.mcap',
                                'starting_time': {'nanoseconds_since_epoch': 6_000_000_000},
                                'duration': {'nanoseconds': 1_000_000_000},
                                'message_count': 3}]
    topics = {t['topic_metadata']['name']: (t['topic_metadata']['type'], t['message_count'])
              for t in closed['topics_with_message_count']}
    assert topics == {'/note': (STRING, 2), '/w': (WRENCH, 1)}
    qos = {c.topic: yaml.safe_load(c.metadata['offered_qos_profiles'])[0]
           for c in channels.values()}
    assert (qos['/note']['reliability'], qos['/note']['durability']) == (1, 1)
    assert (qos['/w']['reliability'], qos['/w']['durability']) == (2, 2)
    assert all(c.metadata['topic_type_hash'].startswith('RIHS01_') and c.message_encoding == 'cdr'
               for c in channels.values())
    # Without custom data: no cvc_balance record, the file's own name.
    plain = tmp_path / 'plain.mcap'
    with BagWriter(plain):
        pass
    with open(plain, 'rb') as stream:
        records = [(m.name, m.metadata) for m in make_reader(stream).iter_metadata()]
    assert [name for name, _ in records] == ['rosbag2', 'rosbag2']
    closed = yaml.safe_load(records[1][1]['serialized_metadata'])
    assert closed['relative_file_paths'] == ['plain.mcap'] and closed['custom_data'] is None


def test_what_was_written_so_far(tmp_path):
    """written(): per channel its messages so far, and the first and last log time."""
    with BagWriter(tmp_path / 'so_far.mcap', chunk_bytes=1 << 16) as writer:
        assert writer.written() == ([], (None, None))
        note = writer.add_channel('/note', STRING, latched=True)
        w = writer.add_channel('/w', WRENCH, best_effort=True)
        writer.write(note, 50, string_message('a'))
        writer.write(note, 20, string_message('b'))
        block = MessageBlock([(w, wrench_stamped_layout('s'))], 4)
        writer.write_block(block, [30, 31, 32, 99, 100], 3)     # the first 3 of the times
        topics, span = writer.written()
        assert [tuple(t) for t in topics] == [('/note', STRING, 2, True, False),
                                              ('/w', WRENCH, 3, False, True)]
        writer.close()
        assert writer.written()[1] == (20, 50)
        assert writer.bag_metadata()['message_count'] == 5


def test_empty_bag(tmp_path):
    """No channel, no message: statistics of zeros, no chunk; read by the mcap library."""
    path = tmp_path / 'empty.mcap'
    BagWriter(path).close()
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        statistics = reader.get_summary().statistics
        assert list(reader.iter_messages()) == []
    assert (statistics.message_count, statistics.chunk_count, statistics.message_start_time,
            statistics.message_end_time, statistics.channel_message_counts) == (0, 0, 0, 0, {})
    assert [op for _, op, _ in records_by_hand(path.read_bytes())] == \
        [HEADER, METADATA, METADATA, DATA_END, STATISTICS, METADATA_INDEX, METADATA_INDEX] + \
        [SUMMARY_OFFSET] * 5 + [FOOTER]


def chunks_of_notes(path, compression, level):
    """Return the chunks (by hand) of 8 notes written at ``path`` in chunks of 2 KiB: 2 or more."""
    text = ' '.join(f'{k * k}' for k in range(400))
    with BagWriter(path, compression=compression, level=level, chunk_bytes=2048) as writer:
        note = writer.add_channel('/note', STRING)
        for k in range(8):
            writer.write(note, k, string_message(text[k * 200:(k + 1) * 300]))
    chunks = [chunk_by_hand(body) for _, op, body in records_by_hand(path.read_bytes())
              if op == CHUNK]
    assert len(chunks) >= 2
    return chunks


@pytest.mark.parametrize('level', [None, 9])
def test_zstd_chunks_are_zstandards_compression_of_their_records(level, tmp_path):
    """Each chunk's bytes: zstandard's at the level given, else at level 1 (libmcap's)."""
    import zstandard
    chunks = chunks_of_notes(tmp_path / 'z.mcap', 'zstd', level)
    for _, _, size, crc, compression, data in chunks:
        inner = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        assert compression == 'zstd' and len(inner) == size and crc == zlib.crc32(inner)
        assert data == zstandard.ZstdCompressor(level=level or 1).compress(inner)
        assert data != zstandard.ZstdCompressor(level=10 - (level or 1)).compress(inner)


@pytest.mark.parametrize('level', [None, 9])
def test_lz4_chunks_are_lz4_frames_of_their_records(level, tmp_path):
    """Each chunk: an lz4 frame at the level given (else 0) that states its content size."""
    import lz4.frame
    chunks = chunks_of_notes(tmp_path / 'l.mcap', 'lz4', level)
    for _, _, size, crc, compression, data in chunks:
        inner = lz4.frame.decompress(data)
        assert compression == 'lz4' and len(inner) == size and crc == zlib.crc32(inner)
        assert lz4.frame.get_frame_info(data)['content_size'] == size
        assert data == lz4.frame.compress(inner, compression_level=level or 0, store_size=True)
        if level:
            assert data != lz4.frame.compress(inner, compression_level=0, store_size=True)


def test_an_unknown_compression_is_refused(tmp_path):
    with pytest.raises(ValueError) as error:
        BagWriter(tmp_path / 'g.mcap', compression='gzip')
    assert str(error.value) == "unknown compression 'gzip' (zstd, lz4 or none)"


def test_a_chunk_closes_when_it_reaches_chunk_bytes(tmp_path):
    """write(): a chunk is closed as soon as it holds chunk_bytes, not a message later."""
    path = tmp_path / 'sized.mcap'
    data = string_message('x' * 7)          # a record of 31 + 16 bytes
    record = 31 + len(data)
    with BagWriter(path, compression='', chunk_bytes=3 * record) as writer:
        note = writer.add_channel('/note', STRING)
        for k in range(7):
            writer.write(note, k, data)
    chunks = [chunk_by_hand(body) for _, op, body in records_by_hand(path.read_bytes())
              if op == CHUNK]
    assert [(start, end, size) for start, end, size, *_ in chunks] == \
        [(0, 2, 3 * record), (3, 5, 3 * record), (6, 6, record)]


def test_blocks_are_cut_into_chunks_of_whole_samples(tmp_path):
    """
    write_block(): chunk_bytes // (bytes of a sample's records) samples a chunk.

    Two channels a sample (the records of a sample together); 11 of a block's samples
    with 4 to a chunk: chunks of 4, 4 and 3 samples, each spanning its own log times, the
    index of each channel pointing at its records; the decoded wrenches as set, by
    rosbags. The writer's own block() lays out as many samples as a chunk holds.
    """
    path = tmp_path / 'blocks.mcap'
    stator, rotor = wrench_stamped_layout('stator'), wrench_stamped_layout('rotor')
    group = 2 * 31 + stator.size + rotor.size
    with BagWriter(path, compression='', chunk_bytes=4 * group + group - 1) as writer:
        a, b = writer.add_channel('/a', WRENCH), writer.add_channel('/b', WRENCH)
        made = writer.block([(a, stator), (b, rotor)])
        assert (made.n, made.group_size) == (4, group)
    with BagWriter(tmp_path / 'small.mcap', chunk_bytes=group - 1) as writer:
        a, b = writer.add_channel('/a', WRENCH), writer.add_channel('/b', WRENCH)
        assert writer.block([(a, stator), (b, rotor)]).n == 1     # at least one sample
        block = MessageBlock([(a, stator), (b, rotor)], 3)
        block.put(['0.force_x', '1.force_x'], np.array([1.0, 2.0, 3.0]), 3)
        writer.write_block(block, [1, 2, 3])
    with open(tmp_path / 'small.mcap', 'rb') as stream:
        reader = make_reader(stream)
        assert [(i.message_start_time, i.message_end_time)
                for i in reader.get_summary().chunk_indexes] == [(1, 1), (2, 2), (3, 3)]
    with BagWriter(path, compression='', chunk_bytes=4 * group + group - 1) as writer:
        a, b = writer.add_channel('/a', WRENCH), writer.add_channel('/b', WRENCH)
        block = MessageBlock([(a, stator), (b, rotor)], 12)
        i = np.arange(12)
        block.put(['0.sec', '1.sec'], i + 100, 12)
        block.put(['0.nanosec', '1.nanosec'], [i * 3, i * 5], 12)
        block.put(['0.force_x', '0.force_y', '0.force_z'], [i * 0.5, -i * 0.25, i + 0.125], 12)
        block.put(['1.torque_z'], [i * 1.5], 12)
        writer.write_block(block, 10 * i + 7, 11)
    data = path.read_bytes()
    records = records_by_hand(data)
    chunks = [(at, chunk_by_hand(body)) for at, op, body in records if op == CHUNK]
    assert [(start, end, size) for _, (start, end, size, *_) in chunks] == \
        [(7, 37, 4 * group), (47, 77, 4 * group), (87, 107, 3 * group)]
    got = {a: [], b: []}
    for record in parsed(data):
        if isinstance(record, Chunk):
            for message in breakup_chunk(record, validate_crc=True):
                assert message.publish_time == message.log_time and message.sequence == 0
                got[message.channel_id].append((message.log_time,) +
                                               wrench_values(message.data))
    assert got[a] == [(10 * k + 7, k + 100, k * 3, 'stator',
                       (k * 0.5, -k * 0.25, k + 0.125, 0.0, 0.0, 0.0)) for k in range(11)]
    assert got[b] == [(10 * k + 7, k + 100, k * 5, 'rotor', (0.0, 0.0, 0.0, 0.0, 0.0, k * 1.5))
                      for k in range(11)]
    # Each chunk's message indexes, by hand: sample j's records at j * group, b's after a's.
    at_of = {at: k for k, (at, _, _) in enumerate(records)}
    for (at, (start, end, size, *_)), first in zip(chunks, (0, 4, 8)):
        k = at_of[at]
        n = size // group
        times = [10 * (first + j) + 7 for j in range(n)]
        assert records[k + 1][2] == index_record(a, [(t, j * group) for j, t in
                                                     enumerate(times)])[9:]
        assert records[k + 2][2] == index_record(b, [(t, j * group + 31 + stator.size)
                                                     for j, t in enumerate(times)])[9:]
    with open(path, 'rb') as stream:
        statistics = make_reader(stream).get_summary().statistics
    assert statistics.channel_message_counts == {a: 11, b: 11}
    assert (statistics.message_start_time, statistics.message_end_time) == (7, 107)


def test_a_block_filled_on_the_writers_thread_and_written_whole(tmp_path):
    """
    write_block(fill=...) with no count: every sample of the block, filled by ``fill``.

    Five blocks in a row through one block object (its one buffer reused), the fill setting
    each buffer's fields; a block of 3 samples to chunks of 2: read back by the mcap
    library and rosbags, each sample as filled.
    """
    path = tmp_path / 'filled.mcap'
    layout = wrench_stamped_layout('stator')
    with BagWriter(path, compression='zstd', chunk_bytes=2 * (31 + layout.size)) as writer:
        w = writer.add_channel('/w', WRENCH)
        block = MessageBlock([(w, layout)], 3, buffers=1)
        late = []     # a fill of no samples is not called: it raced the next block's fill
        for r in range(5):
            def fill(buffer, r=r):
                buffer.put(['0.sec'], np.array([r, r, r]), 3)
                buffer.put(['0.force_x', '0.torque_y'], [np.arange(3) + 10 * r,
                                                         -np.arange(3) - 10 * r], 3)
            writer.write_block(block, np.arange(3) + 100 * r, fill=fill)
            writer.write_block(block, [], 0, fill=late.append)   # nothing: the block stays

        def fill_two(buffer):
            buffer.put(['0.sec'], np.array([5, 5]), 2)
            buffer.put(['0.force_x', '0.torque_y'], [np.arange(2) + 50, -np.arange(2) - 50], 2)
        writer.write_block(block, np.arange(3) + 500, 2, fill=fill_two)
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        got = [(m.log_time, wrench_values(m.data)) for _, _, m in
               reader.iter_messages(log_time_order=False)]
        assert reader.get_summary().statistics.chunk_count == 11
    assert late == []
    assert got == [(100 * r + j, (r, 0, 'stator', (10.0 * r + j, 0.0, 0.0, 0.0, -10.0 * r - j,
                                                   0.0)))
                   for r in range(6) for j in range(3 if r < 5 else 2)]


def test_a_block_holds_at_most_its_buffers(tmp_path):
    """
    A block of two buffers: the third write waits for the first buffer and fills it again.

    The fills wait until released (the first two cannot be done when the second and third
    writes take a buffer); the third write's fill gets the first write's buffer.
    """
    import threading
    release, used = threading.Event(), []
    layout = wrench_stamped_layout('s')
    with BagWriter(tmp_path / 'two.mcap', compression='') as writer:
        w = writer.add_channel('/w', WRENCH)
        block = MessageBlock([(w, layout)], 2, buffers=2)

        def fill(buffer):
            used.append(buffer)
            release.wait(5.0)
            buffer.put(['0.force_x'], np.array([1.0, 2.0]), 2)
        writer.write_block(block, [1, 2], fill=fill)
        writer.write_block(block, [3, 4], fill=fill)
        threading.Timer(0.02, release.set).start()
        writer.write_block(block, [5, 6], fill=fill)
    assert len(used) == 3 and used[0] is not used[1] and used[2] is used[0]


def test_ids_are_the_ones_the_mcap_library_gives(tmp_path):
    """Schema and channel ids: 1, 2, ... in the order registered, as mcap's Writer gives."""
    from mcap.writer import Writer
    theirs = Writer(io.BytesIO())
    theirs.start()
    expected = []
    with BagWriter(tmp_path / 'ids.mcap') as writer:
        schemas = {}
        for topic, msg_type in (('/a', STRING), ('/b', WRENCH), ('/c', STRING), ('/d', WRENCH),
                                ('/e', 'sensor_msgs/msg/JointState')):
            if msg_type not in schemas:
                schemas[msg_type] = theirs.register_schema(msg_type, 'ros2msg', b'')
            expected.append((theirs.register_channel(topic, 'cdr', schemas[msg_type]),
                             schemas[msg_type]))
            assert writer.add_channel(topic, msg_type) == expected[-1][0]
    with open(tmp_path / 'ids.mcap', 'rb') as stream:
        channels = make_reader(stream).get_summary().channels
    assert [(c.id, c.schema_id) for c in channels.values()] == expected


def test_put_sets_fields_together_apart_and_as_one_value(tmp_path):
    """
    MessageBuffer.put: evenly spaced fields in one strided copy, others one by one.

    force_x, force_y, torque_z (not evenly spaced), one row for several fields, a
    stamp's sec and nanosec as one '<u8', a single field: decoded by rosbags.
    """
    path = tmp_path / 'put.mcap'
    layout = wrench_stamped_layout('f')
    with BagWriter(path, compression='') as writer:
        w = writer.add_channel('/w', WRENCH)
        block = MessageBlock([(w, layout)], 4)
        block.put(['0.force_x', '0.force_y', '0.torque_z'], [[1.0, 2, 3], [5.0, 6, 7],
                                                             [9.0, 10, 11]], 3)
        block.put(['0.torque_x', '0.torque_y'], np.array([-1.0, -2, -3, -4]), 4)
        block.put(['0.sec'], (np.arange(4, dtype=np.uint64) << np.uint64(32)) + np.uint64(40),
                  4, '<u8')
        block.put(['0.force_z'], np.array([0.5, 0.25]), 2)
        writer.write_block(block, [1, 2, 3, 4])
        block.put(['0.sec', '0.nanosec'], np.array([7, 8]), 2)
        block.put(['0.force_x', '0.force_y', '0.torque_z'], np.array([0.5, 1.5]), 2)
        block.put(['0.force_z', '0.torque_x', '0.torque_y'], np.zeros(2), 2)
        writer.write_block(block, [5, 6], 2)
    with open(path, 'rb') as stream:
        got = [wrench_values(m.data) for _, _, m in make_reader(stream).iter_messages()]
    assert got == [(40, 0, 'f', (1.0, 5.0, 0.5, -1.0, -1.0, 9.0)),
                   (40, 1, 'f', (2.0, 6.0, 0.25, -2.0, -2.0, 10.0)),
                   (40, 2, 'f', (3.0, 7.0, 0.0, -3.0, -3.0, 11.0)),
                   (40, 3, 'f', (0.0, 0.0, 0.0, -4.0, -4.0, 0.0)),
                   (7, 7, 'f', (0.5, 0.5, 0.0, 0.0, 0.0, 0.5)),
                   (8, 8, 'f', (1.5, 1.5, 0.0, 0.0, 0.0, 1.5))]


def test_closing_twice_changes_nothing(tmp_path):
    path = tmp_path / 'twice.mcap'
    writer = BagWriter(path)
    writer.write(writer.add_channel('/n', STRING), 1, string_message('n'))
    writer.close()
    data = path.read_bytes()
    writer.close()
    with writer:
        pass
    assert path.read_bytes() == data and data.endswith(MAGIC)


def test_an_exclusive_writer_never_replaces_a_file(tmp_path):
    """exclusive=True: a taken name (a file, a link, a directory) is refused and kept."""
    taken = tmp_path / 'taken.mcap'
    taken.write_bytes(b'old')
    (tmp_path / 'link.mcap').symlink_to(tmp_path / 'nowhere.mcap')
    (tmp_path / 'dir.mcap').mkdir()
    for name in ('taken.mcap', 'link.mcap', 'dir.mcap'):
        with pytest.raises(BagError) as error:
            BagWriter(tmp_path / name, exclusive=True)
        assert str(error.value) == (f'{tmp_path / name}: exists; a recording never replaces '
                                    'a file (give a name not taken)')
    assert taken.read_bytes() == b'old' and not (tmp_path / 'nowhere.mcap').exists()
    BagWriter(tmp_path / 'new.mcap', exclusive=True).close()
    with open(tmp_path / 'new.mcap', 'rb') as stream:
        assert make_reader(stream).get_header().profile == 'ros2'


def test_a_file_written_over_is_replaced_unless_linked(tmp_path):
    """
    A regular file of one link is replaced by a new file (a reader of the old keeps it).

    A file with a second (hard) link and a symbolic link's target are written in place:
    every name shows the new bag.
    """
    old = tmp_path / 'old.mcap'
    old.write_bytes(b'old bytes')
    with open(old, 'rb') as reading:
        BagWriter(old).close()
        assert reading.read() == b'old bytes'
    assert old.read_bytes().startswith(MAGIC)
    linked, other = tmp_path / 'linked.mcap', tmp_path / 'other.mcap'
    linked.write_bytes(b'old bytes')
    os.link(linked, other)
    BagWriter(linked).close()
    assert other.read_bytes() == linked.read_bytes() and other.read_bytes().startswith(MAGIC)
    target, symlink = tmp_path / 'target.mcap', tmp_path / 'symlink.mcap'
    target.write_bytes(b'old bytes')
    symlink.symlink_to(target)
    BagWriter(symlink).close()
    assert symlink.is_symlink() and target.read_bytes().startswith(MAGIC)


def test_short_writes_are_completed(tmp_path, monkeypatch):
    """
    os.writev writing at most 5 bytes a call: every record still goes out whole.

    The file is read by the mcap library (CRCs validated) and taken apart by hand; it is
    the file written without short writes, byte for byte.
    """
    def write_bag(path):
        with BagWriter(path, compression='', chunk_bytes=256, custom_data={'k': 'v'},
                       file_name='bag.mcap') as writer:
            note = writer.add_channel('/note', STRING)
            w = writer.add_channel('/w', WRENCH)
            for k in range(6):
                writer.write(note, k, string_message(f'note {k}'))
            block = MessageBlock([(w, wrench_stamped_layout('s'))], 3)
            block.put(['0.force_x'], np.array([1.0, 2.0, 3.0]), 3)
            writer.write_block(block, [10, 11, 12])
    whole = tmp_path / 'whole.mcap'
    write_bag(whole)
    writev, calls = os.writev, []

    def short(fd, views):
        calls.append(sum(len(v) for v in views))
        room, parts = 5, []
        for view in views:
            parts.append(view[:room])
            room -= len(parts[-1])
            if not room:
                break
        return writev(fd, parts)
    monkeypatch.setattr(os, 'writev', short)
    cut = tmp_path / 'cut.mcap'
    write_bag(cut)
    monkeypatch.undo()
    data = cut.read_bytes()
    assert len(calls) > len(data) // 5 and max(calls) > 100
    assert len(records_by_hand(data)) == len(records_by_hand(whole.read_bytes()))
    with open(cut, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        got = [(c.topic, m.log_time) for _, c, m in reader.iter_messages(log_time_order=False)]
    assert got == [('/note', k) for k in range(6)] + [('/w', t) for t in (10, 11, 12)]
    assert data == whole.read_bytes()


def test_written_chunks_leave_the_page_cache(tmp_path, monkeypatch):
    """
    Written chunks leave the page cache.

    Each chunk (with its message indexes) is advised out of the page cache when written,
    and again, then clean, when eight more chunks have been written.
    """
    advised = []
    monkeypatch.setattr(os, 'posix_fadvise',
                        lambda fd, start, length, advice: advised.append((start, length,
                                                                          advice)))
    path = tmp_path / 'cached.mcap'
    with BagWriter(path, compression='', chunk_bytes=64) as writer:
        note = writer.add_channel('/note', STRING)
        for k in range(12):
            writer.write(note, k, string_message(f'{k:060d}'))
    monkeypatch.undo()
    with open(path, 'rb') as stream:
        indexes = make_reader(stream).get_summary().chunk_indexes
    spans = [(i.chunk_start_offset, i.chunk_length + i.message_index_length) for i in indexes]
    assert len(spans) == 12
    expected = []
    for k, span in enumerate(spans):
        expected.append(span)
        if k >= 8:
            expected.append(spans[k - 8])
    assert advised == [(start, length, os.POSIX_FADV_DONTNEED) for start, length in expected]


def test_a_block_of_joint_states_whose_last_bytes_are_no_field(tmp_path):
    """
    Write JointState blocks (two joints; the empty effort's length after the last field).

    Two blocks of 4 and 3 samples, decoded by rosbags: names, stamps, positions and
    velocities as set, effort empty.
    """
    path = tmp_path / 'joints.mcap'
    layout = joint_state_layout('base', ['a', 'bb'])
    with BagWriter(path, compression='lz4') as writer:
        joints = writer.add_channel('/joint_states', 'sensor_msgs/msg/JointState')
        block = MessageBlock([(joints, layout)], 4, buffers=0)    # 0: one buffer all the same
        for first, n in ((0, 4), (4, 3)):
            k = np.arange(first, first + n)
            block.put(['0.sec', '0.nanosec'], [k + 1, 1000 * k], n)
            block.put(['0.position_0', '0.position_1'], [0.5 * k, -0.25 * k], n)
            block.put(['0.velocity_0', '0.velocity_1'], [k + 0.125, k - 0.125], n)
            writer.write_block(block, 10 * k, n)
    got = []
    with open(path, 'rb') as stream:
        for _, _, m in make_reader(stream, validate_crcs=True).iter_messages():
            state = TYPESTORE.deserialize_cdr(m.data, 'sensor_msgs/msg/JointState')
            got.append((m.log_time, state.header.stamp.sec, state.header.stamp.nanosec,
                        state.header.frame_id, list(state.name), state.position.tolist(),
                        state.velocity.tolist(), state.effort.tolist()))
    assert got == [(10 * k, k + 1, 1000 * k, 'base', ['a', 'bb'], [0.5 * k, -0.25 * k],
                    [k + 0.125, k - 0.125], []) for k in range(7)]


def test_chunks_go_out_in_order_when_a_later_one_is_packed_first(tmp_path):
    """
    Chunks go out in order when a later one is packed first.

    The first block's chunk is packed last (its fill waits for the later writes): the
    file still holds the chunks in the order written, as the chunk indexes list them.
    """
    import threading
    release = threading.Event()
    layout = wrench_stamped_layout('s')
    path = tmp_path / 'order.mcap'
    with BagWriter(path, compression='') as writer:
        w = writer.add_channel('/w', WRENCH)
        first, later = (MessageBlock([(w, layout)], 1) for _ in range(2))
        writer.write_block(first, [1], fill=lambda buffer: release.wait(5.0))
        for k in range(2, 6):
            writer.write_block(later, [k])
        threading.Timer(0.05, release.set).start()
    records = records_by_hand(path.read_bytes())
    assert [chunk_by_hand(body)[0] for _, op, body in records if op == CHUNK] == [1, 2, 3, 4, 5]
    with open(path, 'rb') as stream:
        indexes = make_reader(stream).get_summary().chunk_indexes
    assert [(i.message_start_time, i.chunk_start_offset) for i in indexes] == \
        [(k, at) for k, (at, op, _) in zip(range(1, 6), [r for r in records if r[1] == CHUNK])]
