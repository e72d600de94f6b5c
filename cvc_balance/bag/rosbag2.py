"""
A bag as ROS users have them: one file, or a rosbag2 directory; and writing one.

:func:`open_bag` takes what ``ros2 bag`` makes and what the project writes:

* a rosbag2 directory: ``metadata.yaml`` and the files of its
  ``relative_file_paths`` (a run split by ``--max-bag-size`` or
  ``--max-bag-duration``). With storage ``mcap`` each file is read by the
  project's fast reader (:class:`~cvc_balance.bag.mcap_reader.Bag`) and the files
  are one bag (a topic's messages are then taken in log-time order by whoever
  needs them in order); with storage ``sqlite3`` (``.db3``, the default before
  Jazzy) or rosbag2's own compression (file or message mode), through rosbags'
  rosbag2 reader. A directory without ``metadata.yaml`` (a recording that was
  killed) is read from its ``.mcap`` and ``.db3`` files in name order, and said;
* a single ``.mcap`` file, or a single ``.db3`` file (rosbags), or a
  directory's ``metadata.yaml``.

Every bag answers the same questions: ``channels``, ``topics()``,
``channel(topic, type)``, ``message_offsets(channel)`` (message records in
uint8 buffers, the reader's fast path), ``message_count``, ``messages``,
``problems``.

:func:`open_writer` writes a single ``.mcap`` file for a path ending in
``.mcap`` and otherwise, as ``ros2 bag record -o DIR`` does, a rosbag2
directory: ``DIR/DIR_0.mcap`` and ``DIR/metadata.yaml`` (version 9, as
Jazzy's rosbag2 writes it).
"""

from dataclasses import dataclass, field
import os
from pathlib import Path, PurePath
import re
import struct

import numpy as np

from cvc_balance.bag.mcap_reader import Bag, BagError, MAGIC, select_channel
from cvc_balance.bag.mcap_writer import BagWriter
from cvc_balance.bag.rosbag2_metadata import metadata_yaml
from cvc_balance.physics.documents import DocumentError, read_document

METADATA = 'metadata.yaml'
MAX_METADATA_BYTES = 16 * 2**20
"""Largest metadata.yaml read, bytes (a few kB per split file)."""
SQLITE_MAGIC = b'SQLite format 3\x00'
BATCH = 1 << 16
"""Messages read through rosbags packed into one buffer."""
_MESSAGE_RECORD = struct.Struct('<BQHIQQ')


@dataclass
class TopicChannel:
    """A topic of a bag made of parts: its channel (or connection) in each part that has it."""

    id: int
    topic: str
    msg_type: str
    encoding: str
    members: list = field(default_factory=list)     # (part, its channel)


def open_bag(path):
    """Open a bag file or rosbag2 directory (see the module's description)."""
    path = Path(path)
    if path.is_dir():
        return _open_directory(path)
    if path.name == METADATA and path.is_file():
        return _open_directory(path.parent)
    try:
        with open(path, 'rb') as stream:
            head = stream.read(len(SQLITE_MAGIC))
    except OSError as error:
        raise BagError(f'{path}: cannot read bag: {error.strerror}') from None
    if head.startswith(SQLITE_MAGIC):
        return RosbagsBag(path)
    if not head.startswith(MAGIC) and path.suffix not in ('.mcap', ''):
        raise BagError(f'{path}: not a bag (neither an MCAP nor a rosbag2 .db3 file, nor a '
                       'rosbag2 directory)')
    return Bag(path)


def _open_directory(directory):
    metadata = directory / METADATA
    if not metadata.is_file():
        files = sorted((p for p in directory.iterdir() if p.suffix in ('.mcap', '.db3')),
                       key=_natural)
        if not files:
            raise BagError(f'{directory}: not a rosbag2 directory (no {METADATA}, no .mcap or '
                           '.db3 file)')
        return _parts_bag(directory, files, [
            f'no {METADATA} (a recording not finished?): read its {len(files)} bag files in '
            'name order'])
    info = _metadata(metadata)
    storage = info.get('storage_identifier', '')
    mode = str(info.get('compression_mode') or '').lower()
    if storage != 'mcap' or mode not in ('', 'none'):
        return RosbagsBag(directory)
    problems, files = [], []
    for name in _relative_paths(info, metadata):
        part = directory / PurePath(name).name
        if part.is_file():
            files.append(part)
        else:
            problems.append(f'{part.name}: listed in {METADATA} but missing')
    return _parts_bag(directory, files, problems)


def _parts_bag(directory, files, problems):
    """Read the files of a directory as one bag; a file that is no bag is said, the rest used."""
    parts = []
    for path in files:
        try:
            parts.append(Bag(path) if path.suffix != '.db3' else RosbagsBag(path))
        except BagError as error:
            problems.append(f'{path.name}: skipped: {str(error).removeprefix(f"{path}: ")}')
    if not parts:
        raise BagError(f'{directory}: no readable bag file'
                       + (f' ({problems[-1]})' if problems else ''))
    return PartsBag(directory, parts, problems)


def _metadata(path):
    try:
        document = read_document(path, MAX_METADATA_BYTES)
    except (OSError, DocumentError) as error:
        raise BagError(f'{path}: unreadable: {str(error).splitlines()[0]}') from None
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    if not isinstance(info, dict):
        raise BagError(f'{path}: no rosbag2_bagfile_information: not rosbag2 metadata')
    return info


def _relative_paths(info, path):
    names = info.get('relative_file_paths')
    if not isinstance(names, list) or not names or \
            not all(isinstance(n, str) and n for n in names):
        raise BagError(f'{path}: relative_file_paths must list the bag\'s files')
    # Split files in the order of their first messages, where metadata.yaml says it.
    files = info.get('files')
    starts = {str(f.get('path')): f.get('starting_time') for f in files
              if isinstance(f, dict)} if isinstance(files, list) else {}
    starts = {PurePath(name).name: start.get('nanoseconds_since_epoch')
              for name, start in starts.items() if isinstance(start, dict)}
    if all(isinstance(starts.get(PurePath(n).name), int) for n in names):
        names = sorted(names, key=lambda n: starts[PurePath(n).name])
    return names


def _natural(path):
    """Sort key of file names with numbers in them: run_2 before run_10."""
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', path.name)]


class PartsBag:
    """Bags (split files of one recording) read as one: a topic is its channels in every part."""

    def __init__(self, path, parts, problems=()):
        """Join ``parts`` (each a bag) of the bag at ``path``."""
        self.path = str(path)
        self.parts = list(parts)
        self._problems = list(problems)
        self.channels = {}
        by_key = {}
        for part in self.parts:
            for channel in part.channels.values():
                key = (channel.topic, channel.msg_type)
                if key not in by_key:
                    by_key[key] = TopicChannel(len(by_key) + 1, channel.topic, channel.msg_type,
                                               channel.encoding)
                    self.channels[by_key[key].id] = by_key[key]
                by_key[key].members.append((part, channel))

    @property
    def problems(self):
        """Return what could not be read: the bag's own problems, then each part's."""
        own = list(self._problems)
        for part in self.parts:
            own += [f'{Path(part.path).name}: {p}' for p in part.problems]
        return own

    def note(self, problem):
        """Report a problem found while reading."""
        self._problems.append(problem)

    def topics(self):
        """Return {topic: message type} of the bag's channels."""
        return {c.topic: c.msg_type for c in self.channels.values()}

    def channel(self, topic, msg_type, option=None, exact=False):
        """Return the channel of ``topic`` with ``msg_type`` (see ``select_channel``)."""
        return select_channel(self.channels.values(), topic, msg_type, self.path, option, exact)

    def message_offsets(self, channel):
        """Yield (records, offsets) of the channel's messages, part after part."""
        for part, member in channel.members:
            yield from part.message_offsets(member)

    def message_count(self, channel):
        """Return the number of the channel's messages known before reading."""
        return sum(part.message_count(member) for part, member in channel.members)

    def messages(self, channel):
        """Return [(log time ns, bytes)] of a channel, in log-time order."""
        out = [m for part, member in channel.members for m in part.messages(member)]
        return sorted(out, key=lambda message: message[0])


class RosbagsBag:
    """
    A bag read through rosbags' rosbag2 reader: sqlite3 storage, rosbag2 compression.

    Messages are packed into buffers of MCAP message records (BATCH at a time),
    so the column readers take them as they take an MCAP chunk.
    """

    def __init__(self, path):
        """Open ``path`` (a rosbag2 directory or a .db3 file) with rosbags."""
        from rosbags.rosbag2 import Reader
        self.path = str(path)
        self.problems = []
        try:
            self._reader = Reader(Path(path))
            self._reader.open()
        except Exception as error:   # rosbags', sqlite's, YAML's and the file system's errors
            raise BagError(f'{self.path}: cannot read bag: {_first_line(error)}') from None
        self.channels, by_key = {}, {}
        for connection in self._reader.connections:
            key = (connection.topic, connection.msgtype)
            if key not in by_key:
                by_key[key] = TopicChannel(len(by_key) + 1, connection.topic,
                                           connection.msgtype, 'cdr')
                self.channels[by_key[key].id] = by_key[key]
            by_key[key].members.append((self, connection))

    def note(self, problem):
        """Report a problem found while reading."""
        self.problems.append(problem)

    def topics(self):
        """Return {topic: message type} of the bag's channels."""
        return {c.topic: c.msg_type for c in self.channels.values()}

    def channel(self, topic, msg_type, option=None, exact=False):
        """Return the channel of ``topic`` with ``msg_type`` (see ``select_channel``)."""
        return select_channel(self.channels.values(), topic, msg_type, self.path, option, exact)

    def message_offsets(self, channel):
        """Yield (records, offsets) of the channel's messages, BATCH at a time."""
        connections = [connection for _, connection in channel.members]
        records, offsets = bytearray(), []
        try:
            for _, log_time, data in self._reader.messages(connections=connections):
                offsets.append(len(records))
                records += _MESSAGE_RECORD.pack(0x05, 22 + len(data), channel.id, 0,
                                                log_time, log_time)
                records += data
                if len(offsets) == BATCH:
                    yield np.frombuffer(bytes(records), np.uint8), np.array(offsets, np.int64)
                    records, offsets = bytearray(), []
        except Exception as error:   # a damaged database: what was read is used
            self.problems.append(f'{channel.topic}: reading stopped: {_first_line(error)}')
        if offsets:
            yield np.frombuffer(bytes(records), np.uint8), np.array(offsets, np.int64)

    def message_count(self, channel):
        """Return the channel's message count as the bag's metadata states it."""
        return sum(max(int(connection.msgcount), 0) for _, connection in channel.members)

    def messages(self, channel):
        """Return [(log time ns, bytes)] of a channel, in log-time order."""
        out = []
        for buffer, offsets in self.message_offsets(channel):
            data = buffer.tobytes()
            for offset in offsets.tolist():
                length, = struct.unpack_from('<Q', data, offset + 1)
                log_time, = struct.unpack_from('<Q', data, offset + 15)
                out.append((log_time, data[offset + 31:offset + 9 + length]))
        return sorted(out, key=lambda message: message[0])


def _first_line(error):
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


def open_writer(path, compression='zstd', chunk_bytes=1 << 20, level=None, custom_data=None,
                exclusive=False):
    """
    Return a writer for ``path``: a single MCAP file if it ends in .mcap, else a rosbag2 directory.

    Both have the methods of :class:`~cvc_balance.bag.mcap_writer.BagWriter`.
    ``custom_data`` ({key: value} strings, e.g. ``{'machine_id': 'gantry-0042'}``) goes
    into the MCAP file as a Metadata record named ``cvc_balance`` and into
    rosbag2's own record's metadata and, for a directory, into ``metadata.yaml``'s
    ``custom_data`` (as ``ros2 bag record --custom-data`` puts it). ``exclusive``
    (recordings): the file or directory is created, an existing one refused
    (BagError), never replaced.
    """
    text = os.fspath(path)
    options = dict(compression=compression, chunk_bytes=chunk_bytes, level=level,
                   custom_data=dict(custom_data) if custom_data else None, exclusive=exclusive)
    if text.endswith('.mcap'):
        return BagWriter(text, **options)
    if text.endswith('.db3'):
        raise BagError(f'{text}: cannot write sqlite3 bags; give a .mcap file or a directory')
    return Rosbag2Writer(text, **options)


class Rosbag2Writer:
    """
    A rosbag2 directory: one MCAP file written by :class:`BagWriter`, metadata.yaml on close.

    An existing directory is used if it is empty, and replaced if it is a rosbag2
    directory holding only its listed files; anything else is left alone (error). With
    ``exclusive`` (recordings) the directory is made, an existing one refused.
    """

    def __init__(self, path, exclusive=False, **options):
        """Make (or empty) directory ``path``; ``options`` go to :class:`BagWriter`."""
        self.directory = Path(path.rstrip('/') if isinstance(path, str) else path)
        if exclusive:
            try:
                self.directory.mkdir()
            except FileExistsError:
                raise BagError(f'{self.directory}: exists; a recording never replaces a bag '
                               'or a directory (give a name not taken)') from None
            except OSError as error:
                raise BagError(f'{self.directory}: cannot make the bag directory: '
                               f'{error.strerror}') from None
        else:
            _prepare_directory(self.directory)
        self.file_name = f'{self.directory.name}_0.mcap'
        self.path = str(self.directory)
        self.writer = BagWriter(self.directory / self.file_name, exclusive=exclusive,
                                **options)
        self._closed = False

    def add_channel(self, topic, msg_type, latched=False, best_effort=False):
        """Register ``topic`` of ``msg_type``; return its channel id (see BagWriter)."""
        return self.writer.add_channel(topic, msg_type, latched, best_effort)

    def write(self, channel, log_time, data):
        """Add one serialized message (see BagWriter)."""
        self.writer.write(channel, log_time, data)

    def block(self, parts):
        """Return a message block of one chunk's samples (see BagWriter)."""
        return self.writer.block(parts)

    def write_block(self, block, log_time, count=None, fill=None):
        """Add samples of a message block (see BagWriter)."""
        self.writer.write_block(block, log_time, count, fill)

    def close(self):
        """Finalise the MCAP file, then write metadata.yaml."""
        if self._closed:
            return
        self.writer.close()
        text = metadata_yaml(self.writer.bag_metadata())
        temporary = self.directory / f'.{METADATA}.tmp'
        temporary.write_text(text, encoding='utf-8')
        temporary.replace(self.directory / METADATA)
        self._closed = True

    def __enter__(self):
        """Use as a context manager: closed (finalised) on exit."""
        return self

    def __exit__(self, *exc):
        """Finalise the bag."""
        self.close()


def writable_directory(directory):
    """
    Return the files to remove before ``directory`` is written as a bag, or raise BagError.

    It may be absent, empty, or a rosbag2 bag holding only its own files (replaced).
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise BagError(f'{directory}: exists and is not a directory; give a .mcap file or a '
                       'directory for the bag')
    if not directory.exists():
        return []
    entries = {p.name for p in directory.iterdir()}
    if not entries:
        return []
    if METADATA in entries:
        try:
            listed = {PurePath(n).name
                      for n in _relative_paths(_metadata(directory / METADATA), directory)}
        except BagError:
            listed = None
        if listed is not None and entries <= listed | {METADATA}:
            return [directory / name for name in entries]
    raise BagError(f'{directory}: exists and is not an empty directory or a rosbag2 bag; not '
                   'overwritten')


def _prepare_directory(directory):
    for old in writable_directory(directory):
        old.unlink()
    if not directory.exists():
        try:
            directory.mkdir(parents=True)
        except OSError as error:
            raise BagError(f'{directory}: cannot make the bag directory: '
                           f'{error.strerror}') from None
