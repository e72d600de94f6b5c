"""
The bag reader's field gathering against a second reader (issue 29's mutation run).

Bags written by the ``mcap`` library's own writer, their messages serialised by rosbags;
what :mod:`cvc_balance.bag.mcap_reader` gathers with numpy (strided views for runs of
equal records, byte gathering for the others) is compared, value for value, with rosbags'
deserialisation of every message the ``mcap`` library's reader returns.
"""

import io
import struct

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from cvc_balance.bag.mcap_reader import (Bag, float64_samples, joint_samples, string_samples,
                                         wrench_samples)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
WRENCH, JOINT, STRING = ('geometry_msgs/msg/WrenchStamped', 'sensor_msgs/msg/JointState',
                         'std_msgs/msg/String')


def header(sec, nanosec, frame):
    types = TYPESTORE.types
    return types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame)


def wrench(sec, nanosec, frame, values):
    types = TYPESTORE.types
    vector = types['geometry_msgs/msg/Vector3']
    msg = types[WRENCH](header=header(sec, nanosec, frame), wrench=types[
        'geometry_msgs/msg/Wrench'](force=vector(*values[:3]), torque=vector(*values[3:])))
    return TYPESTORE.serialize_cdr(msg, WRENCH).tobytes()


def joint_state(sec, nanosec, frame, names, position, velocity):
    msg = TYPESTORE.types[JOINT](header=header(sec, nanosec, frame), name=list(names),
                                 position=np.array(position, float),
                                 velocity=np.array(velocity, float),
                                 effort=np.zeros(0))
    return TYPESTORE.serialize_cdr(msg, JOINT).tobytes()


def write_with_mcap_library(path, topics, messages, chunk_size=1024,
                            compression=CompressionType.LZ4, chunking=True):
    """Write ``messages`` [(topic, log time ns, bytes)] with the mcap library; return path."""
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=chunk_size, compression=compression,
                        use_chunking=chunking)
        writer.start(profile='ros2', library='mcap python')
        ids = {}
        for topic, msg_type in topics.items():
            schema = writer.register_schema(name=msg_type, encoding='ros2msg', data=b'')
            ids[topic] = writer.register_channel(topic=topic, message_encoding='cdr',
                                                 schema_id=schema)
        for n, (topic, log_time, data) in enumerate(messages):
            writer.add_message(ids[topic], log_time=log_time, data=data,
                               publish_time=log_time, sequence=n)
        writer.finish()
    return path


def read_with_mcap_library(path, topic, msg_type):
    """[(log time, message)] of ``topic`` by the mcap library, deserialised by rosbags."""
    with open(path, 'rb') as stream:
        return [(m.log_time, TYPESTORE.deserialize_cdr(m.data, msg_type))
                for _, c, m in make_reader(stream).iter_messages(topics=[topic])]


def wrench_messages():
    """Return a run of equal records (one frame), then frames of other lengths, odd stamps."""
    rng = np.random.default_rng(29)
    out = []
    for k in range(60):                      # equal lengths: read through strided views
        out.append((1_000 + k, 7 + k, 1_000 * k + 1, 'stator', rng.normal(size=6) * 1e3))
    stamps = [(-3, 5), (2**31 - 1, 999_999_999), (0, 0), (12, 1)]
    for k, ((sec, nanosec), frame) in enumerate(zip(stamps, ['', 'a', 'rotor_frame_x', 'ab'])):
        out.append((9_000 + k, sec, nanosec, frame, rng.normal(size=6) * 1e-3))
    return out


@pytest.mark.parametrize('chunking', [True, False], ids=['chunks', 'loose'])
def test_wrench_samples_are_rosbags_decoding_of_every_message(chunking, tmp_path):
    """
    Stamps (int32 sec, negative too, and uint32 nanosec) and the six floats of each wrench.

    60 messages of one length (strided gathering), then four of other frame ids (gathered
    by bytes): each message's stamp in ns and wrench equal to rosbags', exactly; a
    channel with no messages gives empty arrays of the documented shapes.
    """
    written = wrench_messages()
    path = write_with_mcap_library(
        tmp_path / 'wrench.mcap', {'/load': WRENCH, '/empty': WRENCH},
        [('/load', log, wrench(sec, ns, frame, values))
         for log, sec, ns, frame, values in written], chunking=chunking)
    theirs = read_with_mcap_library(path, '/load', WRENCH)
    assert len(theirs) == len(written) == 64
    bag = Bag(path)
    assert bag.problems == []
    stamp, force, torque = wrench_samples(bag, bag.channel('/load', WRENCH))
    expected_stamp = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
                      for _, m in theirs]
    assert stamp.dtype == np.int64 and stamp.tolist() == expected_stamp
    assert stamp[60] == -3 * 10**9 + 5 and stamp[61] == (2**31 - 1) * 10**9 + 999_999_999
    w = [m.wrench for _, m in theirs]
    assert force.tolist() == [[v.force.x, v.force.y, v.force.z] for v in w]
    assert torque.tolist() == [[v.torque.x, v.torque.y, v.torque.z] for v in w]
    empty = wrench_samples(bag, bag.channel('/empty', WRENCH))
    assert [(a.shape, a.dtype) for a in empty] == \
        [((0,), np.int64), ((0, 3), np.float64), ((0, 3), np.float64)]


def test_joint_states_of_publishers_of_several_lengths_in_one_chunk(tmp_path):
    """
    Interleaved publishers (one chunk): the rows by name, as rosbags decodes them.

    Four publishers on one topic: A (frame 'a'; names gantry_joint, tube), B (frame
    'longer frame'; names in the other order), C (frame 'b': A's length, other bytes),
    D (no gantry_joint: skipped and its names said) and E (gantry_joint without a
    velocity: rejected). Stamps, log times, angle and speed of each A, B, C message equal
    rosbags' decoding picked by the joint's name; written out of log-time order, they come
    sorted.
    """
    messages = []
    for n in range(30):
        log = 10_000 - 7 * n if n % 5 == 0 else 10_000 + 11 * n     # some out of order
        sec, ns = 100 + n, 1_000 * n + 3
        q, w = 0.01 * n - 0.1, 2.0 + n
        which = n % 5
        if which == 0:
            data = joint_state(sec, ns, 'a', ['gantry_joint', 'tube'], [q, 9.0], [w, 8.0])
        elif which == 1:
            data = joint_state(sec, ns, 'longer frame', ['tube', 'gantry_joint'], [7.0, q],
                               [6.0, w])
        elif which == 2:
            data = joint_state(sec, ns, 'b', ['gantry_joint', 'tube'], [q, 5.0], [w, 4.0])
        elif which == 3:
            data = joint_state(sec, ns, 'a', ['table', 'tilt'], [q, 1.0], [w, 1.0])
        else:
            data = joint_state(sec, ns, 'a', ['gantry_joint'], [q], [])
        messages.append(('/joint_states', log, data))
    path = write_with_mcap_library(tmp_path / 'joints.mcap', {'/joint_states': JOINT},
                                   messages, chunk_size=1 << 20)
    theirs = read_with_mcap_library(path, '/joint_states', JOINT)
    rows = []
    for log, m in theirs:
        if 'gantry_joint' in m.name and len(m.velocity):
            i = list(m.name).index('gantry_joint')
            rows.append((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, log,
                         m.position[i], m.velocity[i]))
    rows.sort(key=lambda r: r[1])
    bag = Bag(path)
    assert len(bag.chunks) == 1
    motion = joint_samples(bag, bag.channel('/joint_states', JOINT), 'gantry_joint')
    assert len(rows) == 18
    assert list(zip(motion.stamp.tolist(), motion.log_time.tolist(), motion.angle.tolist(),
                    motion.omega.tolist())) == rows
    assert (motion.skipped, motion.rejected, motion.joints_seen) == (6, 6, ['table', 'tilt'])
    assert motion.reasons == ['6 /joint_states messages not readable as JointState with '
                              'position and velocity']


def test_an_unreadable_string_message_is_said_and_the_rest_sorted(tmp_path):
    """
    A String whose length runs past its message costs itself, said in one line.

    Three layout texts written out of log-time order and one damaged (its length field
    says 200 bytes in a message of 12): the three texts in log-time order, as the mcap
    library and rosbags read them, and the one line naming the topic and log time.
    """
    good = [(30, 'third'), (10, 'first'), (20, 'second')]
    damaged = b'\x00\x01\x00\x00' + (200).to_bytes(4, 'little') + b'abc\x00'
    messages = [('/layout', log, TYPESTORE.serialize_cdr(
        TYPESTORE.types[STRING](data=text), STRING).tobytes()) for log, text in good]
    messages.insert(1, ('/layout', 15, damaged))
    path = write_with_mcap_library(tmp_path / 'layouts.mcap', {'/layout': STRING}, messages)
    with open(path, 'rb') as stream:
        raw = [(m.log_time, m.data) for *_, m in make_reader(stream).iter_messages()]
    assert (15, damaged) in raw
    theirs = sorted((log, TYPESTORE.deserialize_cdr(data, STRING).data)
                    for log, data in raw if data != damaged)
    bag = Bag(path)
    assert string_samples(bag, bag.channel('/layout', STRING)) == theirs
    assert bag.problems == ['/layout: message at 15 ns unreadable (string length beyond the '
                            'message); skipped']


def test_messages_of_a_channel_in_file_order_with_their_log_times(tmp_path):
    """``Bag.messages``: every message's log time and bytes, as the mcap library reads them."""
    written = wrench_messages()
    path = write_with_mcap_library(
        tmp_path / 'w.mcap', {'/load': WRENCH},
        [('/load', log, wrench(sec, ns, frame, values))
         for log, sec, ns, frame, values in written], chunk_size=600,
        compression=CompressionType.ZSTD)
    with open(path, 'rb') as stream:
        theirs = [(m.log_time, bytes(m.data)) for *_, m in make_reader(stream).iter_messages()]
    bag = Bag(path)
    assert len(bag.chunks) > 4
    assert bag.messages(bag.channel('/load', WRENCH)) == theirs


# -- a chunk without message indexes, written by hand ------------------------------------

def record(opcode, body):
    return struct.pack('<BQ', opcode, len(body)) + body


def text(value):
    data = value.encode()
    return struct.pack('<I', len(data)) + data


def message(channel, sequence, log_time, data):
    return record(0x05, struct.pack('<HIQQ', channel, sequence, log_time, log_time) + data)


def float64(value):
    return b'\x00\x01\x00\x00' + struct.pack('<d', value)     # CDR: aligned after the 4


def hand_bag(chunk_records):
    """Return an MCAP file by hand: a header, one uncompressed chunk (CRC 0), no index."""
    definitions = record(0x03, struct.pack('<H', 1) + text(FLOAT64) + text('ros2msg') +
                         text('')) + \
        record(0x04, struct.pack('<HH', 1, 1) + text('/speed') + text('cdr') +
               struct.pack('<I', 0))
    records = definitions + b''.join(chunk_records)
    chunk = record(0x06, struct.pack('<QQQI', 0, 0, len(records), 0) + text('') +
                   struct.pack('<Q', len(records)) + records)
    header = record(0x01, text('ros2') + text('by hand'))
    body = MAGIC + header + chunk + record(0x0F, struct.pack('<I', 0))
    return body + record(0x02, struct.pack('<QQI', 0, 0, 0)) + MAGIC, len(MAGIC + header), \
        len(definitions)


FLOAT64 = 'std_msgs/msg/Float64'
MAGIC = b'\x89MCAP0\r\n'
# Log times: a run of 12 equal records (one of them out of order, one tie), an empty
# message (22 bytes: the shortest message record) on the run's stride, Float64s cut to
# 8 and to 11 bytes of data (12 whole), and three more.
SPEEDS = [(100 + 10 * k, 0.5 * k) for k in range(12)] + [(130, 99.0)]
SPEEDS[5] = (40, -2.5)
TAIL = [(200, 1.25), (150, -7.0), (200, 3.5)]


def speed_records():
    out = [message(1, k, log, float64(w)) for k, (log, w) in enumerate(SPEEDS)]
    out.append(message(1, 20, 170, b''))
    out.append(message(1, 21, 175, float64(8.0)[:8]))
    out.append(message(1, 22, 176, float64(9.0)[:11]))      # one byte short of whole
    out += [message(1, 30 + k, log, float64(w)) for k, (log, w) in enumerate(TAIL)]
    return out


def test_a_chunk_without_message_indexes_is_walked_record_by_record(tmp_path):
    """
    A chunk without message indexes: its records walked in runs of equal records.

    Each message's log time and bytes as the ``mcap`` library's stream reader gives them
    (the empty one too); the speeds of the whole Float64 messages (12 bytes of data or
    more: not the empty one, not those cut to 8 and 11 bytes) by hand, sorted by log time, ties
    in file order.
    """
    from mcap.records import Message
    from mcap.stream_reader import StreamReader
    data, _, _ = hand_bag(speed_records())
    path = tmp_path / 'hand.mcap'
    path.write_bytes(data)
    theirs = [(r.log_time, bytes(r.data)) for r in StreamReader(io.BytesIO(data)).records
              if isinstance(r, Message)]
    assert len(theirs) == 19
    bag = Bag(path)
    assert bag.problems == []
    channel = bag.channel('/speed', FLOAT64)
    assert bag.messages(channel) == theirs
    times, speeds = float64_samples(bag, channel)
    expected = sorted(SPEEDS + TAIL, key=lambda pair: pair[0])     # stable: ties in order
    assert times.dtype == np.int64 and speeds.dtype == np.float64
    assert list(zip(times.tolist(), speeds.tolist())) == expected


def test_float64_samples_sort_only_what_is_out_of_order(tmp_path):
    """Log times 5, 10, 7 (none before the first): sorted all the same; none: empty arrays."""
    data, _, _ = hand_bag([message(1, 0, 5, float64(1.0)), message(1, 1, 10, float64(2.0)),
                           message(1, 2, 7, float64(3.0))])
    path = tmp_path / 'three.mcap'
    path.write_bytes(data)
    bag = Bag(path)
    times, speeds = float64_samples(bag, bag.channel('/speed', FLOAT64))
    assert times.tolist() == [5, 7, 10] and speeds.tolist() == [1.0, 3.0, 2.0]
    data, _, _ = hand_bag([])
    path.write_bytes(data)
    bag = Bag(path)
    empty = float64_samples(bag, bag.channel('/speed', FLOAT64))
    assert [(a.shape, a.dtype) for a in empty] == [((0,), np.int64), ((0,), np.float64)]


def test_a_record_too_short_for_a_message_is_not_taken_for_one(tmp_path):
    """
    A record of opcode 5 and length 21 (a message needs 22: channel, sequence, two times).

    Not a message: the chunk's other messages are read as without it, nothing made up.
    """
    bogus = record(0x05, struct.pack('<HIQ', 1, 9, 160) + b'\x00' * 7)
    assert len(bogus) == 9 + 21
    records = speed_records()
    data, _, _ = hand_bag(records)
    (tmp_path / 'good.mcap').write_bytes(data)
    good = Bag(tmp_path / 'good.mcap')
    expected = good.messages(good.channel('/speed', FLOAT64))
    data, _, _ = hand_bag(records[:13] + [bogus] + records[13:])
    (tmp_path / 'bogus.mcap').write_bytes(data)
    bag = Bag(tmp_path / 'bogus.mcap')
    assert bag.messages(bag.channel('/speed', FLOAT64)) == expected
    assert len(expected) == 19


def test_a_record_running_past_its_chunks_end_is_said_and_the_rest_read(tmp_path):
    """
    The chunk's last record says it is 1000 bytes longer than the chunk holds.

    The problem line names the chunk's byte in the file, where the walk stopped and the
    records' length (by hand); every message before that record is read.
    """
    records = speed_records()
    last = bytearray(records[-1])
    struct.pack_into('<Q', last, 1, len(last) - 9 + 1000)
    data, chunk_at, definitions = hand_bag(records[:-1] + [bytes(last)])
    path = tmp_path / 'long.mcap'
    path.write_bytes(data)
    bag = Bag(path)
    channel = bag.channel('/speed', FLOAT64)
    assert [log for log, _ in bag.messages(channel)] == \
        [log for log, _ in SPEEDS] + [170, 175, 176] + [log for log, _ in TAIL[:-1]]
    stop = definitions + sum(len(r) for r in records[:-1])
    size = stop + len(last)
    assert bag.problems == [f"chunk at byte {chunk_at}: a record runs past the chunk's end "
                            f'at byte {stop} of its {size}; the rest of the chunk skipped']


def test_a_damaged_channel_record_in_a_chunk_costs_only_itself(tmp_path):
    """
    A second Channel record in the chunk whose topic length runs past the chunk's records.

    Said in one line (the chunk's byte, the record's opcode and offset by hand); the
    channel defined before it and its messages are read as without it.
    """
    damaged = record(0x04, struct.pack('<HH', 2, 1) + struct.pack('<I', 1 << 24) + b'/x')
    records = speed_records()
    data, chunk_at, definitions = hand_bag([damaged] + records)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(data)
    bag = Bag(path)
    channel = bag.channel('/speed', FLOAT64)
    assert len(bag.messages(channel)) == 19
    assert bag.topics() == {'/speed': FLOAT64}
    assert bag.problems == [f'chunk at byte {chunk_at}: corrupt record (opcode 0x4) at '
                            f'{definitions}: string beyond the record; skipped']


def test_a_topic_of_the_wrong_type_names_every_topic_of_the_bag():
    """The refusal's one line: each topic with its type, '(no schema)' for one without."""
    from cvc_balance.bag.mcap_reader import BagError, ChannelInfo, select_channel
    channels = [ChannelInfo(1, '/speed', FLOAT64, 'cdr'), ChannelInfo(2, '/layout', '', 'cdr'),
                ChannelInfo(3, '/joint_states', JOINT, 'cdr')]
    with pytest.raises(BagError) as refused:
        select_channel(channels, 'speed', STRING, 'x.mcap')
    assert str(refused.value) == (
        f'x.mcap: topic /speed has type {FLOAT64}, expected {STRING}; the bag has: '
        f'/joint_states ({JOINT}), /layout (no schema), /speed ({FLOAT64})')


def test_a_run_of_equal_records_is_counted_to_its_last_one():
    """
    ``_run``: how many records from a position share the first's opcode and length.

    1000 equal messages (30-byte records: many of ``_run``'s growing blocks), then one of
    another length, or another opcode of the same length, at each of several places: the
    count is that place, by construction; the records' table lists every record.
    """
    from cvc_balance.bag.mcap_reader import _run, record_table
    same = message(1, 0, 7, b'\x00' * 8)
    step = len(same)
    for at in (2, 3, 17, 18, 83, 500, 999):
        for other in (message(1, 0, 7, b'\x00' * 9), record(0x07, b'\x00' * (step - 9))):
            buffer = np.frombuffer(same * at + other + same * (1000 - at), np.uint8)
            assert _run(buffer, 0, step, 0x05, step - 9) == at
            offsets, opcodes, lengths, end = record_table(buffer)
            expected = [step * k for k in range(at + 1)] + \
                [step * (at + 1) + len(other) - step + step * k for k in range(1000 - at)]
            assert offsets.tolist() == expected and end == len(buffer)
            assert opcodes.tolist() == [5] * at + [other[0]] + [5] * (1000 - at)
    buffer = np.frombuffer(same * 1000, np.uint8)
    assert _run(buffer, 0, step, 0x05, step - 9) == 1000
    assert _run(buffer, step * 990, step, 0x05, step - 9) == 10


def test_the_records_table_of_edge_buffers():
    """
    ``record_table`` at its edges: no records, a torn header, a last record of 9 bytes.

    The table of an empty buffer (an empty chunk) is three empty arrays of int64, uint8,
    int64 and ``end`` 0; of 5 bytes (less than a record's header), the same; a record of
    no body (9 bytes, opcode and length 0) ending the buffer exactly is listed, and
    ``end`` is the buffer's length.
    """
    from cvc_balance.bag.mcap_reader import record_table
    for data in (b'', b'\x05\x00\x00\x00\x00'):
        offsets, opcodes, lengths, end = record_table(np.frombuffer(data, np.uint8))
        assert [(a.shape, a.dtype) for a in (offsets, opcodes, lengths)] == \
            [((0,), np.int64), ((0,), np.uint8), ((0,), np.int64)] and end == 0
    same = message(1, 0, 7, b'\x00' * 8)
    for tail in (record(0x07, b''), record(0x07, b'') * 2, same + record(0x07, b'')):
        data = same * 3 + tail
        offsets, opcodes, lengths, end = record_table(np.frombuffer(data, np.uint8))
        assert end == len(data)
        assert offsets[-1] == len(data) - 9 and opcodes[-1] == 7 and lengths[-1] == 0


# -- a damaged record in a recording without a summary: the walk goes on by itself --------

def top_level(data):
    """[(offset, opcode, length)] of a file's top-level records, walked by hand."""
    position, found = 8, []
    while position + 9 <= len(data):
        opcode, length = struct.unpack_from('<BQ', data, position)
        if position + 9 + length > len(data):
            break
        found.append((position, opcode, length))
        position += 9 + length
    return found


def stream_messages(data, topic='/joint_states'):
    """(log time, bytes) of ``topic``'s messages the mcap library's stream reader reads."""
    from mcap.exceptions import EndOfFile
    return read_before_the_cut(data, topic, ends=(EndOfFile,))


@pytest.fixture(scope='module')
def cut_recording(tmp_path_factory):
    """Return a recording killed after its fifth chunk (no summary) and its records."""
    import yaml
    from independent import ramp, write_input_bag
    from test_survivors import GANTRY
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=3.0)
    path = write_input_bag(tmp_path_factory.mktemp('cut') / 'whole.mcap', stamps, angle,
                           omega, [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    data = path.read_bytes()
    chunks = [(o, n) for o, op, n in top_level(data) if op == 0x06]
    data = data[:chunks[4][0] + 9 + chunks[4][1]]
    return data, top_level(data)


@pytest.mark.parametrize('damage, number', [('length', 1), ('length and data', 1),
                                            ('length and data', 3), ('a false record', 1),
                                            ('header length', 0x01), ('schema length', 0x03),
                                            ('channel length', 0x04)])
def test_a_damaged_chunk_in_a_cut_recording(damage, number, cut_recording, tmp_path):
    """
    A chunk's length field says 1 MiB more than the file holds (and its data is damaged).

    Without a summary no chunk index says where chunks are: the walk goes on by itself.
    With its data whole the chunk's own fields (its CRC holds) give its length: every
    message is read, as the mcap library reads the undamaged file. With a byte of its
    data flipped too, the walk goes on at the next chunk: every message but that chunk's,
    as the mcap library reads the file without it; the line says how many bytes were
    skipped to which byte (by hand from the top-level records), and the next that the
    recording is cut (it was not said when another problem was). Chunk 3: the next whole
    record is the last, ending at the file's end. A false record: the damage looks like a
    Channel record's opcode and a length that fits the file (10), its fields not. The
    length field of the Header, the first Schema or the first Channel damaged: each read
    by its own fields.
    """
    data, records = cut_recording
    chunks = [(o, n) for o, op, n in records if op == 0x06]
    (at, length), (following, _) = chunks[number % 4], chunks[number % 4 + 1]
    damaged = bytearray(data)
    if damage.endswith(' length'):       # the first Header, Schema or Channel record
        at, length = next((o, n) for o, op, n in records if op == number)
    struct.pack_into('<Q', damaged, at + 1, length + (1 << 20))
    if damage.endswith('length'):
        expected = stream_messages(data)
        said = (f'record (opcode 0x{data[at]:02x}) at byte {at} runs past the end of the '
                f'file: its length field ({length + (1 << 20)}) is damaged, its fields give '
                f'{length}: read by them')
    else:
        if damage == 'a false record':
            struct.pack_into('<BQ', damaged, at + 9 + length // 2, 0x04, 10)
        else:
            damaged[at + 9 + length // 2] ^= 0xFF
        expected = stream_messages(data[:at] + data[following:])
        said = (f'record (opcode 0x06) at byte {at} runs past the end of the file: '
                f'{following - at} bytes skipped to the next whole record at byte {following}')
    assert number != 3 or damage.endswith('length') or \
        following + 9 + chunks[number + 1][1] == len(data)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(damaged))
    bag = Bag(path)
    ours = bag.messages(bag.channel('/joint_states', JOINT))
    assert len(ours) > 100 and ours == expected
    assert bag.problems == [said, 'file has no end of data (truncated recording?)']


# -- files that are cut, damaged or no bag at all (issue 29, third session) ----------------

def notes_bag(path, chunk_size=400, compression=CompressionType.ZSTD):
    """Write 40 String messages on /n (and 10 on /m) with the mcap library; return the path."""
    messages = []
    for k in range(40):
        messages.append(('/n', 1_000 + k, TYPESTORE.serialize_cdr(
            TYPESTORE.types[STRING](data=f'note {k} ' + 'x' * (k % 9)), STRING).tobytes()))
        if k % 4 == 0:
            messages.append(('/m', 1_000 + k, TYPESTORE.serialize_cdr(
                TYPESTORE.types[STRING](data=f'm {k}'), STRING).tobytes()))
    return write_with_mcap_library(path, {'/n': STRING, '/m': STRING}, messages,
                                   chunk_size=chunk_size, compression=compression)


def indexed_messages(data, topic='/n'):
    """(log time, bytes) of ``topic`` as the mcap library's indexed reader reads them."""
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    return [(m.log_time, bytes(m.data))
            for _, c, m in reader.iter_messages(log_time_order=False) if c.topic == topic]


def ours(path, topic='/n'):
    """(Bag, its messages of ``topic``)."""
    bag = Bag(path)
    return bag, bag.messages(bag.channel(topic, STRING))


def read_before_the_cut(data, topic='/n', ends=None):
    """
    Return (log time, bytes) of ``topic`` the mcap library's stream reader reads before the cut.

    ``ends``: the errors that say where the file ends (default: the end of the file, or a
    record cut short).
    """
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    out, topics = [], {}
    try:
        for r in StreamReader(io.BytesIO(data)).records:
            if isinstance(r, Channel):
                topics[r.id] = r.topic
            elif isinstance(r, Message) and topics[r.channel_id] == topic:
                out.append((r.log_time, bytes(r.data)))
    except ends or (EndOfFile, struct.error):            # where the file ends
        pass
    return out


def test_what_is_no_bag_is_refused_in_one_line(tmp_path):
    """No file, a directory, an empty file, a text: the words a person reads."""
    from cvc_balance.bag.mcap_reader import BagError
    (tmp_path / 'empty.mcap').write_bytes(b'')
    (tmp_path / 'text.mcap').write_text('name: not a bag\n')
    for name, why in (('missing.mcap', 'cannot read bag: No such file or directory'),
                      ('.', 'cannot read bag: Is a directory'),
                      ('empty.mcap', 'not an MCAP file (no MCAP magic at the start)'),
                      ('text.mcap', 'not an MCAP file (no MCAP magic at the start)')):
        with pytest.raises(BagError) as refused:
            Bag(tmp_path / name)
        assert str(refused.value) == f'{tmp_path / name}: {why}'


def test_a_file_cut_anywhere_says_where_and_keeps_what_came_before(tmp_path):
    """
    Cut inside a record's header, inside a chunk, after the data, inside the summary.

    Each time the one line says where (bytes by hand from the top-level records) and the
    messages are those the mcap library's stream reader reads before the cut; a cut in the
    summary loses no message.
    """
    data = notes_bag(tmp_path / 'whole.mcap').read_bytes()
    records = top_level(data)
    chunks = [o for o, op, _ in records if op == 0x06]
    data_end = next(o for o, op, _ in records if op == 0x0F)
    summary = next(o for o, op, _ in records if o > data_end)
    assert len(chunks) >= 4
    for cut, said in (
            (chunks[2] + 5, f'file ends inside a record header at byte {chunks[2]} '
                            '(truncated recording?)'),
            (chunks[2] + 30, f'file ends inside a record (opcode 0x06) at byte {chunks[2]} of '
                             f'{chunks[2] + 30} (truncated recording?)'),
            (data_end, 'file has no end of data (truncated recording?)'),
            (chunks[3] - 5, f'file ends inside a record (opcode 0x07) at byte '
                            f'{max(o for o, _, _ in records if o < chunks[3] - 5)} of '
                            f'{chunks[3] - 5} (truncated recording?)'),
            (summary + 12, f'file ends inside a record (opcode 0x{data[summary]:02x}) at byte '
                           f'{summary} of {summary + 12}, in its summary (every message was '
                           'read)')):
        path = tmp_path / 'cut.mcap'
        path.write_bytes(data[:cut])
        bag, got = ours(path)
        assert got == read_before_the_cut(data[:cut]), cut
        assert bag.problems == [said]
        assert bag.finished is False
    assert read_before_the_cut(data[:summary + 12]) == indexed_messages(data)
    # A record of no body (a kind no reader knows) ending exactly at the cut: read.
    path = tmp_path / 'cut.mcap'
    path.write_bytes(data[:chunks[2]] + struct.pack('<BQ', 0x80, 0))
    bag, got = ours(path)
    assert got == read_before_the_cut(data[:chunks[2]])
    assert bag.problems == ['file has no end of data (truncated recording?)']
    bag, got = ours(tmp_path / 'whole.mcap')
    assert bag.finished is True and bag.problems == [] and got == indexed_messages(data)


@pytest.mark.parametrize('data_end', ['whole', 'flipped'])
def test_records_the_walk_cannot_take_are_found_by_the_summarys_indexes(data_end, tmp_path):
    """
    Records the walk cannot take are found by the summarys indexes.

    Two chunks' opcodes flipped to a message's and a metadata record's to a kind no reader
    knows (and the data end's: the summary then found by the footer, the walk having
    missed it): the summary gives the chunks and the metadata record where they are.

    Every message as the mcap library's indexed reader reads the damaged file (through the
    summary: all of them), none taken for a message outside chunks; both metadata records
    (the first found by its index, the second by the walk), in file order, read once; one
    line for the chunks.
    """
    path = tmp_path / 'meta.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=400, compression=CompressionType.LZ4)
        writer.start(profile='ros2', library='mcap python')
        schema = writer.register_schema(name=STRING, encoding='ros2msg', data=b'')
        channel = writer.register_channel(topic='/n', message_encoding='cdr', schema_id=schema)
        for k in range(40):
            writer.add_message(channel, log_time=k, publish_time=k, sequence=k,
                               data=TYPESTORE.serialize_cdr(TYPESTORE.types[STRING](
                                   data=f'note {k} ' + 'y' * k), STRING).tobytes())
            if k in (10, 30):
                writer.add_metadata('zeta' if k == 10 else 'alpha', {'id': f'g-{k}'})
        writer.finish()
    data = bytearray(path.read_bytes())
    records = top_level(bytes(data))
    chunks = [o for o, op, _ in records if op == 0x06]
    metadata = [o for o, op, _ in records if op == 0x0C]
    data_end_at = next(o for o, op, _ in records if op == 0x0F)
    data[chunks[1]], data[chunks[3]], data[metadata[0]] = 0x05, 0x05, 0x7F
    if data_end == 'flipped':
        data[data_end_at] = 0x7E
    damaged = tmp_path / 'damaged.mcap'
    damaged.write_bytes(bytes(data))
    bag, got = ours(damaged)
    assert got == indexed_messages(bytes(data)) == indexed_messages(path.read_bytes())
    assert len(got) == 40 and bag.loose_messages() == []
    assert bag.problems == ["2 chunks read where the summary's chunk indexes put them (the "
                            'walk did not reach them whole)']
    assert [(offset, name, values) for offset, name, values, _ in bag.metadata] == \
        [(metadata[0], 'zeta', {'id': 'g-10'}), (metadata[1], 'alpha', {'id': 'g-30'})]
    summary = make_reader(io.BytesIO(bytes(data))).get_summary()
    assert bag.summary_records[0x08] == len(summary.chunk_indexes) >= 4
    assert bag.summary_records[0x0D] == 2 and bag.finished


def test_a_damaged_summary_record_stops_the_walk_there(tmp_path):
    """
    A damaged summary record stops the walk there.

    A Channel of the summary whose topic runs past it: said; every message read (as the
    mcap library's stream reader reads the data section).
    """
    data = bytearray(notes_bag(tmp_path / 'whole.mcap').read_bytes())
    records = top_level(bytes(data))
    data_end = next(o for o, op, _ in records if op == 0x0F)
    at = next(o for o, op, _ in records if o > data_end and op == 0x04)
    struct.pack_into('<I', data, at + 9 + 4, 1000)          # the topic's length
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    assert got == read_before_the_cut(bytes(data[:data_end])) and len(got) == 40
    assert bag.problems == [f'corrupt summary (opcode 0x04) at byte {at}: string beyond the '
                            'record; stopped reading there']


def test_two_messages_a_chunk_lists_in_reverse(tmp_path):
    """
    Two messages a chunk lists in reverse.

    A chunk's message index listing its two messages in reverse (by log time, as some
    writers sort it): both read, as the mcap library's stream reader reads them.
    """
    data = bytearray(hand_built_file([{1: [(20, 'later'), (10, 'earlier')]}]))
    index = next(o for o, op, _ in top_level(bytes(data)) if op == 0x07)
    entries = index + 9 + 6
    data[entries:entries + 32] = data[entries + 16:entries + 32] + data[entries:entries + 16]
    path = tmp_path / 'reversed.mcap'
    path.write_bytes(bytes(data))
    bag = Bag(path)
    assert bag.messages(bag.channel('/n', STRING)) == read_before_the_cut(bytes(data))[::-1]
    assert string_samples(bag, bag.channel('/n', STRING)) == [(10, 'earlier'), (20, 'later')]
    assert bag.problems == []


@pytest.mark.parametrize('damage, said', [
    ('crc', 'CRC mismatch'), ('size', 'size differs from the chunk header'),
    ('compression', "unknown compression 'zstx'"), ('no crc', None)])
def test_a_chunk_that_does_not_decode_costs_only_itself(damage, said, tmp_path):
    """
    A chunk that does not decode costs only itself.

    A chunk's CRC, uncompressed size or compression damaged: its messages are lost, said
    once; the others are read (as the mcap library reads them from the file without that
    chunk). A CRC of 0 means none was computed: the chunk is read.
    """
    data = bytearray(notes_bag(tmp_path / 'whole.mcap').read_bytes())
    records = top_level(bytes(data))
    at, length = [(o, n) for o, op, n in records if op == 0x06][1]
    following = next(o for o, op, _ in records if o > at and op not in (0x06, 0x07))
    following = min(following, [o for o, op, _ in records if op == 0x06][2])
    if damage == 'crc':
        data[at + 9 + 24] ^= 0x01
    elif damage == 'size':
        struct.pack_into('<Q', data, at + 9 + 16, struct.unpack_from('<Q', data, at + 25)[0] + 1)
    elif damage == 'compression':
        assert data[at + 9 + 32:at + 9 + 36] == b'zstd'
        data[at + 9 + 35:at + 9 + 36] = b'x'
    else:
        struct.pack_into('<I', data, at + 9 + 24, 0)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    if said is None:
        assert got == indexed_messages(bytes(data)) and bag.problems == []
        return
    whole = bytes(data)
    assert got == stream_messages(whole[:at] + whole[following:], '/n')
    assert len(got) < 40
    assert bag.problems == [f'chunk at byte {at} unreadable ({said}); skipped']
    bag.check_chunks()
    assert len(bag.problems) == 1


def test_a_message_index_that_points_elsewhere_walks_its_chunk(tmp_path):
    """
    A message index that points elsewhere walks its chunk.

    An entry of a chunk's message index moved by one byte: said, the chunk walked, every
    message read (as the mcap library's stream reader, which needs no index, reads them).
    """
    data = bytearray(notes_bag(tmp_path / 'whole.mcap').read_bytes())
    records = top_level(bytes(data))
    chunk = [o for o, op, _ in records if op == 0x06][1]
    index = next(o for o, op, _ in records if o > chunk and op == 0x07 and
                 struct.unpack_from('<H', data, o + 9)[0] == 1)
    offset, = struct.unpack_from('<Q', data, index + 9 + 6 + 8 + 16)   # its second entry
    struct.pack_into('<Q', data, index + 9 + 6 + 8 + 16, offset + 1)
    path = tmp_path / 'moved.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    assert got == stream_messages(bytes(data), '/n') and len(got) == 40
    assert bag.problems == [f'chunk at byte {chunk}: message index of /n does not point at its '
                            'messages; chunk walked instead']


def joint_rows_by_rosbags(path, joint='gantry_joint', skip=None):
    """
    Return the JointStates rows as rosbags reads them.

    ((stamp, log time, angle, speed) of each JointState rosbags decodes, by log time;
    how many it cannot decode), from the mcap library's reading of /joint_states; those
    naming ``skip`` left out.
    """
    from rosbags.serde import SerdeError
    rows, failed = [], 0
    with open(path, 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            if channel.topic != '/joint_states':
                continue
            try:
                m = TYPESTORE.deserialize_cdr(message.data, JOINT)
            except SerdeError:
                failed += 1
                continue
            if skip in m.name:
                continue
            i = list(m.name).index(joint)
            rows.append((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, message.log_time,
                         m.position[i], m.velocity[i]))
    return sorted(rows, key=lambda row: row[1]), failed


@pytest.mark.parametrize('strided', [True, False], ids=['strided', 'gathered'])
def test_joint_states_of_one_length_and_other_layouts_are_told_apart(strided, tmp_path):
    """
    Read JointStates of one length (104 bytes) whose joint is elsewhere, and unreadable ones.

    Kinds in a seeded random order: the joint first or second of two names, and two
    positions and speeds; one position and three speeds; three positions and one speed;
    a message whose name count says 1000 (unreadable: rejected); one whose second name
    differs from the joint's in its last letter (skipped). One chunk, the
    records one after the other (``strided``: read through strided views) or between
    String messages of other lengths (gathered; log times a permutation starting with the
    smallest: the message index lists them in that order). Every row equals rosbags'
    decoding (the joint picked by name), in log-time order; the unreadable ones counted;
    nothing else said.
    """
    rng = np.random.default_rng(5)
    kinds = np.concatenate([[1], rng.integers(0, 6, 63)])   # the first group's: every kind
    log_times = 1_000 + (np.arange(64) if strided else           # the index's order
                         np.concatenate([[0], 1 + rng.permutation(63)]))
    messages, expected, bad, skipped = [], [], 0, 0
    for n, (kind, log) in enumerate(zip(kinds.tolist(), log_times.tolist())):
        q, w = 0.01 * n - 0.3, 2.0 + 0.5 * n
        names, position, velocity = [(['gantry_joint', 'tb'], [q, 9.0], [w, 8.0]),
                                     (['tb', 'gantry_joint'], [9.0, q], [8.0, w]),
                                     (['gantry_joint', 'tb'], [q], [w, 8.0, 7.0]),
                                     (['gantry_joint', 'tb'], [q, 9.0, 8.0], [w]),
                                     (['gantry_joint', 'tb'], [q, 9.0], [w, 8.0]),
                                     (['tb', 'gantry_joinx'], [9.0, q], [8.0, w])][kind]
        data = bytearray(joint_state(100 + n, 7 * n, 'f', names, position, velocity))
        assert len(data) == 104
        if kind == 4:
            struct.pack_into('<I', data, 20, 1000)        # the name count
            bad += 1
        elif kind == 5:
            skipped += 1
        else:
            expected.append(((100 + n) * 10**9 + 7 * n, log, q, w))
        messages.append(('/joint_states', log, bytes(data)))
        if not strided:
            messages.append(('/note', log, TYPESTORE.serialize_cdr(
                TYPESTORE.types[STRING](data='x' * (n % 7)), STRING).tobytes()))
    path = write_with_mcap_library(tmp_path / 'joints.mcap',
                                   {'/joint_states': JOINT, '/note': STRING}, messages,
                                   chunk_size=1 << 20)
    expected.sort(key=lambda row: row[1])
    assert joint_rows_by_rosbags(path, skip='gantry_joinx') == (expected, bad) and bad >= 5
    bag = Bag(path)
    assert len(bag.chunks) == 1
    motion = joint_samples(bag, bag.channel('/joint_states', JOINT), 'gantry_joint')
    assert list(zip(motion.stamp.tolist(), motion.log_time.tolist(), motion.angle.tolist(),
                    motion.omega.tolist())) == expected
    assert (motion.rejected, motion.skipped) == (bad, skipped) and skipped >= 5
    assert motion.joints_seen == ['gantry_joinx', 'tb']
    assert motion.reasons == [f'{bad} /joint_states messages not readable as JointState with '
                              'position and velocity']
    good = write_with_mcap_library(tmp_path / 'good.mcap', {'/joint_states': JOINT},
                                   [m for m, k in zip(messages[::1 if strided else 2], kinds)
                                    if k < 4])
    motion = joint_samples(Bag(good), Bag(good).channel('/joint_states', JOINT), 'gantry_joint')
    assert len(motion.stamp) == len(expected) and motion.reasons == [] and \
        motion.rejected == 0


def test_more_publishers_in_a_chunk_than_are_gathered_at_once(tmp_path):
    """
    More publishers in a chunk than are gathered at once.

    Twenty publishers (frames of 0 to 19 letters) on one topic in one chunk: the first 16
    layouts gathered at once, the others message by message; every row as rosbags decodes
    it, the one unreadable message counted.
    """
    from cvc_balance.bag.mcap_reader import LAYOUTS
    assert LAYOUTS == 16
    rng = np.random.default_rng(8)
    messages, expected = [], []
    for n, publisher in enumerate(rng.integers(0, 20, 200).tolist()):
        q, w = 0.001 * n, 1.0 + n
        data = joint_state(50 + n, n, 'f' * publisher, ['gantry_joint'], [q], [w])
        if n == 150:
            data = data[:40]                   # a message cut short: unreadable
        else:
            expected.append(((50 + n) * 10**9 + n, 5_000 + n, q, w))
        messages.append(('/joint_states', 5_000 + n, data))
    path = write_with_mcap_library(tmp_path / 'many.mcap', {'/joint_states': JOINT},
                                   messages, chunk_size=1 << 20)
    assert joint_rows_by_rosbags(path) == (expected, 1)
    bag = Bag(path)
    motion = joint_samples(bag, bag.channel('/joint_states', JOINT), 'gantry_joint')
    assert list(zip(motion.stamp.tolist(), motion.log_time.tolist(), motion.angle.tolist(),
                    motion.omega.tolist())) == expected
    assert (motion.rejected, motion.skipped) == (1, 0)


def built(*records):
    """Return the bytes of ``records`` (the mcap library's record classes), one after the other."""
    from mcap.data_stream import RecordBuilder
    out = b''
    for record in records:
        builder = RecordBuilder()
        record.write(builder)
        out += builder.end()
    return out


def string_record(channel, log_time, text):
    """Return a Message record (the mcap library's) of a std_msgs/String serialised by rosbags."""
    from mcap.records import Message
    return Message(channel_id=channel, sequence=0, log_time=log_time, publish_time=log_time,
                   data=TYPESTORE.serialize_cdr(TYPESTORE.types[STRING](data=text),
                                                STRING).tobytes())


def hand_built_file(chunks, loose_before=(), loose_after=(), compress=None, crc=True,
                    indexes=True, summary=False):
    """
    Return a recording built record by record.

    A recording built record by record (the mcap library's records): Header, Schema,
    Channels 1 (/n) and 2 (/m), loose messages, chunks of messages ({id: [(time, text)]}
    each; compressed by ``compress`` (name, function) if given, their CRC or 0, with
    message indexes or not), loose messages, DataEnd, a summary of the Schema and the
    Channels (``summary``) or none, the Footer.
    """
    import zlib
    from mcap.records import Channel, Chunk, DataEnd, Footer, Header, MessageIndex, Schema
    out = MAGIC + built(Header(profile='ros2', library='by hand'),
                        Schema(id=1, name=STRING, encoding='ros2msg', data=b''),
                        Channel(id=1, schema_id=1, topic='/n', message_encoding='cdr',
                                metadata={}),
                        Channel(id=2, schema_id=1, topic='/m', message_encoding='cdr',
                                metadata={}))
    out += built(*(string_record(1, t, text) for t, text in loose_before))
    for chunk in chunks:
        records, index = b'', {}
        for channel, messages in chunk.items():
            for t, text in messages:
                index.setdefault(channel, []).append((t, len(records)))
                records += built(string_record(channel, t, text))
        name, pack = compress or ('', lambda data: data)
        times = [t for messages in chunk.values() for t, _ in messages]
        out += built(Chunk(message_start_time=min(times), message_end_time=max(times),
                           uncompressed_size=len(records),
                           uncompressed_crc=zlib.crc32(records) if crc else 0,
                           compression=name, data=pack(records)))
        if indexes:
            out += built(*(MessageIndex(channel_id=c, records=entries)
                           for c, entries in index.items()))
    out += built(*(string_record(1, t, text) for t, text in loose_after))
    out += built(DataEnd(data_section_crc=0))
    start = len(out) if summary else 0
    if summary:
        out += built(Schema(id=1, name=STRING, encoding='ros2msg', data=b''),
                     *(Channel(id=i, schema_id=1, topic=topic, message_encoding='cdr',
                               metadata={}) for i, topic in ((1, '/n'), (2, '/m'))))
    return out + built(Footer(summary_start=start, summary_offset_start=0,
                              summary_crc=0)) + MAGIC


MAGIC = b'\x89MCAP0\r\n'


def test_messages_outside_chunks_come_in_file_order(tmp_path):
    """
    Messages outside chunks come in file order.

    Loose messages before, between (none) and after chunks, and chunks without a message
    of one channel: every channel's messages in file order, as the mcap library's stream
    reader reads them, with and without message indexes (and then with the channels in
    a summary: the chunks are walked only when read).
    """
    for indexes, summary in ((True, False), (False, False), (False, True)):
        data = hand_built_file([{1: [(20, 'c1'), (21, 'c2')], 2: [(22, 'm1')]},
                                {2: [(30, 'm2')]}, {1: [(40, 'd1')]}],
                               loose_before=[(10, 'a'), (11, 'b')],
                               loose_after=[(50, 'e')], indexes=indexes, summary=summary)
        path = tmp_path / 'loose.mcap'
        path.write_bytes(data)
        bag = Bag(path)
        assert bag.problems == []
        for topic, texts in (('/n', ['a', 'b', 'c1', 'c2', 'd1', 'e']), ('/m', ['m1', 'm2'])):
            theirs = read_before_the_cut(data, topic)
            assert [TYPESTORE.deserialize_cdr(d, STRING).data for _, d in theirs] == texts
            assert bag.messages(bag.channel(topic, STRING)) == theirs, (topic, indexes)


def test_a_zstd_chunk_without_its_content_size_and_a_chunk_without_a_crc(tmp_path):
    """
    A zstd chunk without its content size and a chunk without a crc.

    A zstd frame that does not state its size (the chunk record does) and a chunk whose
    CRC is 0 (none computed): both read, as the mcap library reads them.
    """
    import zstandard
    pack = zstandard.ZstdCompressor(write_content_size=False).compress
    data = hand_built_file([{1: [(1, 'one'), (2, 'two')]}, {1: [(3, 'three')]}],
                           compress=('zstd', pack), crc=False)
    path = tmp_path / 'sizeless.mcap'
    path.write_bytes(data)
    bag = Bag(path)
    assert bag.problems == [] and [c.crc for c in bag.chunks] == [0, 0]
    assert bag.messages(bag.channel('/n', STRING)) == read_before_the_cut(data)
    assert len(read_before_the_cut(data)) == 3


def test_a_chunk_without_a_crc_found_by_its_chunk_index(tmp_path):
    """
    A chunk without a crc found by its chunk index.

    test_records_the_walk_cannot_take_are_found_by_the_summarys_indexes with a CRC of 0
    in the chunk the walk cannot take: its records are checked whole instead, and read.
    """
    path = notes_bag(tmp_path / 'whole.mcap', compression=CompressionType.NONE)
    data = bytearray(path.read_bytes())
    records = top_level(bytes(data))
    chunk = [o for o, op, _ in records if op == 0x06][2]
    struct.pack_into('<I', data, chunk + 9 + 24, 0)
    data[chunk] = 0x05
    damaged = tmp_path / 'damaged.mcap'
    damaged.write_bytes(bytes(data))
    bag, got = ours(damaged)
    assert got == indexed_messages(path.read_bytes()) and len(got) == 40
    assert bag.problems == ["1 chunks read where the summary's chunk indexes put them (the "
                            'walk did not reach them whole)']


def test_a_message_index_naming_a_channel_not_in_its_chunk(tmp_path):
    """
    A message index naming a channel not in its chunk.

    The second chunk's message index of /n relabelled /m (whose messages the chunk lacks):
    /m read first walks that chunk (said); then both channels are whole, as the mcap
    library's stream reader reads them.
    """
    data = bytearray(hand_built_file([{1: [(1, 'a')], 2: [(2, 'm')]}, {1: [(3, 'b')]},
                                      {2: [(4, 'n')], 1: [(5, 'c')]}]))
    records = top_level(bytes(data))
    chunk = [o for o, op, _ in records if op == 0x06][1]
    index = next(o for o, op, _ in records if o > chunk and op == 0x07)
    struct.pack_into('<H', data, index + 9, 2)
    path = tmp_path / 'relabelled.mcap'
    path.write_bytes(bytes(data))
    bag = Bag(path)
    assert bag.messages(bag.channel('/m', STRING)) == read_before_the_cut(bytes(data), '/m')
    assert bag.messages(bag.channel('/n', STRING)) == read_before_the_cut(bytes(data), '/n')
    assert len(read_before_the_cut(bytes(data), '/n')) == 3
    assert bag.problems == [f'chunk at byte {chunk}: message index of /m does not point at its '
                            'messages; chunk walked instead']


def test_a_damaged_chunk_the_walk_cannot_take_is_said(tmp_path):
    """
    A damaged chunk the walk cannot take is said.

    A chunk's opcode flipped to a message's and a byte of its data flipped: the walk does
    not take it and its chunk index finds no whole chunk there. Said (it was lost without
    a word); every other message read, as the mcap library's stream reader reads the file
    without that chunk.
    """
    whole = notes_bag(tmp_path / 'whole.mcap').read_bytes()
    at, length = [(o, n) for o, op, n in top_level(whole) if op == 0x06][1]
    data = bytearray(whole)
    data[at] = 0x05
    data[at + 9 + length // 2] ^= 0xFF
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    expected = read_before_the_cut(whole[:at] + whole[at + 9 + length:])
    assert got == expected and 0 < len(expected) < 40
    assert bag.problems == [f"chunk at byte {at} (from the summary's chunk index) unreadable "
                            '(not a whole chunk whose CRC holds); skipped']


# -- the survivors the third session left (issue 29, fourth session) ----------------------

def test_a_damaged_record_with_no_whole_record_after_it_stops_the_walk(tmp_path):
    """
    Stop the walk at a damaged record of the data section that nothing whole follows.

    The last chunk's records length says one byte more than its record holds: no whole
    record after it (message indexes, the data end and the footer are no place to go on
    at), so the walk stops there, saying so in the words for a data-section record; the
    messages are those the mcap library's stream reader reads before that chunk.
    """
    data = bytearray(hand_built_file([{1: [(1, 'a'), (2, 'b')]},
                                      {1: [(5, 'c')], 2: [(7, 'm')]}]))
    at = [o for o, op, _ in top_level(bytes(data)) if op == 0x06][1]
    assert data[at + 37:at + 41] == b'\x00\x00\x00\x00'       # no compression: length 0
    records_length, = struct.unpack_from('<Q', data, at + 41)
    struct.pack_into('<Q', data, at + 41, records_length + 1)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    assert got == read_before_the_cut(bytes(data[:at])) and len(got) == 2
    assert bag.problems == [f'corrupt record (opcode 0x06) at byte {at}: chunk data beyond its '
                            'record; stopped reading there']


def test_a_message_right_after_a_chunk_found_by_its_index_is_kept(tmp_path):
    """
    Keep a message outside chunks that starts where a chunk found by its index ends.

    The chunk's opcode flipped to a message's: the walk takes the chunk for a message
    outside chunks, the summary's chunk index (added by hand) finds the chunk, and that
    false message is dropped; the true one right after the chunk's end is kept. /n: the
    chunk's two messages and that one, as the mcap library's stream reader reads the
    undamaged file.
    """
    from mcap.records import ChunkIndex
    whole = hand_built_file([{1: [(10, 'c1'), (11, 'c2')]}], loose_after=[(20, 'e')],
                            indexes=False, summary=True)
    records = top_level(whole)
    at, length = next((o, n) for o, op, n in records if op == 0x06)
    assert next(op for o, op, _ in records if o == at + 9 + length) == 0x05
    records_length, = struct.unpack_from('<Q', whole, at + 41)
    index = built(ChunkIndex(chunk_length=9 + length, chunk_start_offset=at, compression='',
                             compressed_size=records_length, message_end_time=11,
                             message_index_length=0, message_index_offsets={},
                             message_start_time=10, uncompressed_size=records_length))
    footer = len(whole) - len(MAGIC) - 29
    data = bytearray(whole[:footer] + index + whole[footer:])
    data[at] = 0x05
    path = tmp_path / 'flipped.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    expected = read_before_the_cut(whole)
    assert [TYPESTORE.deserialize_cdr(d, STRING).data for _, d in expected] == ['c1', 'c2', 'e']
    assert got == expected
    assert bag.loose_messages() == [(1, at + 9 + length)]
    assert bag.problems == ["1 chunks read where the summary's chunk indexes put them (the "
                            'walk did not reach them whole)']


def test_a_chunk_without_a_crc_whose_records_are_not_whole_is_not_taken(tmp_path):
    """
    Skip a CRC-less chunk whose records do not fill it, when its length field is damaged.

    The second of three uncompressed chunks without a CRC: a message's length inside it
    one byte longer (its records no longer fill the chunk) and the chunk's length field
    1 MiB longer than the file. Nothing checks such a chunk but its records: it is not
    read by its fields; the walk goes on at the next chunk (bytes by hand), and the
    messages are those the mcap library's stream reader reads from the file without it.
    """
    data = bytearray(hand_built_file([{1: [(1, 'a')]}, {1: [(2, 'b'), (5, 'c')]},
                                      {1: [(7, 'd')]}], crc=False))
    chunks = [(o, n) for o, op, n in top_level(bytes(data)) if op == 0x06]
    (at, length), (following, _) = chunks[1], chunks[2]
    second = at + 49 + 41          # its second message: after the first (41 bytes)
    assert data[second] == 0x05 and struct.unpack_from('<Q', data, second + 1)[0] == 32
    struct.pack_into('<Q', data, second + 1, 33)
    struct.pack_into('<Q', data, at + 1, length + (1 << 20))
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    expected = read_before_the_cut(bytes(data[:at] + data[following:]))
    assert [TYPESTORE.deserialize_cdr(d, STRING).data for _, d in expected] == ['a', 'd']
    assert got == expected
    assert bag.problems == [f'record (opcode 0x06) at byte {at} runs past the end of the file: '
                            f'{following - at} bytes skipped to the next whole record at byte '
                            f'{following}']


def test_joint_states_without_the_joint_of_several_layouts_are_all_counted(tmp_path):
    """
    Count the skipped and rejected JointStates of every layout; name at most 20 joints.

    One chunk: JointStates naming 25 other joints (3), two other joints (2), the joint
    without a velocity (2, and 3 more of another length), and the joint whole (6). The
    counts are rosbags' (the joint not among the names: skipped; no velocity at its
    index: rejected); the joints named are the first 20 of the first message without the
    joint (until 20 are known, none are added).
    """
    many = [f'j{k:02d}' for k in range(25)]
    kinds = [(many, [0.0] * 25, [0.0] * 25)] * 3 + [(['a', 'b'], [0.0, 0.0], [0.0, 0.0])] * 2 \
        + [(['gantry_joint'], [0.5], [])] * 2 + [(['gantry_joint', 'x'], [0.5, 1.0], [])] * 3
    order = [0, 5, 10, 3, 6, 1, 11, 7, 12, 4, 8, 2, 13, 9, 14, 15]
    good = [(['gantry_joint'], [0.1 * k], [2.0 + k]) for k in range(6)]
    everything = kinds + good
    messages = [('/joint_states', 1_000 + n,                # stamps of 2023: over 2^53 ns
                 joint_state(1_700_000_000 + n, 123_456_789 + n, 'f', *everything[k]))
                for n, k in enumerate(order)]
    path = write_with_mcap_library(tmp_path / 'joints.mcap', {'/joint_states': JOINT},
                                   messages, chunk_size=1 << 20)
    rows, skipped, rejected = [], 0, 0
    with open(path, 'rb') as stream:
        for _, _, m in make_reader(stream).iter_messages():
            state = TYPESTORE.deserialize_cdr(m.data, JOINT)
            if 'gantry_joint' not in state.name:
                skipped += 1
                continue
            i = list(state.name).index('gantry_joint')
            if len(state.velocity) <= i:
                rejected += 1
                continue
            rows.append((state.header.stamp.sec * 10**9 + state.header.stamp.nanosec,
                         m.log_time, state.position[i], state.velocity[i]))
    assert (skipped, rejected, len(rows)) == (5, 5, 6)
    bag = Bag(path)
    assert len(bag.chunks) == 1
    motion = joint_samples(bag, bag.channel('/joint_states', JOINT), 'gantry_joint')
    assert (motion.skipped, motion.rejected) == (skipped, rejected)
    assert motion.joints_seen == many[:20]
    assert list(zip(motion.stamp.tolist(), motion.log_time.tolist(), motion.angle.tolist(),
                    motion.omega.tolist())) == rows


def test_which_topic_a_name_chooses_and_the_refusals():
    """
    Choose a topic by its name, with or without '/', or by the one topic ending in it.

    By hand: the name itself first (a namespaced one then does not count); else the only
    topic ending in '/' + name (not with ``exact``); none: None. Two matching topics, a
    topic without a schema of the wrong type, a bag of no topic: the words people read,
    with the option that chooses one when there is one.
    """
    from cvc_balance.bag.mcap_reader import (BagError, ChannelInfo, describe_topics,
                                             select_channel)
    speed = ChannelInfo(1, '/speed', FLOAT64, 'cdr')
    spaced = ChannelInfo(2, '/gantry/joint_states', JOINT, 'cdr')
    other = ChannelInfo(3, '/arm/joint_states', JOINT, 'cdr')
    plain = ChannelInfo(4, 'joint_states/', JOINT, 'cdr')
    assert select_channel([speed, spaced], '/speed/', FLOAT64, 'x') is speed
    assert select_channel([speed, spaced], 'joint_states', JOINT, 'x') is spaced
    assert select_channel([speed, spaced], 'joint_states', JOINT, 'x', exact=True) is None
    assert select_channel([spaced, other, plain], '/joint_states', JOINT, 'x') is plain
    assert select_channel([speed], 'states', JOINT, 'x') is None
    upper = ChannelInfo(6, '/speedX', FLOAT64, 'cdr')       # only '/' is taken off the ends
    assert select_channel([speed, upper], 'speedX', FLOAT64, 'x') is upper
    assert select_channel([speed, upper], 'speed', FLOAT64, 'x') is speed
    for option, said in ((None, ''), ('--joint-states', ' with --joint-states')):
        with pytest.raises(BagError) as refused:
            select_channel([speed, spaced, other], 'joint_states', JOINT, 'x.mcap', option)
        assert str(refused.value) == ('x.mcap: several topics match joint_states: '
                                      f'/arm/joint_states, /gantry/joint_states; choose one{said}')
    with pytest.raises(BagError) as refused:
        select_channel([ChannelInfo(5, '/speed', '', 'cdr')], 'speed', FLOAT64, 'x.mcap')
    assert str(refused.value) == ('x.mcap: topic /speed has type (none), expected '
                                  f'{FLOAT64}; the bag has: /speed (no schema)')
    assert describe_topics([]) == 'none'


def test_a_bags_topic_chosen_with_its_option(tmp_path):
    """Bag.channel: the bag's path in the words, the option named, ``exact`` kept."""
    from cvc_balance.bag.mcap_reader import BagError
    path = write_with_mcap_library(
        tmp_path / 'two.mcap', {'/a/n': STRING, '/b/n': STRING, '/c/m': STRING},
        [('/a/n', 1, b'\x00\x01\x00\x00\x01\x00\x00\x00\x00')])
    bag = Bag(path)
    assert bag.channel('m', STRING).topic == '/c/m' and bag.channel('m', STRING, exact=True) \
        is None
    with pytest.raises(BagError) as refused:
        bag.channel('n', STRING, '--note-topic')
    assert str(refused.value) == (f'{path}: several topics match n: /a/n, /b/n; choose one '
                                  'with --note-topic')


def test_columns_grow_to_take_more_rows_than_they_were_made_for():
    """Rows taken past the capacity (none, one) keep what was filled, in order, and dtypes."""
    from cvc_balance.bag.mcap_reader import _Columns
    for capacity, counts in ((0, (3, 2, 4)), (1, (1, 1, 3))):
        columns = _Columns((np.int64, float), capacity)
        rows = 0
        for count in counts:
            whole, real = columns.take(count)
            whole[:] = np.arange(rows, rows + count) + 2**60
            real[:] = np.arange(rows, rows + count) * 0.5
            rows += count
        whole, real = columns.filled()
        assert whole.dtype == np.int64 and whole.tolist() == [2**60 + k for k in range(rows)]
        assert real.tolist() == [0.5 * k for k in range(rows)]


def test_float64_messages_spaced_unevenly_are_not_read_as_evenly_spaced(tmp_path):
    """
    Read Float64s whose records are 100, 90 and 110 bytes apart (on average 100).

    Between them String records of 57, 47 and 67 bytes (the Float64 records are 43): the
    first and last offsets are three average steps apart, but the steps differ. The
    values and log times are the mcap library's, decoded by rosbags.
    """
    def note(k):
        data = TYPESTORE.serialize_cdr(TYPESTORE.types[STRING](data='x' * k), STRING)
        assert 31 + len(data) == k + 40
        return data.tobytes()
    messages = []
    for n, k in enumerate((17, 7, 27, None)):
        messages.append(('/speed', 10 + n, float64(1.5 * n - 1.0)))
        if k is not None:
            messages.append(('/note', 10 + n, note(k)))
    path = write_with_mcap_library(tmp_path / 'uneven.mcap', {'/speed': FLOAT64,
                                                              '/note': STRING}, messages)
    with open(path, 'rb') as stream:
        theirs = [(m.log_time, TYPESTORE.deserialize_cdr(m.data, FLOAT64).data)
                  for _, _, m in make_reader(stream).iter_messages(topics=['/speed'])]
    bag = Bag(path)
    assert len(bag.chunks) == 1
    offsets = bag.chunks[0].indexes[bag.channel('/speed', FLOAT64).id]
    assert np.diff(offsets).tolist() == [100, 90, 110]
    times, values = float64_samples(bag, bag.channel('/speed', FLOAT64))
    assert list(zip(times.tolist(), values.tolist())) == theirs and len(theirs) == 4


def test_a_message_index_pointing_past_its_chunk_walks_it(tmp_path):
    """
    Walk a chunk whose message index points at its last byte (a message cannot start there).

    Said, and every message read as the mcap library's stream reader reads them.
    """
    data = bytearray(notes_bag(tmp_path / 'whole.mcap', compression=CompressionType.NONE)
                     .read_bytes())
    records = top_level(bytes(data))
    chunk = [o for o, op, _ in records if op == 0x06][1]
    records_length, = struct.unpack_from('<Q', data, chunk + 41)
    index = next(o for o, op, _ in records if o > chunk and op == 0x07 and
                 struct.unpack_from('<H', data, o + 9)[0] == 1)
    struct.pack_into('<Q', data, index + 9 + 6 + 8 + 16, records_length - 1)
    path = tmp_path / 'past.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    assert got == stream_messages(bytes(data), '/n') and len(got) == 40
    assert bag.problems == [f'chunk at byte {chunk}: message index of /n does not point at its '
                            'messages; chunk walked instead']


def test_what_a_bag_keeps_of_its_records_for_a_rewrite(tmp_path):
    """
    Keep the header, each definition and attachment as the file has them, ids up to 2^16.

    A file built record by record: a Channel (id 40000) before its Schema (id 40001), a
    channel without a schema (schema id 0), an Attachment, loose messages (one of no
    data at all, the shortest message record; two at one log time, in file order against
    the order of their texts). By hand from the file's top-level records: the Header's
    bytes, each Schema's and Channel's record, the attachment's offset and length, each
    channel (its type from the later Schema; '' without one), how many messages it has,
    and the texts in log-time order (ties in file order), as the mcap library's stream
    reader reads them. A file without a Header record: no header; its messages counted,
    loose and in a chunk.
    """
    from mcap.records import Attachment, Channel, DataEnd, Footer, Header, Message, Schema
    from cvc_balance.bag.mcap_reader import ChannelInfo
    texts = [(30, 'b'), (30, 'a'), (20, 'z')]
    data = MAGIC + built(
        Header(profile='ros2', library='by hand'),
        Channel(id=40000, schema_id=40001, topic='/n', message_encoding='cdr', metadata={}),
        Schema(id=40001, name=STRING, encoding='ros2msg', data=b''),
        Channel(id=7, schema_id=0, topic='/raw', message_encoding='', metadata={}),
        Attachment(create_time=1, log_time=2, name='notes.txt', media_type='text/plain',
                   data=b'hello'),
        *(string_record(40000, t, text) for t, text in texts),
        Message(channel_id=7, sequence=0, log_time=40, publish_time=40, data=b''),
        DataEnd(data_section_crc=0),
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0)) + MAGIC
    path = tmp_path / 'records.mcap'
    path.write_bytes(data)
    records = top_level(data)
    whole = {op: [data[o:o + 9 + n] for o, o2, n in records if o2 == op] for _, op, _ in records}
    attachment, = [(o, 9 + n) for o, op, n in records if op == 0x09]
    bag = Bag(path)
    assert bag.problems == []
    assert bag.header == whole[0x01][0] and bag.attachments == [attachment]
    assert bag.definitions == {(0x04, 40000): whole[0x04][0], (0x03, 40001): whole[0x03][0],
                               (0x04, 7): whole[0x04][1]}
    assert bag.channels == {40000: ChannelInfo(40000, '/n', STRING, 'cdr', 40001),
                            7: ChannelInfo(7, '/raw', '', '', 0)}
    note, raw = bag.channels[40000], bag.channels[7]
    assert (bag.message_count(note), bag.message_count(raw)) == (3, 1)
    assert bag.messages(raw) == [(40, b'')] == read_before_the_cut(data, '/raw')
    assert bag.messages(note) == read_before_the_cut(data)
    assert string_samples(bag, note) == [(20, 'z'), (30, 'b'), (30, 'a')]
    full = hand_built_file([{1: [(20, 'c'), (21, 'd')]}], loose_before=[(10, 'e')])
    (_, _, length), = [r for r in top_level(full) if r[1] == 0x01]
    headless = tmp_path / 'headless.mcap'          # no Header record; messages in a chunk
    headless.write_bytes(full[:8] + full[8 + 9 + length:])
    bag = Bag(headless)
    assert bag.header is None and bag.problems == []
    assert bag.message_count(bag.channel('/n', STRING)) == len(read_before_the_cut(full)) == 3


@pytest.mark.parametrize('damaged', ['message index', 'metadata', 'metadata value'])
def test_an_index_or_metadata_record_whose_fields_overrun_it(damaged, tmp_path):
    """
    Skip a message index whose entries, or a metadata record whose map, overrun the record.

    The first chunk's message index says 16 bytes more of entries than it holds, or a
    metadata record before the chunks says its map, or the value in its map, is a byte
    longer (the map ends with the record: the value would end past both): said in the words for
    that record (bytes by hand), the walk going on at the next chunk; every message read,
    as the mcap library's stream reader reads the undamaged file (an index only locates
    messages: that chunk is walked).
    """
    from mcap.records import Metadata
    whole = hand_built_file([{1: [(1, 'a'), (2, 'b')]}, {1: [(5, 'c')]}])
    chunks = [o for o, op, _ in top_level(whole) if op == 0x06]
    if damaged.startswith('metadata'):
        whole = whole[:chunks[0]] + built(Metadata(name='m', metadata={'k': 'v'})) + \
            whole[chunks[0]:]
    records = top_level(whole)
    data = bytearray(whole)
    following = [o for o, op, _ in records if op == 0x06][0 if 'metadata' in damaged else 1]
    if damaged.startswith('metadata'):
        at = next(o for o, op, _ in records if op == 0x0C)
        field, why = ((at + 9 + 4 + 1, 'map beyond the record') if damaged == 'metadata' else
                      (at + 9 + 4 + 1 + 4 + 4 + 1, 'string beyond the record'))
        struct.pack_into('<I', data, field, struct.unpack_from('<I', data, field)[0] + 1)
    else:
        at = next(o for o, op, _ in records if op == 0x07)
        field, why = at + 9 + 2, 'message index entries beyond its record'
        struct.pack_into('<I', data, field, struct.unpack_from('<I', data, field)[0] + 16)
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    bag, got = ours(path)
    assert got == read_before_the_cut(whole) and len(got) == 3
    assert bag.problems == [f'corrupt record (opcode 0x{data[at]:02x}) at byte {at}: {why}: '
                            f'{following - at} bytes skipped to the next whole record at byte '
                            f'{following}']
    assert bag.metadata == []


def test_metadata_bytes_split_message_indexes_and_a_record_too_short_for_a_message(tmp_path):
    """
    Keep a metadata record's bytes, join a chunk's two message indexes of one channel.

    By hand from the top-level records: the metadata record as the file has it (a rewrite
    copies it); a chunk whose messages of /n are listed by two message index records (one
    entry each): both messages, where the entries say, as the mcap library's stream
    reader reads them; a record of a message's opcode one byte too short for one (21
    bytes) at the end of the data: no message.
    """
    from mcap.records import MessageIndex, Metadata
    whole = hand_built_file([{1: [(1, 'a'), (2, 'b')]}])
    records = top_level(whole)
    index, length = next((o, n) for o, op, n in records if op == 0x07)
    entries = struct.unpack_from('<QQQQ', whole, index + 9 + 6)
    split = built(MessageIndex(channel_id=1, records=[entries[:2]]),
                  MessageIndex(channel_id=1, records=[entries[2:]]))
    data_end = next(o for o, op, _ in records if op == 0x0F)
    metadata = built(Metadata(name='m', metadata={'k': 'v'}))
    short = record(0x05, struct.pack('<HIQ', 1, 0, 3) + bytes(7))
    data = whole[:index] + split + whole[index + 9 + length:data_end] + metadata + short + \
        whole[data_end:]
    path = tmp_path / 'split.mcap'
    path.write_bytes(data)
    at = next(o for o, op, _ in top_level(data) if op == 0x0C)
    bag = Bag(path)
    assert bag.problems == [] and bag.loose_messages() == []
    assert bag.metadata == [(at, 'm', {'k': 'v'}, data[at:at + len(metadata)])]
    assert bag.chunks[0].indexes[1].tolist() == [entries[1], entries[3]] == [0, 41]
    assert bag.messages(bag.channel('/n', STRING)) == read_before_the_cut(whole)
    assert len(read_before_the_cut(whole)) == 2


@pytest.mark.parametrize('last', ['channel', 'metadata'])
def test_a_damaged_length_of_the_record_ending_the_file(last, tmp_path):
    """
    Read by its fields a Channel or Metadata record that ends the file, its length damaged.

    A recording cut right after that record, whose length field says 1 MiB more: its own
    fields give its length, which ends exactly at the file's end; read by them (the topic,
    or the metadata and its bytes as written), said, and the recording said cut.
    """
    from mcap.records import Channel, Header, Metadata, Schema
    if last == 'channel':
        final = built(Channel(id=1, schema_id=1, topic='/n', message_encoding='cdr',
                              metadata={'k': 'v'}))
    else:
        final = built(Metadata(name='m', metadata={'k': 'v'}))
    start = MAGIC + built(Header(profile='ros2', library='by hand'),
                          Schema(id=1, name=STRING, encoding='ros2msg', data=b''))
    data = bytearray(start + final)
    at, length = len(start), len(final) - 9
    struct.pack_into('<Q', data, at + 1, length + (1 << 20))
    path = tmp_path / 'cut.mcap'
    path.write_bytes(bytes(data))
    bag = Bag(path)
    if last == 'channel':
        assert bag.topics() == {'/n': STRING}
    else:
        assert bag.metadata == [(at, 'm', {'k': 'v'}, final)]
    assert bag.problems == [f'record (opcode 0x{final[0]:02x}) at byte {at} runs past the end '
                            f'of the file: its length field ({length + (1 << 20)}) is damaged, '
                            f'its fields give {length}: read by them',
                            'file has no end of data (truncated recording?)']


def test_a_schema_found_in_a_later_chunk_than_the_first_opened(tmp_path):
    """
    Look for a channel's schema chunk by chunk until it is found, not only in the first.

    The summary repeats the channel (id 40000, beyond 2^15), not its schema; the schema is
    in the second chunk only. Both chunks' messages by their message indexes, as the mcap
    library's stream reader reads them, and the channel's type from that schema.
    """
    import zlib
    from mcap.records import (Channel, Chunk, DataEnd, Footer, Header, MessageIndex,
                              Schema)
    channel = Channel(id=40000, schema_id=1, topic='/n', message_encoding='cdr', metadata={})
    out = MAGIC + built(Header(profile='ros2', library='by hand'))
    for chunk, (first, extra) in enumerate((((1, 'a'), b''),
                                            ((2, 'b'), built(Schema(id=1, name=STRING,
                                                                    encoding='ros2msg',
                                                                    data=b''))))):
        records = (built(channel) if chunk == 0 else b'') + extra
        offset = len(records)
        records += built(string_record(40000, *first))
        out += built(Chunk(message_start_time=first[0], message_end_time=first[0],
                           uncompressed_size=len(records), uncompressed_crc=zlib.crc32(records),
                           compression='', data=records))
        out += built(MessageIndex(channel_id=40000, records=[(first[0], offset)]))
    out += built(DataEnd(data_section_crc=0))
    summary = len(out)
    out += built(channel, Footer(summary_start=summary, summary_offset_start=0,
                                 summary_crc=0)) + MAGIC
    path = tmp_path / 'late.mcap'
    path.write_bytes(out)
    bag = Bag(path)
    assert bag.problems == [] and bag.topics() == {'/n': STRING}
    assert bag.messages(bag.channel('/n', STRING)) == read_before_the_cut(out)
    assert len(read_before_the_cut(out)) == 2


def test_message_indexes_pointing_at_records_that_are_not_whole_messages(tmp_path):
    """
    Trust a message index only where it points at whole messages of its channel.

    Three chunks, each indexed entry by entry by hand: a message and one of no data at all
    (22 bytes, the shortest, ending the chunk): both read, nothing said; a message and a
    record of a message's opcode one byte too short for one (21 bytes), then a message; a
    message and one whose length field says a byte more than its chunk holds: those two
    chunks walked (said), their whole messages read.
    """
    import zlib
    from mcap.records import (Channel, Chunk, DataEnd, Footer, Header, Message,
                              MessageIndex, Schema)
    out = MAGIC + built(Header(profile='ros2', library='by hand'),
                        Schema(id=1, name=STRING, encoding='ros2msg', data=b''),
                        Channel(id=1, schema_id=1, topic='/n', message_encoding='cdr',
                                metadata={}))
    first = built(string_record(1, 1, 'a'))
    empty = built(Message(channel_id=1, sequence=0, log_time=2, publish_time=2, data=b''))
    short = record(0x05, struct.pack('<HIQ', 1, 0, 3) + bytes(7))
    over = bytearray(built(string_record(1, 4, 'd')))
    struct.pack_into('<Q', over, 1, len(over) - 9 + 1)
    chunks = []
    after = built(string_record(1, 5, 'e'))          # so the short record does not end it
    for second in (empty, short + after, bytes(over)):
        records = first + second
        chunks.append(len(out))
        out += built(Chunk(message_start_time=1, message_end_time=4,
                           uncompressed_size=len(records), uncompressed_crc=zlib.crc32(records),
                           compression='', data=records))
        out += built(MessageIndex(channel_id=1, records=[(1, 0), (2, len(first))]))
    out += built(DataEnd(data_section_crc=0), Footer(summary_start=0, summary_offset_start=0,
                                                     summary_crc=0)) + MAGIC
    path = tmp_path / 'indexes.mcap'
    path.write_bytes(out)
    bag = Bag(path)
    a = TYPESTORE.serialize_cdr(TYPESTORE.types[STRING](data='a'), STRING).tobytes()
    e = TYPESTORE.serialize_cdr(TYPESTORE.types[STRING](data='e'), STRING).tobytes()
    assert bag.messages(bag.channel('/n', STRING)) == [(1, a), (2, b''), (1, a), (5, e), (1, a)]
    walked = [f'chunk at byte {at}: message index of /n does not point at its messages; chunk '
              'walked instead' for at in chunks[1:]]
    assert len(first) == len(over) == 41
    assert bag.problems == walked + [f"chunk at byte {chunks[2]}: a record runs past the "
                                     "chunk's end at byte 41 of its 82; the rest of the chunk "
                                     'skipped']
