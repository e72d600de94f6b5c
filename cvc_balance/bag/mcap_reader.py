"""
Read MCAP files fast and forgivingly: whole chunks parsed with numpy.

Any valid MCAP (the specification's read-conformance files are a test): Schema
and Channel records at the top level, inside chunks or repeated in the summary;
chunks compressed with zstd, lz4 or not at all, or no chunks; with or without
message indexes, chunk indexes, statistics, summary and summary offsets;
records longer than the fields this reader knows (padding) and record kinds it
does not know are skipped by their length, as the specification asks.

The top-level records are walked once (a few per chunk). Channels come from the
top level and the summary; a chunk is opened to look for them only when the
summary lists none and the chunk may hold one not yet known (no message index,
or one naming an unknown channel). Messages of a channel are located through
the message indexes written after each chunk or, without them, by walking the
chunk's records in runs of equal records (a fixed-layout stream takes a few
numpy steps per chunk); fields of fixed-layout messages are then gathered for
all messages of a chunk at once.

A file that ends inside a record (a recording killed mid-chunk), a chunk that
does not decompress or fails its CRC, a message index that does not point at
its channel's messages: each is reported in ``Bag.problems`` and the rest is
still used. A damaged record (a flipped byte in its length, or in its fields) does
not end the walk: a record whose own fields say its length (a header, schema,
channel, metadata, or a chunk whose CRC holds) is read by them, else the walk
goes on at the next whole record (fields filling its length exactly; a chunk's
CRC holding), and chunks that the summary's chunk indexes list are read where they
say, as the ``mcap`` library's indexed reader and rosbags read them: one damaged
byte costs at most its own record, never the chunks after it.
"""

from collections import Counter, deque
from dataclasses import dataclass, field
import mmap
import os
import re
import struct
import threading

import numpy as np

from cvc_balance.messages.cdr import (find_joint_state_fields, joint_state_names,
                                      read_string_message)

try:    # ISA-L's CRC-32 (zlib's polynomial) runs ~15 times faster than zlib's here
    from isal.isal_zlib import crc32
except ImportError:                                  # pragma: no cover
    from zlib import crc32

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT = 0x06, 0x07, 0x08, 0x09
OP_METADATA, OP_METADATA_INDEX, OP_DATA_END = 0x0C, 0x0D, 0x0F
COMPRESSIONS = ('', 'zstd', 'lz4')
"""Chunk compressions this reader decompresses."""
MESSAGE_HEADER = 31
"""Bytes of a message record before its data: opcode, length, channel, sequence, times."""
AHEAD = 4
"""Chunks decompressed ahead of the one being parsed."""
_RECORD = struct.Struct('<BQ')
_U64 = struct.Struct('<Q')
_U32 = struct.Struct('<I')
_RESYNC = re.compile(b'[\x03\x04\x06\x0c]')
"""Opcodes the walk may go on at after a damaged record: schema, channel, chunk, metadata."""
_local = threading.local()   # a decompressor per thread


class BagError(ValueError):
    """A bag that cannot be used at all; ``str()`` says why in one line."""


@dataclass
class ChannelInfo:
    """A channel of the bag: topic, message type (its schema's name), encoding."""

    id: int
    topic: str
    msg_type: str
    encoding: str
    schema_id: int = 0


@dataclass
class ChunkInfo:
    """
    A chunk's place in the file and where its messages are.

    ``indexes`` maps a channel id to the offsets of its message records in the
    decompressed records: from the message indexes after the chunk, or from a
    walk of its records (``walked``); None while unknown.
    """

    offset: int
    compression: str
    data: memoryview
    uncompressed_size: int
    crc: int
    indexes: dict = None
    walked: bool = False
    end: int = 0             # where its record ends in the file


def select_channel(channels, topic, msg_type, where, option=None, exact=False):
    """
    Return the channel of ``channels`` (ChannelInfo-like values) for ``topic``, or None.

    ``topic`` is a name, with or without its leading '/'. ``exact``: only that
    topic (one the user named); else a namespaced or remapped topic ending in
    it (``/gantry/joint_states``) also matches if no topic has the name itself
    and exactly one ends in it. Several matches, or a match of another type than
    ``msg_type``, is a :class:`BagError` naming the bag's topics (and ``option``,
    the command-line option that chooses one).
    """
    wanted = topic.strip('/')
    found = [c for c in channels if c.topic.strip('/') == wanted]
    if not found and not exact:
        found = [c for c in channels if c.topic.endswith('/' + wanted)]
    names = {c.topic for c in found}
    if len(names) > 1:
        raise BagError(f'{where}: several topics match {topic}: {", ".join(sorted(names))}; '
                       f'choose one{f" with {option}" if option else ""}')
    for c in found:
        if c.msg_type != msg_type:
            raise BagError(f'{where}: topic {c.topic} has type {c.msg_type or "(none)"}, '
                           f'expected {msg_type}; the bag has: {describe_topics(channels)}')
    return found[0] if found else None


def describe_topics(channels):
    """Return 'topic (type), ...' of ``channels``, sorted, or 'none'."""
    found = sorted({(c.topic, c.msg_type or 'no schema') for c in channels})
    return ', '.join(f'{t} ({m})' for t, m in found) or 'none'


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
        self.header = None          # the Header record's bytes (None: not readable)
        self.definitions = {}       # (opcode, id) -> bytes of its Schema or Channel record
        self.metadata = []          # Metadata records: (offset, name, {key: value}, bytes)
        self.attachments = []       # Attachment records: (offset, length)
        self.finished = False       # the walk reached the footer
        self.summary_records = Counter()    # opcode -> records of the summary
        self._indexed_chunks = []   # offsets of chunks the summary's chunk indexes give
        self._indexed_metadata = []  # offsets of metadata records the summary indexes
        self._loose = []           # (channel, offset in file) of messages outside chunks
        self._mended = {}          # offset -> length of records whose length field is damaged
        self._unreadable = set()   # chunks already reported
        self._summary_channels = False
        self._walk()
        if not self.summary_records:
            self._summary_by_footer()
        self._read_indexed()
        self._find_channels_in_chunks()
        for channel in self.channels.values():    # a schema may come after its channel
            if not channel.msg_type:
                channel.msg_type = self.schemas.get(channel.schema_id, '')

    # -- structure -------------------------------------------------------------------

    def _walk(self):
        data = self._bytes
        if data[:8] != MAGIC:
            raise BagError(f'{self.path}: not an MCAP file (no MCAP magic at the start)')
        position, size = 8, len(data)
        data_end = False
        indexing = None   # the chunk that message index records now follow
        stopped = False   # the walk stopped at a record, and said so
        while position < size:
            torn, opcode, length = self._framing(position)
            damage = None
            if torn is None:
                start = position + 9
                try:
                    if data_end:
                        self._summary_record(opcode, start, length)
                    else:
                        indexing = self._record(opcode, start, length, indexing)
                except (struct.error, UnicodeDecodeError, ValueError) as error:
                    damage = f'corrupt {"summary" if data_end else "record"} (opcode ' \
                             f'0x{opcode:02x}) at byte {position}: {error}'
            if torn is not None or damage is not None:
                resume = None if data_end else self._resume(position, length)
                if resume is None:
                    if torn is not None:
                        self._ended(data_end, torn)
                    else:
                        self.problems.append(f'{damage}; stopped reading there')
                    stopped = True
                    break
                if indexing is not None:      # its message indexes may be part gone: walked
                    indexing.indexes, indexing.walked = None, False
                    indexing = None
                damage = damage or f'record (opcode 0x{opcode:02x}) at byte {position} runs ' \
                    'past the end of the file'
                if resume == position:
                    self.problems.append(f'{damage}: its length field ({length}) is damaged, '
                                         f'its fields give {self._mended[position]}: read by '
                                         'them')
                else:
                    self.problems.append(f'{damage}: {resume - position} bytes skipped to the '
                                         f'next whole record at byte {resume}')
                position = resume
                continue
            position = start + length
            if opcode == OP_FOOTER:
                self.finished = True
                break
            data_end = data_end or opcode == OP_DATA_END
        if not self.finished and not data_end and not stopped:
            self.problems.append('file has no end of data (truncated recording?)')

    def _framing(self, position):
        """
        Return (torn, opcode, length) of the record at ``position``.

        ``torn`` is None, or where the file ends inside the record. A record whose
        length field was found damaged (:meth:`_resume`) gets the length its fields give.
        """
        data, size = self._bytes, len(self._bytes)
        if position + 9 > size:
            return f'file ends inside a record header at byte {position}', None, 0
        opcode, length = _RECORD.unpack_from(data, position)
        length = self._mended.get(position, length)
        if position + 9 + length > size:
            return (f'file ends inside a record (opcode 0x{opcode:02x}) at byte {position} of '
                    f'{size}'), opcode, length
        return None, opcode, length

    def _resume(self, position, length):
        """
        Return where the walk goes on after the damaged record at ``position`` (None: nowhere).

        ``position`` itself when the record's own fields give a length other than its
        length field's (remembered for :meth:`_framing`), else the next whole record.
        """
        derived = _derived_length(self._bytes, position)
        if derived is not None and derived != length and position not in self._mended:
            self._mended[position] = derived
            return position
        return self._next_whole_record(position + 1)

    def _next_whole_record(self, start):
        """Return where the first whole record at or after ``start`` begins (None: none)."""
        data, size = self._bytes, len(self._bytes)
        if start >= size:
            return None
        for match in _RESYNC.finditer(data, start):
            at = match.start()
            if at + 9 > size:
                return None
            length, = _U64.unpack_from(data, at + 1)
            if length <= size - at - 9 and _derived_length(data, at) == length:
                return at
        return None

    def _ended(self, data_end, where):
        if data_end:
            self.problems.append(f'{where}, in its summary (every message was read)')
        else:
            self.problems.append(f'{where} (truncated recording?)')

    def _record(self, opcode, start, length, indexing):
        """Take one data-section record; return the chunk later message indexes belong to."""
        data = self._bytes
        if opcode in (OP_SCHEMA, OP_CHANNEL):
            self._definition(data, opcode, start, length)
        elif opcode == OP_CHUNK:
            chunk = _chunk_at(data, start - 9, start + length)
            if chunk is None:
                raise ValueError('chunk data beyond its record')
            self.chunks.append(chunk)
            return chunk
        elif opcode == OP_MESSAGE_INDEX and indexing is not None:
            channel_id, body = struct.unpack_from('<HI', data, start)
            if body % 16 or 6 + body > length:
                raise ValueError('message index entries beyond its record')
            pairs = np.frombuffer(data, dtype=[('t', '<u8'), ('o', '<u8')], count=body // 16,
                                  offset=start + 6)
            indexes = indexing.indexes = indexing.indexes or {}
            offsets = pairs['o']
            if channel_id in indexes:
                offsets = np.concatenate([indexes[channel_id], offsets])
            indexes[channel_id] = offsets
            return indexing
        elif opcode == OP_MESSAGE:
            if length >= MESSAGE_HEADER - 9:
                channel_id, = struct.unpack_from('<H', data, start)
                self._loose.append((channel_id, start - 9))
        elif opcode == OP_HEADER:
            _string(data, _string(data, start)[1])         # profile, library: readable
            self.header = _record_bytes(data, start, length)
        elif opcode == OP_METADATA:
            self._metadata(start - 9, start + length)
        elif opcode == OP_ATTACHMENT:
            self.attachments.append((start - 9, 9 + length))
        elif not OP_HEADER <= opcode <= OP_DATA_END:
            return indexing        # a kind this reader does not know: skipped, nothing ends
        return None

    def _metadata(self, offset, end):
        """Register the Metadata record at ``offset`` (ending at ``end``)."""
        name, position = _string(self._bytes, offset + 9)
        values, _ = _string_map(self._bytes, position, end)
        self.metadata.append((offset, name, values,
                              _record_bytes(self._bytes, offset + 9, end - offset - 9)))

    def _summary_record(self, opcode, start, length):
        if opcode in (OP_SCHEMA, OP_CHANNEL):
            self._definition(self._bytes, opcode, start, length)
            self._summary_channels |= opcode == OP_CHANNEL
        elif opcode == OP_CHUNK_INDEX:
            self._indexed_chunks.append(_U64.unpack_from(self._bytes, start + 16)[0])
        elif opcode == OP_METADATA_INDEX:
            self._indexed_metadata.append(struct.unpack_from('<QQ', self._bytes, start))
        self.summary_records[opcode] += 1

    def _summary_by_footer(self):
        """
        Read the summary where the footer says it starts, when the walk did not reach it.

        Its channels, chunk and metadata indexes are then used as the walk's would be.
        A summary that does not read whole is left unused, unsaid (the walk said why it
        stopped).
        """
        data, size = self._bytes, len(self._bytes)
        footer = size - len(MAGIC) - 29
        if footer < 8 or data[size - len(MAGIC):] != MAGIC or \
                _RECORD.unpack_from(data, footer) != (OP_FOOTER, 20):
            return
        position, = _U64.unpack_from(data, footer + 9)
        records = []
        while 8 <= position < footer:
            opcode, length = _RECORD.unpack_from(data, position)
            if position + 9 + length > footer:
                return
            records.append((opcode, position + 9, length))
            position += 9 + length
        if position != footer:
            return
        try:
            for opcode, start, length in records:
                self._summary_record(opcode, start, length)
        except (struct.error, UnicodeDecodeError, ValueError):
            pass

    def _read_indexed(self):
        """
        Read the chunks and metadata records the summary lists that the walk did not find.

        Found where the summary's indexes say, as the ``mcap`` library's indexed reader
        finds them (their record headers are not needed); a chunk only if its CRC holds
        (else said, as a chunk that does not decode is).
        """
        data, size = self._bytes, len(self._bytes)
        known = {chunk.offset for chunk in self.chunks}
        found = 0
        for offset in self._indexed_chunks:
            if offset in known or not 8 <= offset < size:
                continue
            chunk = _chunk_at(data, offset, size, check=True)
            if chunk is not None:
                self.chunks.append(chunk)
                known.add(offset)
                found += 1
            else:
                self.problems.append(f"chunk at byte {offset} (from the summary's chunk index) "
                                     'unreadable (not a whole chunk whose CRC holds); skipped')
        if found:
            self.chunks.sort(key=lambda c: c.offset)
            self.problems.append(f'{found} chunks read where the summary\'s chunk indexes '
                                 'put them (the walk did not reach them whole)')
            spans = [(c.offset, c.end) for c in self.chunks]
            self._loose = [(c, o) for c, o in self._loose
                           if not any(lo <= o < hi for lo, hi in spans)]
        seen = {offset for offset, *_ in self.metadata}
        for offset, length in self._indexed_metadata:
            if offset not in seen and 8 <= offset and offset + length <= size:
                try:
                    self._metadata(offset, offset + length)
                    seen.add(offset)
                except (struct.error, UnicodeDecodeError, ValueError):
                    pass
        self.metadata.sort(key=lambda m: m[0])

    def _definition(self, data, opcode, start, length):
        """Register a Schema or Channel record starting (after its opcode and length) here."""
        if opcode == OP_SCHEMA:
            schema_id, = struct.unpack_from('<H', data, start)
            name, _ = _string(data, start + 2)
            if schema_id:                            # 0: no schema, by the specification
                self.schemas[schema_id] = name
                self.definitions.setdefault((opcode, schema_id),
                                            _record_bytes(data, start, length))
            return
        channel_id, schema_id = struct.unpack_from('<HH', data, start)
        topic, position = _string(data, start + 4)
        encoding, _ = _string(data, position)
        self.channels[channel_id] = ChannelInfo(channel_id, topic,
                                                self.schemas.get(schema_id, ''), encoding,
                                                schema_id)
        self.definitions.setdefault((opcode, channel_id), _record_bytes(data, start, length))

    def _find_channels_in_chunks(self):
        """
        Open the chunks that may define channels or schemas not known yet.

        Those whose message indexes name an unknown channel, and without a channel
        list in the summary those without message indexes too; then, while a
        channel's schema is still unknown (channels repeated in the summary, their
        schemas not), the others in order until it is found.
        """
        known, numbers = set(self.channels), []
        for n, chunk in enumerate(self.chunks):
            if (chunk.indexes is None and not self._summary_channels) or \
                    set(chunk.indexes or ()) - known:
                numbers.append(n)
                known |= set(chunk.indexes or ())
        opened = set(numbers)
        for number, records in self._decoded_chunks(numbers):
            if records is not None:
                self._walk_chunk(number, records)
        if not self._missing_schemas():
            return
        for number, records in self._decoded_chunks(
                n for n in range(len(self.chunks)) if n not in opened):
            if records is not None:
                self._walk_chunk(number, records)
                if not self._missing_schemas():
                    return

    def _missing_schemas(self):
        return {c.schema_id for c in self.channels.values()} - set(self.schemas) - {0}

    def _walk_chunk(self, number, records):
        """Walk a chunk's records: register its schemas and channels, index its messages."""
        chunk = self.chunks[number]
        buffer = np.frombuffer(records, dtype=np.uint8)
        offsets, opcodes, lengths, end = record_table(buffer)
        if end != len(buffer):
            self.problems.append(f'chunk at byte {chunk.offset}: a record runs past the '
                                 f'chunk\'s end at byte {end} of its {len(buffer)}; the rest '
                                 'of the chunk skipped')
        for offset, opcode, length in zip(offsets.tolist(), opcodes.tolist(), lengths.tolist()):
            if opcode in (OP_SCHEMA, OP_CHANNEL):
                try:
                    self._definition(records, opcode, offset + 9, length)
                except (struct.error, UnicodeDecodeError, ValueError) as error:
                    self.problems.append(f'chunk at byte {chunk.offset}: corrupt record '
                                         f'(opcode 0x{opcode}) at {offset}: {error}; skipped')
        if chunk.indexes is None or chunk.walked:
            messages = offsets[(opcodes == OP_MESSAGE) & (lengths >= MESSAGE_HEADER - 9)]
            channel = column(buffer, messages + 9, '<u2')
            chunk.indexes = {int(c): messages[channel == c] for c in np.unique(channel)}
            chunk.walked = True

    def note(self, problem):
        """Report a problem found while reading."""
        self.problems.append(problem)

    @property
    def data(self):
        """Return the file's bytes (mapped)."""
        return self._bytes

    def loose_messages(self):
        """Return [(channel id, offset in the file)] of the message records outside chunks."""
        return list(self._loose)

    def topics(self):
        """Return {topic: message type} of the bag's channels."""
        return {c.topic: c.msg_type for c in self.channels.values()}

    def channel(self, topic, msg_type, option=None, exact=False):
        """Return the channel of ``topic`` with ``msg_type`` (see :func:`select_channel`)."""
        return select_channel(self.channels.values(), topic, msg_type, self.path, option, exact)

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

    def check_chunks(self):
        """Decompress every chunk and check its CRC; those that fail go to ``problems``."""
        for _ in self.decoded_chunks():
            pass

    def decoded_chunks(self):
        """Yield (chunk, its records or None) of every chunk, in order (failures said once)."""
        for number, records in self._decoded_chunks(range(len(self.chunks))):
            yield self.chunks[number], records

    def message_offsets(self, channel):
        """
        Yield (records as uint8 array, offsets of this channel's message records), in file order.

        Chunks whose message indexes lack the channel are not even decompressed;
        messages outside chunks come with the whole file as their records.
        """
        loose = np.array([o for c, o in self._loose if c == channel.id], dtype=np.int64)
        wanted = [number for number, chunk in enumerate(self.chunks)
                  if chunk.indexes is None or channel.id in chunk.indexes]
        for number, records in self._decoded_chunks(wanted):
            chunk = self.chunks[number]
            before = int(np.searchsorted(loose, chunk.offset))
            if before:
                yield np.frombuffer(self._bytes, dtype=np.uint8), loose[:before]
                loose = loose[before:]
            if records is None:
                continue
            if chunk.indexes is None:
                self._walk_chunk(number, records)
            buffer = np.frombuffer(records, dtype=np.uint8)
            offsets = chunk.indexes.get(channel.id)
            if offsets is None or not len(offsets):
                continue
            offsets = offsets.astype(np.int64)
            if not chunk.walked and not _points_at_messages(buffer, offsets, channel.id):
                self.problems.append(f'chunk at byte {chunk.offset}: message index of '
                                     f'{channel.topic} does not point at its messages; chunk '
                                     'walked instead')
                chunk.walked = True
                self._walk_chunk(number, records)
                offsets = chunk.indexes.get(channel.id, np.zeros(0, np.int64))
                if not len(offsets):
                    continue
            yield buffer, offsets
        if len(loose):
            yield np.frombuffer(self._bytes, dtype=np.uint8), loose

    def message_count(self, channel):
        """Return the number of messages of ``channel`` known before reading (indexes, loose)."""
        return sum(len(chunk.indexes.get(channel.id, ())) for chunk in self.chunks
                   if chunk.indexes is not None) + \
            sum(1 for c, _ in self._loose if c == channel.id)

    def messages(self, channel):
        """Return [(log time ns, bytes)] of a channel, in file order (for few messages)."""
        out = []
        for buffer, offsets in self.message_offsets(channel):
            lengths = column(buffer, offsets + 1, '<u8').tolist()
            times = column(buffer, offsets + 15, '<u8').tolist()
            for offset, length, log_time in zip(offsets.tolist(), lengths, times):
                out.append((log_time, buffer[offset + MESSAGE_HEADER:offset + 9 + length]
                            .tobytes()))
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


def _string(data, position, end=None):
    length, = _U32.unpack_from(data, position)
    if position + 4 + length > (len(data) if end is None else end):
        raise ValueError('string beyond the record')
    return bytes(data[position + 4:position + 4 + length]).decode('utf-8'), position + 4 + length


def _record_bytes(data, start, length):
    """Return the record whose body is ``length`` bytes at ``start``, with that length field."""
    return bytes(data[start - 9:start - 8]) + _U64.pack(length) + bytes(data[start:start + length])


def _string_map(data, position, end):
    """Return ({key: value}, end) of a map<string, string> at ``position`` within ``end``."""
    length, = _U32.unpack_from(data, position)
    position += 4
    stop = position + length
    if stop > end:
        raise ValueError('map beyond the record')
    values = {}
    while position < stop:
        key, position = _string(data, position, stop)
        values[key], position = _string(data, position, stop)
    return values, stop


def _chunk_at(data, offset, end, check=False):
    """
    Return the ChunkInfo of the chunk record at ``offset`` (None if it does not fit ``end``).

    Its fields are read after the opcode and length (which are not used: the chunk's
    records say its length). ``check``: None unless its records decompress and their
    CRC holds (a chunk found by a chunk index or by looking for one).
    """
    try:
        size, crc = struct.unpack_from('<QI', data, offset + 25)
        compression, position = _string(data, offset + 37, end)
        records_length, = _U64.unpack_from(data, position)
    except (struct.error, UnicodeDecodeError, ValueError):
        if check:
            return None
        raise
    stop = position + 8 + records_length
    if stop > end:
        return None
    chunk = ChunkInfo(offset, compression, memoryview(data)[position + 8:stop], size, crc,
                      end=stop)
    if check:
        if compression not in COMPRESSIONS:
            return None
        records, error = _decode(chunk)
        if error is not None or (not crc and record_table(
                np.frombuffer(records, np.uint8))[3] != len(records)):
            return None
    return chunk


def _derived_length(data, offset):
    """
    Return the length of the record at ``offset`` as its own fields give it, or None.

    For the kinds whose fields fill their record exactly (header, schema, channel,
    metadata) when they do, as readable text; for a chunk when its records decompress
    and their CRC holds. None for other kinds and for anything that does not fit.
    """
    size = len(data)
    opcode = data[offset]
    body = offset + 9
    try:
        if opcode == OP_CHUNK:
            chunk = _chunk_at(data, offset, size, check=True)
            return None if chunk is None else chunk.end - body
        if opcode == OP_HEADER:
            _, position = _string(data, body)
            _, position = _string(data, position)
        elif opcode == OP_SCHEMA:
            _, position = _string(data, body + 2)
            _, position = _string(data, position)
            length, = _U32.unpack_from(data, position)
            position += 4 + length
        elif opcode == OP_CHANNEL:
            _, position = _string(data, body + 4)
            _, position = _string(data, position)
            _, position = _string_map(data, position, size)
        elif opcode == OP_METADATA:
            name, position = _string(data, body)
            _, position = _string_map(data, position, size)
            if not name:
                return None
        else:
            return None
    except (struct.error, UnicodeDecodeError, ValueError):
        return None
    return position - body if position <= size else None


def _points_at_messages(buffer, offsets, channel_id):
    """Whether every offset is a whole message record of ``channel_id`` in ``buffer``."""
    if int(offsets.min()) < 0 or int(offsets.max()) + MESSAGE_HEADER > len(buffer):
        return False
    lengths = column(buffer, offsets + 1, '<u8')
    return bool(np.all(column(buffer, offsets, 'u1') == OP_MESSAGE) and
                np.all(column(buffer, offsets + 9, '<u2') == channel_id) and
                np.all(lengths >= MESSAGE_HEADER - 9) and
                np.all(lengths <= len(buffer) - 9 - offsets))


def record_table(buffer):
    """
    Return (offsets, opcodes, lengths, end) of the records in ``buffer`` (uint8).

    Walked in runs: where the next record has the opcode and length of this one,
    the following ones are checked a growing block at a time through strided
    views, so a chunk of equal records takes a few numpy steps; other records
    one by one. ``end`` is where the walk stopped: ``len(buffer)`` unless a
    record runs past the end.
    """
    size, position = len(buffer), 0
    runs = []       # (start, step, count, opcode, length)
    while position + 9 <= size:
        opcode, length = _RECORD.unpack_from(buffer, position)
        step = 9 + length
        if position + step > size:
            break
        count = 1
        following = position + step
        if following + step <= size and _RECORD.unpack_from(buffer, following) == \
                (opcode, length):
            count = _run(buffer, position, step, opcode, length)
        runs.append((position, step, count, opcode, length))
        position += step * count
    if not runs:
        empty = np.zeros(0, np.int64)
        return empty, np.zeros(0, np.uint8), empty, position
    start, step, count, opcode, length = (np.array(c, dtype=np.int64) for c in zip(*runs))
    first = np.repeat(np.cumsum(count) - count, count)
    index = np.arange(int(count.sum()), dtype=np.int64) - first
    offsets = np.repeat(start, count) + index * np.repeat(step, count)
    return (offsets, np.repeat(opcode, count).astype(np.uint8), np.repeat(length, count),
            position)


def _run(buffer, position, step, opcode, length):
    """Return how many records from ``position`` on share ``opcode`` and ``length``."""
    fitting = (len(buffer) - position) // step     # records of this size that fit
    count, block = 2, 16
    while count < fitting:
        n = min(block, fitting - count)
        at = position + step * count
        same = (np.ndarray((n,), np.uint8, buffer, at, (step,)) == opcode) & \
            (np.ndarray((n,), '<u8', buffer, at + 1, (step,)) == length)
        if not same.all():
            return count + int(np.argmin(same))
        count += n
        block *= 4
    return count


def _stride(at):
    """Return the common step of evenly spaced positions ``at`` (increasing), else None."""
    if len(at) > 1:
        stride = int(at[1] - at[0])
        if stride > 0 and at[-1] - at[0] == stride * (len(at) - 1) and \
                np.all(np.diff(at) == stride):
            return stride
    return None


def matching(buffer, at, spans):
    """
    Which positions ``at`` have, in each span ((start, stop) after them), the first one's bytes.

    Compared up to eight bytes at a time through strided views when the positions
    are evenly spaced (records of one fixed layout written one after the other),
    else gathered. Returns a boolean array.
    """
    stride = _stride(at)
    same = np.ones(len(at), dtype=bool)
    for lo, hi in spans:
        if hi <= lo:
            continue
        if stride is None:
            block = buffer[at[:, None] + np.arange(lo, hi)]
            same &= np.all(block == block[0], axis=1)
            continue
        width = next(w for w in (8, 4, 2, 1) if w <= hi - lo)
        starts = list(range(lo, hi - width + 1, width))
        if starts[-1] + width < hi:
            starts.append(hi - width)       # the last word overlaps the one before
        for start in starts:
            words = np.ndarray(shape=(len(at),), dtype=f'<u{width}', buffer=buffer,
                               offset=int(at[0]) + start, strides=(stride,))
            same &= words == words[0]
    return same


def column(buffer, at, dtype, copy=True):
    """
    ``dtype`` at each position ``at`` of ``buffer`` (uint8).

    Evenly spaced positions (records of one fixed layout written one after the
    other) are read through a strided view (returned as it is with
    ``copy=False``: valid while ``buffer`` is); others by gathering their bytes.
    """
    dtype = np.dtype(dtype)
    if not len(at):
        return np.zeros(0, dtype)
    stride = _stride(at)
    if stride is not None:
        view = np.ndarray(shape=(len(at),), dtype=dtype, buffer=buffer, offset=int(at[0]),
                          strides=(stride,))
        return view.copy() if copy else view
    if len(at) == 1:
        return buffer[int(at[0]):int(at[0]) + dtype.itemsize].copy().view(dtype)
    return buffer[at[:, None] + np.arange(dtype.itemsize)].copy().view(dtype).ravel()


def gather(buffer, offsets, data_offset, dtype, copy=True):
    """One field of every message: ``dtype`` at ``data_offset`` in each message's data."""
    return column(buffer, offsets + (MESSAGE_HEADER + data_offset), dtype, copy)


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
    return column(buffer, offsets + 1, '<u8')


def log_times(buffer, offsets, copy=True):
    """Log times (ns) of the messages at ``offsets`` (``copy`` as in :func:`column`)."""
    return column(buffer, offsets + 15, '<u8', copy)


@dataclass
class MotionSamples:
    """
    Motion samples of a bag: stamp (ns), log time (ns), angle (rad), omega (rad/s).

    ``rejected`` messages could not be read; ``reasons`` say why. ``skipped``
    JointState messages do not carry the joint (``joints_seen``: the names they have,
    at most 20 of a message, none added once 20 are known).
    ``problems``: what else the source's reader found (a keyphasor's marks repaired);
    ``joint_topic``: the JointState topic when the angle and speed are its position and
    velocity as sent (None for motion made from a speed or a keyphasor).
    """

    stamp: np.ndarray
    log_time: np.ndarray
    angle: np.ndarray
    omega: np.ndarray
    rejected: int = 0
    reasons: list = field(default_factory=list)
    skipped: int = 0
    joints_seen: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    joint_topic: str = None


LAYOUTS = 16
"""JointState layouts (publishers) of one chunk gathered at once; further ones one by one."""


def joint_samples(bag, channel, joint):
    """
    Stamp, angle and speed of ``joint`` from every JointState of ``channel``.

    The joint is found by name among the message's joints, in any order. The
    messages of a chunk that share the first one's layout (length, frame id,
    joint names and sequence lengths) are gathered with numpy at once; the
    others likewise by their own first message's layout (several publishers on
    one topic), up to :data:`LAYOUTS` layouts a chunk, then one by one.
    Messages without the joint are skipped and counted (with the joints they
    name); unreadable ones are rejected.
    """
    tally = _Tally()
    # Filled in place, chunk by chunk: sized by the message indexes, where there are some.
    columns = _Columns((np.int64, np.int64, float, float), bag.message_count(channel))
    for buffer, offsets in bag.message_offsets(channel):
        lengths = _lengths(buffer, offsets)
        for _ in range(LAYOUTS):
            if not len(offsets):
                break
            offsets, lengths = _one_layout(buffer, offsets, lengths, joint, columns, tally)
        for offset, length in zip(offsets.tolist(), lengths.tolist()):
            _one_layout(buffer, np.array([offset]), np.array([length]), joint, columns, tally)
    stamp, log_time, angle, omega = columns.filled()
    if np.any(log_time[1:] < log_time[:-1]):
        order = np.argsort(log_time, kind='stable')
        stamp, log_time, angle, omega = stamp[order], log_time[order], angle[order], omega[order]
    reasons = [f'{tally.rejected} {channel.topic} messages not readable as JointState with '
               'position and velocity'] if tally.rejected else []
    return MotionSamples(stamp, log_time, angle, omega, tally.rejected, reasons,
                         tally.skipped, sorted(tally.seen))


@dataclass
class _Tally:
    """JointState messages rejected (unreadable) and skipped (without the joint)."""

    rejected: int = 0
    skipped: int = 0
    seen: set = field(default_factory=set)


def _one_layout(buffer, offsets, lengths, joint, columns, tally):
    """
    Take the messages laid out as the first of ``offsets``; return the other (offsets, lengths).

    Their rows go to ``columns`` if they carry the joint with position and velocity;
    else they are counted in ``tally``.
    """
    first, length = int(offsets[0]), int(lengths[0])
    data = buffer[first + MESSAGE_HEADER:first + 9 + length].tobytes()
    try:
        names, names_end = joint_state_names(data)
        found = find_joint_state_fields(data, joint)
    except (ValueError, struct.error, UnicodeDecodeError):
        tally.rejected += 1
        return offsets[1:], lengths[1:]
    spans = [(0, 4), (12, names_end)]    # all but the stamp: encapsulation, frame, names
    if found is not None:
        spans += [(found[0][f'{s}_count'], found[0][f'{s}_count'] + 4)
                  for s in ('position', 'velocity')]
    same = lengths == length
    same &= matching(buffer, offsets + MESSAGE_HEADER, spans) if same.all() else \
        _scattered(same, lambda at: matching(buffer, at + MESSAGE_HEADER, spans), offsets)
    group = offsets if same.all() else offsets[same]
    if found is None:
        if joint not in names:
            tally.skipped += len(group)
            tally.seen.update(names[:20] if len(tally.seen) < 20 else ())
        else:                                # the joint without position or velocity
            tally.rejected += len(group)
    else:
        fields = found[0]
        stamp, log_time, angle, omega = columns.take(len(group))
        np.multiply(gather(buffer, group, fields['sec'], '<i4', copy=False), 1_000_000_000,
                    out=stamp, dtype=np.int64)
        nanosec = gather(buffer, group, fields['nanosec'], '<u4', copy=False)
        stamp += nanosec
        stamp[nanosec >= 1_000_000_000] = 0     # no stamp: rejected, as the node does
        log_time[:] = log_times(buffer, group, copy=False)
        angle[:] = gather(buffer, group, fields['position'], '<f8', copy=False)
        omega[:] = gather(buffer, group, fields['velocity'], '<f8', copy=False)
    if same.all():
        return offsets[:0], lengths[:0]
    return offsets[~same], lengths[~same]


def _scattered(mask, test, offsets):
    """``test`` applied to the offsets where ``mask`` holds, spread back over all of them."""
    out = np.zeros(len(offsets), dtype=bool)
    out[mask] = test(offsets[mask])
    return out


def float64_samples(bag, channel):
    """(log time ns, data) of every std_msgs/Float64 of ``channel``, in log-time order."""
    times, values = [], []
    for buffer, offsets in bag.message_offsets(channel):
        lengths = _lengths(buffer, offsets)
        whole = lengths >= MESSAGE_HEADER - 9 + 12        # encapsulation, pad, float64
        offsets = offsets[whole]
        times.append(log_times(buffer, offsets).astype(np.int64))
        values.append(gather(buffer, offsets, 4, '<f8'))
    if not times:
        return np.zeros(0, np.int64), np.zeros(0)
    times, values = np.concatenate(times), np.concatenate(values)
    if np.any(times[1:] < times[:-1]):     # sorted only when needed: half the read's time
        order = np.argsort(times, kind='stable')
        times, values = times[order], values[order]
    return times, values


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
    """[(log time ns, text)] of a std_msgs/String channel in log-time order; bad ones reported."""
    out = []
    for log_time, data in bag.messages(channel):
        try:
            out.append((log_time, read_string_message(data)))
        except (ValueError, UnicodeDecodeError) as error:
            bag.note(f'{channel.topic}: message at {log_time} ns unreadable ({error}); skipped')
    return sorted(out, key=lambda pair: pair[0])
