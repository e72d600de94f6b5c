"""
The MCAP project's read-conformance files, read by the project's reader.

``test/data/mcap-conformance/`` is the ``tests/conformance/data`` set of the MCAP project
(github.com/foxglove/mcap, commit 95d067356, MIT licence, its LICENSE beside it):
every combination of chunking, message and chunk indexes, statistics, summary, summary
offsets, padding and repeated schemas and channels (416 files), each with the .json of the
records a conforming reader must find. The project was given the files as Git LFS pointers (sha256
and size); ``rebuild.py`` there writes each from its .json as the specification lays records
out, and every one matches its pointer's sha256: they are the MCAP project's files. Every
message of every file must come back: its channel, topic, log time and payload bytes, in file
order, and nothing reported as a problem.
"""

import hashlib
import json
from pathlib import Path

import pytest

from cvc_balance.bag.mcap_reader import Bag

DATA = Path(__file__).resolve().parent / 'data' / 'mcap-conformance'
FILES = sorted(DATA.rglob('*.mcap'))


def expected_records(path):
    """Return (schemas {id: name}, channels {id: (topic, schema id)}, messages) of a .json."""
    records = json.loads(path.with_suffix('.json').read_text())['records']
    schemas, channels, messages = {}, {}, []
    for record in records:
        fields = dict(record['fields'])
        if record['type'] == 'Schema':
            schemas[int(fields['id'])] = fields['name']
        elif record['type'] == 'Channel':
            channels[int(fields['id'])] = (fields['topic'], int(fields['schema_id']))
        elif record['type'] == 'Message':
            messages.append((int(fields['channel_id']), int(fields['log_time']),
                             bytes(int(b) for b in fields['data'])))
    return schemas, channels, messages


def test_every_conformance_file_is_there():
    assert len(FILES) == 416
    assert {f.parent.name for f in FILES} == {'NoData', 'OneAttachment', 'OneMessage',
                                              'OneMetadata', 'OneSchemalessMessage',
                                              'TenMessages'}
    assert all(f.with_suffix('.json').is_file() for f in FILES)
    sums = {}
    for line in (DATA / 'SHA256SUMS').read_text().splitlines():
        digest, size, name = line.split('  ')
        sums[name] = (digest, int(size))
    assert len(sums) == len(FILES)
    for path in FILES:     # the MCAP project's files, byte for byte
        data = path.read_bytes()
        assert (hashlib.sha256(data).hexdigest(), len(data)) == \
            sums[str(path.relative_to(DATA))], path.name


@pytest.mark.parametrize('group', sorted({f.parent.name for f in FILES}))
def test_reader_finds_every_message_of_the_conformance_files(group):
    files = [f for f in FILES if f.parent.name == group]
    checked = 0
    for path in files:
        schemas, channels, messages = expected_records(path)
        bag = Bag(path)
        assert bag.problems == [], path.name
        assert {i: c.topic for i, c in bag.channels.items()} == \
            {i: topic for i, (topic, _) in channels.items()}, path.name
        for i, (_, schema_id) in channels.items():
            assert bag.channels[i].msg_type == schemas.get(schema_id, ''), path.name
        got = [(channel.id, log_time, data) for channel in bag.channels.values()
               for log_time, data in bag.messages(channel)]
        # Per channel in file order (the files have one channel; the order is the file's).
        assert got == sorted(messages, key=lambda m: m[0]), path.name
        checked += 1
    assert checked == len(files) >= 6


def test_log_times_out_of_file_order_stay_in_file_order():
    """Log times of TenMessages go 0 2 1 3 3 5 4 7 8 9: messages() keeps the file's order."""
    path = DATA / 'TenMessages' / 'TenMessages-ch-chx-mx-pad-rch-rsh-st-sum.mcap'
    bag = Bag(path)
    (channel,) = bag.channels.values()
    assert [t for t, _ in bag.messages(channel)] == [0, 2, 1, 3, 3, 5, 4, 7, 8, 9]


def test_unknown_records_are_skipped_at_the_top_level_and_in_chunks(tmp_path):
    """
    Records of kinds the reader does not know (0x42, user opcode 0x80) are skipped by length.

    The file is built here from the specification's record layouts; the mcap library's
    own reader, which also skips unknown records, finds the same ten messages.
    """
    import struct
    import zlib
    from mcap.reader import make_reader

    def record(opcode, body):
        return struct.pack('<BQ', opcode, len(body)) + body

    def text(value):
        return struct.pack('<I', len(value)) + value.encode()

    unknown = record(0x42, b'\x01\x02\x03') + record(0x80, b'user data')
    chunk, offsets = bytearray(), []
    chunk += record(0x03, struct.pack('<H', 1) + text('Example') + text('c') +
                    struct.pack('<I', 3) + b'\x04\x05\x06')
    chunk += unknown
    chunk += record(0x04, struct.pack('<HH', 1, 1) + text('example') + text('a') +
                    struct.pack('<I', 0))
    for i in range(10):
        offsets.append(len(chunk))
        chunk += record(0x05, struct.pack('<HIQQ', 1, i, 100 + i, 100 + i) + bytes([i] * 5))
        if i == 4:
            chunk += unknown
    data = bytearray(b'\x89MCAP0\r\n')
    data += record(0x01, text('') + text(''))
    data += unknown
    data += record(0x06, struct.pack('<QQQI', 100, 109, len(chunk), zlib.crc32(chunk)) +
                   text('') + struct.pack('<Q', len(chunk)) + chunk)
    data += unknown
    entries = b''.join(struct.pack('<QQ', 100 + i, o) for i, o in enumerate(offsets))
    data += record(0x07, struct.pack('<HI', 1, len(entries)) + entries)
    data += unknown
    data += record(0x0F, struct.pack('<I', 0))
    data += unknown
    data += record(0x02, struct.pack('<QQI', 0, 0, 0)) + b'\x89MCAP0\r\n'
    path = tmp_path / 'unknown.mcap'
    path.write_bytes(bytes(data))
    with open(path, 'rb') as stream:
        theirs = [(m.log_time, m.data) for _, _, m in make_reader(stream).iter_messages()]
    bag = Bag(path)
    assert bag.problems == [] and bag.topics() == {'example': 'Example'}
    ours = bag.messages(bag.channels[1])
    assert ours == theirs == [(100 + i, bytes([i] * 5)) for i in range(10)]
    assert bag.chunks[0].indexes is not None and not bag.chunks[0].walked  # index kept
