"""
Rebuild the MCAP read-conformance files from their .json, byte for byte.

The MCAP project keeps its conformance .mcap files in Git LFS; the copy this
project was given held only the LFS pointers (sha256 and size of each file).
Each .json lists every record a reader must find, with every field (offsets,
CRCs, sizes) and the file's features; this script writes those records as
the MCAP specification lays them out (https://mcap.dev/spec), the way the
project's generator arranges them: one uncompressed chunk after the other
data records when chunked (``ch``), its message indexes (``mx``), the summary
records as the .json lists them, three bytes of padding (01 ff ff) after the
known fields of each top-level record that may be padded (``pad``; not the
Footer, Message, Chunk or DataEnd), and none inside the chunk.

Each rebuilt file must have the sha256 and size of its LFS pointer
(``SHA256SUMS``): then it is the MCAP project's file. Run from anywhere:

    python test/data/mcap-conformance/rebuild.py [--pointers]

``--pointers`` first reads the LFS pointer files in place into SHA256SUMS.
"""

import hashlib
import json
from pathlib import Path
import struct
import sys
import zlib

HERE = Path(__file__).resolve().parent
SUMS = HERE / 'SHA256SUMS'
MAGIC = b'\x89MCAP0\r\n'
OPCODES = {'Header': 0x01, 'Footer': 0x02, 'Schema': 0x03, 'Channel': 0x04, 'Message': 0x05,
           'Chunk': 0x06, 'MessageIndex': 0x07, 'ChunkIndex': 0x08, 'Attachment': 0x09,
           'AttachmentIndex': 0x0A, 'Statistics': 0x0B, 'Metadata': 0x0C,
           'MetadataIndex': 0x0D, 'SummaryOffset': 0x0E, 'DataEnd': 0x0F}
UNPADDED = {'Footer', 'Message', 'Chunk', 'DataEnd'}
PADDING = b'\x01\xff\xff'


def u8(v):
    return struct.pack('<B', int(v))


def u16(v):
    return struct.pack('<H', int(v))


def u32(v):
    return struct.pack('<I', int(v))


def u64(v):
    return struct.pack('<Q', int(v))


def text(v):
    data = v.encode('utf-8')
    return u32(len(data)) + data


def data_bytes(values):
    return bytes(int(b) for b in values)


def mapping(items, key, value):
    body = b''.join(key(k) + value(v) for k, v in items.items())
    return u32(len(body)) + body


def body(kind, f):
    """Serialise the fields of a record of ``kind`` (a dict of the .json's fields)."""
    if kind == 'Header':
        return text(f['profile']) + text(f['library'])
    if kind == 'Schema':
        data = data_bytes(f['data'])
        return u16(f['id']) + text(f['name']) + text(f['encoding']) + u32(len(data)) + data
    if kind == 'Channel':
        return (u16(f['id']) + u16(f['schema_id']) + text(f['topic']) +
                text(f['message_encoding']) + mapping(f['metadata'], text, text))
    if kind == 'Message':
        return (u16(f['channel_id']) + u32(f['sequence']) + u64(f['log_time']) +
                u64(f['publish_time']) + data_bytes(f['data']))
    if kind == 'Attachment':
        data = data_bytes(f['data'])
        fields = (u64(f['log_time']) + u64(f['create_time']) + text(f['name']) +
                  text(f['media_type']) + u64(len(data)) + data)
        return fields + u32(zlib.crc32(fields))
    if kind == 'Metadata':
        return text(f['name']) + mapping(f['metadata'], text, text)
    if kind == 'Statistics':
        return (u64(f['message_count']) + u16(f['schema_count']) + u32(f['channel_count']) +
                u32(f['attachment_count']) + u32(f['metadata_count']) + u32(f['chunk_count']) +
                u64(f['message_start_time']) + u64(f['message_end_time']) +
                mapping(f['channel_message_counts'], u16, u64))
    if kind == 'ChunkIndex':
        return (u64(f['message_start_time']) + u64(f['message_end_time']) +
                u64(f['chunk_start_offset']) + u64(f['chunk_length']) +
                mapping(f['message_index_offsets'], u16, u64) +
                u64(f['message_index_length']) + text(f['compression']) +
                u64(f['compressed_size']) + u64(f['uncompressed_size']))
    if kind == 'AttachmentIndex':
        return (u64(f['offset']) + u64(f['length']) + u64(f['log_time']) +
                u64(f['create_time']) + u64(f['data_size']) + text(f['name']) +
                text(f['media_type']))
    if kind == 'MetadataIndex':
        return u64(f['offset']) + u64(f['length']) + text(f['name'])
    if kind == 'SummaryOffset':
        return u8(f['group_opcode']) + u64(f['group_start']) + u64(f['group_length'])
    raise ValueError(f'unknown record type {kind}')


def record(kind, content, pad=False):
    if pad and kind not in UNPADDED:
        content += PADDING
    return u8(OPCODES[kind]) + u64(len(content)) + content


def rebuild(spec):
    """Return the bytes of the file the .json ``spec`` describes."""
    features = set(spec['meta']['variant']['features'])
    pad, chunked = 'pad' in features, 'ch' in features
    out = bytearray(MAGIC)
    chunk, indexes, times = bytearray(), {}, []
    expected_footer = None
    records = spec['records']
    for number, entry in enumerate(records):
        kind, fields = entry['type'], dict(entry['fields'])
        if kind == 'DataEnd':
            if chunked:
                out += chunk_records(chunk, indexes, times, 'mx' in features, pad, out)
            out += record(kind, u32(zlib.crc32(out)))
            assert int(fields['data_section_crc']) == zlib.crc32(out[:-13])
            summary_start = len(out)
            continue
        if kind == 'Footer':
            expected_footer = fields
            break
        if chunked and kind in ('Schema', 'Channel', 'Message') and \
                not any(r['type'] == 'DataEnd' for r in records[:number]):
            if kind == 'Channel':
                indexes.setdefault(int(fields['id']), [])
            if kind == 'Message':
                indexes.setdefault(int(fields['channel_id']), []).append(
                    (int(fields['log_time']), len(chunk)))
                times.append(int(fields['log_time']))
            chunk += record(kind, body(kind, fields))
            continue
        out += record(kind, body(kind, fields), pad)
    summary = bytes(out[summary_start:])
    start = summary_start if summary else 0
    offsets_start = int(expected_footer['summary_offset_start'])
    head = u8(OPCODES['Footer']) + u64(20) + u64(start) + u64(offsets_start)
    crc = zlib.crc32(summary + head)
    assert int(expected_footer['summary_start']) == start
    assert int(expected_footer['summary_crc']) == crc
    out += head + u32(crc) + MAGIC
    return bytes(out)


def chunk_records(chunk, indexes, times, message_indexes, pad, out):
    """Return the chunk record and its message indexes, to be placed after ``out``."""
    start, end = (min(times), max(times)) if times else (0, 0)
    content = (u64(start) + u64(end) + u64(len(chunk)) + u32(zlib.crc32(chunk)) + text('') +
               u64(len(chunk)) + bytes(chunk))
    data = record('Chunk', content)
    if message_indexes:
        for channel, entries in indexes.items():
            pairs = b''.join(u64(t) + u64(o) for t, o in entries)
            data += record('MessageIndex', u16(channel) + u32(len(pairs)) + pairs, pad)
    return data


def read_pointers():
    """Write SHA256SUMS from the LFS pointer files in place."""
    lines = []
    for path in sorted(HERE.rglob('*.mcap')):
        fields = dict(line.split(' ', 1) for line in path.read_text().splitlines())
        lines.append(f"{fields['oid'].split(':', 1)[1]}  {fields['size']}  "
                     f'{path.relative_to(HERE)}')
    SUMS.write_text('\n'.join(lines) + '\n')


def main():
    if '--pointers' in sys.argv:
        read_pointers()
    wrong = 0
    for line in SUMS.read_text().splitlines():
        digest, size, name = line.split('  ')
        path = HERE / name
        data = rebuild(json.loads(path.with_suffix('.json').read_text()))
        if hashlib.sha256(data).hexdigest() != digest or len(data) != int(size):
            wrong += 1
            print(f'differs from the MCAP project\'s file: {name}')
            continue
        path.write_bytes(data)
    print(f'{len(SUMS.read_text().splitlines()) - wrong} files rebuilt, {wrong} differ')
    return 1 if wrong else 0


if __name__ == '__main__':
    sys.exit(main())
