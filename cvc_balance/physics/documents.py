"""
YAML 1.2 and JSON documents, read safely: the one reader of every file the package reads.

Layouts, tolerance files, scenarios, coefficient records and rosbag2 metadata all come
through :func:`load_document` (text or bytes) or :func:`read_document` (a file). The rules:

* **YAML 1.2 core schema** for plain scalars: ``3:00`` is text, not 180 (YAML 1.1's base
  60); ``yes``, ``no``, ``on``, ``off`` are text, not booleans; ``010`` is ten, not eight;
  ``1e5`` is a number. Octal and hexadecimal (``0o17``, ``0x1F``) are deliberately read as
  text: every quantity is written in decimal, and a field that wants a number then says
  it got text. ``.inf`` and ``.nan`` are numbers (which the readers then refuse).
* **Keys once**: a mapping that gives a key twice is refused (YAML says keys are unique;
  parsers silently keep the last). The same in JSON. YAML 1.1's merge key ``<<`` is
  refused, saying so (YAML 1.2 has none).
* **Aliases**: an alias is the anchored value itself, never a copy; a document whose
  aliases would expand it beyond :data:`ALIAS_EXPANSION` times is refused, as is an alias
  to the collection it is inside of (a recursive document).
* **Streaming**: YAML is read as libyaml's events and built with an explicit stack (no
  node graph, no recursion); a reader may collect one top-level list item by item
  (``collect``), so a layout's 10^5 components become columns, not dicts.

Every failure is one line, :class:`DocumentError` (a ``ValueError``), naming the line.
"""

import json
import os
import re
import stat

import yaml
from yaml import events

try:    # libyaml's parser (C, events): fast, and it keeps its own stack
    from yaml._yaml import CParser as _Parser
except ImportError:                                  # pragma: no cover
    from yaml.parser import Parser as _Parser

    class _Stream(yaml.reader.Reader, yaml.scanner.Scanner, _Parser):
        pass
    _Parser = _Stream

ALIAS_EXPANSION = 4
"""YAML aliases may at most multiply a document's nodes by this (plus ALIAS_ALLOWANCE)."""
ALIAS_ALLOWANCE = 10_000
MAX_DEPTH = 100
"""Deepest nesting of collections (a layout needs 5 levels)."""
READ_CHUNK = 1 << 16
"""Characters handed to libyaml at a time from a text."""


class DocumentError(ValueError):
    """A text that is not one valid YAML 1.2 or JSON document; ``str()`` is one line."""


# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution), plain scalars.
_NULL = frozenset(('', '~', 'null', 'Null', 'NULL'))
_BOOL = {'true': True, 'True': True, 'TRUE': True,
         'false': False, 'False': False, 'FALSE': False}
_INT = re.compile(r'[-+]?[0-9]+')
_FLOAT = re.compile(r'[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?')
_SPECIAL = {'.inf': float('inf'), '.Inf': float('inf'), '.INF': float('inf'),
            '+.inf': float('inf'), '+.Inf': float('inf'), '+.INF': float('inf'),
            '-.inf': float('-inf'), '-.Inf': float('-inf'), '-.INF': float('-inf'),
            '.nan': float('nan'), '.NaN': float('nan'), '.NAN': float('nan')}
_NUMERIC_START = frozenset('0123456789+-.')
_TAG = 'tag:yaml.org,2002:'


def plain_scalar(text):
    """Return the value of a plain (unquoted, untagged) YAML scalar by the core schema."""
    if text and text[0] in _NUMERIC_START:
        if _INT.fullmatch(text):
            return int(text)
        if _FLOAT.fullmatch(text):
            return float(text)
        special = _SPECIAL.get(text)
        return text if special is None else special
    if text in _NULL:
        return None
    return _BOOL.get(text, text)


def _tagged_scalar(tag, text, line):
    """Return the value of a scalar with an explicit tag (``!!int 3``), or refuse it."""
    kind = tag[len(_TAG):] if tag.startswith(_TAG) else None
    if tag == '!' or kind == 'str':
        return text
    value = plain_scalar(text)
    if kind == 'int' and type(value) is int:
        return value
    if kind == 'float' and type(value) in (int, float):
        return float(value)
    if kind == 'bool' and type(value) is bool or kind == 'null' and value is None:
        return value
    if kind in ('int', 'float', 'bool', 'null'):
        raise DocumentError(f'line {line}: {text[:40]!r} is not a YAML 1.2 {kind}')
    raise DocumentError(f'line {line}: tag {tag[:60]!r} is not read (YAML 1.2 core schema: '
                        'str, int, float, bool, null, map, seq)')


def _key_of(value, line):
    """Return ``value`` as a mapping key: text, a number, true/false or null only."""
    if type(value) in (str, int, float, bool) or value is None:
        return value
    raise DocumentError(f'line {line}: a key must be a number or text, got a '
                        f'{type(value).__name__}')


def _json_object(pairs):
    """Build a JSON object, refusing a key given twice (json.loads' object_pairs_hook)."""
    mapping = dict(pairs)
    if len(mapping) < len(pairs):
        seen = set()
        for key, _ in pairs:
            if key in seen:
                raise DocumentError(f'key {_short(key)} given twice')
            seen.add(key)
    return mapping


def _short(value, limit=40):
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + '...'


class _TextChunks:
    """A text handed to libyaml a chunk at a time (no UTF-8 copy of the whole text)."""

    def __init__(self, text):
        self.text, self.at = text, 0
        self.lines = text.count('\n') + (not text.endswith('\n'))

    def read(self, size):
        """Return the next at most ``size`` characters ('' at the end)."""
        part = self.text[self.at:self.at + min(max(size // 4, 1), READ_CHUNK)]
        self.at += len(part)
        return part


class _FileChunks:
    """A binary file handed to libyaml a chunk at a time, its lines counted as read."""

    def __init__(self, stream, first, limit):
        self.stream, self.first, self.limit = stream, first, limit
        self.newlines, self.last, self.total = 0, b'\n', 0

    @property
    def lines(self):
        """Lines read so far (a last line without its newline counted)."""
        return self.newlines + (self.last != b'\n')

    def read(self, size):
        """Return the next at most ``size`` bytes (b'' at the end)."""
        if self.first:
            part, self.first = self.first, b''
        else:
            part = self.stream.read(size)
        if part:
            self.total += len(part)
            if self.total > self.limit:
                raise DocumentError(f'over the limit of {self.limit} bytes')
            self.newlines += part.count(b'\n')
            self.last = part[-1:]
        return part


class _Open:
    """A collection being built: its value, the key waiting for a value (mappings), size."""

    __slots__ = ('value', 'key', 'size', 'anchor', 'collector', 'mapping')

    def __init__(self, value, anchor, collector):
        self.value, self.anchor, self.collector = value, anchor, collector
        self.mapping = type(value) is dict
        self.key = _NO_KEY
        self.size = 1                  # nodes, aliases expanded


_NO_KEY = object()


def _build(stream, collect, as_text=False):
    """
    Build the one document of ``stream`` (a chunk reader) from libyaml's events.

    Returns (value, literal nodes, expanded nodes). ``collect``: {top-level key: factory};
    the list under such a key is handed item by item to ``factory()``'s ``add(item, line)``
    and becomes what its ``finish()`` returns. ``as_text``: plain scalars stay text.
    """
    parser = _Parser(stream)
    anchors, sizes = {}, {}
    stack, root, root_size, literal, documents = [], None, 0, 0, 0
    scalar_event, alias_event = events.ScalarEvent, events.AliasEvent
    mapping_start, sequence_start = events.MappingStartEvent, events.SequenceStartEvent
    mapping_end, sequence_end = events.MappingEndEvent, events.SequenceEndEvent
    get_event = parser.get_event
    try:
        while True:
            event = get_event()
            kind = type(event)
            if kind is scalar_event:
                tag = event.tag
                if tag is None and event.implicit[0] and not as_text:
                    value = plain_scalar(event.value)
                elif tag is None or tag == '!':
                    value = event.value
                else:
                    value = _tagged_scalar(tag, event.value, event.start_mark.line + 1)
                size = 1
                literal += 1
                if event.anchor is not None:
                    anchors[event.anchor], sizes[event.anchor] = value, 1
            elif kind is mapping_start or kind is sequence_start:
                literal += 1
                line = event.start_mark.line + 1
                if len(stack) >= MAX_DEPTH:
                    raise DocumentError(f'line {line}: nested too deeply (more than '
                                        f'{MAX_DEPTH} levels)')
                tag = event.tag
                if tag is not None and tag != '!' and \
                        tag != _TAG + ('map' if kind is mapping_start else 'seq'):
                    raise DocumentError(f'line {line}: tag {tag[:60]!r} is not read (YAML '
                                        '1.2 core schema: str, int, float, bool, null, map, '
                                        'seq)')
                collector = None
                if collect and kind is sequence_start and len(stack) == 1 \
                        and stack[0].mapping and stack[0].key in collect:
                    collector = collect[stack[0].key]()
                opened = _Open({} if kind is mapping_start else [], event.anchor, collector)
                if event.anchor is not None:
                    anchors[event.anchor] = opened          # open: an alias to it recurses
                stack.append(opened)
                continue
            elif kind is mapping_end or kind is sequence_end:
                closed = stack.pop()
                value = closed.value if closed.collector is None else closed.collector.finish()
                size = closed.size
                if closed.anchor is not None:
                    anchors[closed.anchor], sizes[closed.anchor] = value, size
            elif kind is alias_event:
                value = anchors.get(event.anchor, _NO_KEY)
                line = event.start_mark.line + 1
                if value is _NO_KEY:
                    raise DocumentError(f'line {line}: alias *{event.anchor} names no anchor')
                if type(value) is _Open:        # inside the collection it names
                    raise DocumentError('a YAML alias refers to a node that holds it (a '
                                        'recursive structure): refused')
                size = sizes[event.anchor]
            elif kind is events.DocumentStartEvent:
                documents += 1
                if documents > 1:
                    raise DocumentError(f'line {event.start_mark.line + 1}: a second '
                                        'document: expected one')
                continue
            elif kind is events.StreamEndEvent:
                break
            else:                                           # stream start, document end
                continue
            if not stack:
                root, root_size = value, size
                continue
            top = stack[-1]
            top.size += size
            if top.mapping:
                if top.key is _NO_KEY:
                    key = _key_of(value, event.start_mark.line + 1)
                    if key == '<<' and kind is scalar_event and event.implicit[0]:
                        raise DocumentError(f'line {event.start_mark.line + 1}: a merge key '
                                            '(<<) is YAML 1.1, not 1.2: write the fields out')
                    if key in top.value:
                        raise DocumentError(f'line {event.start_mark.line + 1}: key '
                                            f'{_short(key)} given twice')
                    top.key = key
                else:
                    top.value[top.key] = value
                    top.key = _NO_KEY
            elif top.collector is not None:
                top.collector.add(value, event.start_mark.line + 1)
            else:
                top.value.append(value)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        # libyaml marks a problem found at the end of the text on the line after the last.
        where = f'line {min(mark.line + 1, max(1, stream.lines))}: ' if mark is not None \
            else ''
        problem = getattr(error, 'problem', None) or str(error).splitlines()[0]
        raise DocumentError(f'{where}not valid YAML or JSON: {problem[:80]}') from None
    finally:
        if hasattr(parser, 'dispose'):
            parser.dispose()
    return root, literal, root_size


def _yaml(stream, collect, as_text=False):
    value, literal, expanded = _build(stream, collect, as_text)
    if expanded > ALIAS_EXPANSION * literal + ALIAS_ALLOWANCE:
        raise DocumentError(f'YAML aliases expand {literal} nodes to {expanded}: refused '
                            f'(at most {ALIAS_EXPANSION}x)')
    return value


def looks_like_json(start):
    """Tell whether a text starting with ``start`` (str or bytes) may be a JSON document."""
    head = start.lstrip()[:1]
    return head in ('{', '[', b'{', b'[')


def load_document(text, collect=None, as_text=False):
    """
    Return the value of one YAML 1.2 or JSON document ``text`` (str, or UTF-8 bytes).

    JSON (which YAML mostly contains) is tried first for a text that starts as an object
    or a list, so that JSON's NaN and Infinity are read as numbers (for the readers to
    refuse). ``collect``: see :func:`_build` (YAML only); ``as_text``: YAML's plain scalars
    are kept as the text written (a map of strings, as rosbag2's custom_data). Raises
    :class:`DocumentError`.
    """
    if isinstance(text, (bytes, bytearray)):
        try:
            text = text.decode('utf-8')
        except UnicodeDecodeError:
            raise DocumentError('not UTF-8 text') from None
    if not isinstance(text, str):
        raise DocumentError(f'expected text, got {type(text).__name__}')
    try:
        if looks_like_json(text[:64]):
            try:
                return json.loads(text, object_pairs_hook=_json_object)
            except json.JSONDecodeError:
                pass                                    # not JSON: YAML then
        return _yaml(_TextChunks(text), collect, as_text)
    except RecursionError:                               # json.loads recurses per level
        raise DocumentError(f'nested too deeply (more than {MAX_DEPTH} levels)') from None


def load_stream(stream, start, limit, collect=None, as_text=False):
    """
    Return the value of the YAML 1.2 document read from ``stream`` (binary) as a stream.

    ``start``: bytes already read from it; ``limit``: the most bytes to read; ``collect``
    and ``as_text`` as :func:`load_document`'s. The text is never held whole. Raises
    :class:`DocumentError`.
    """
    reader = _FileChunks(stream, start, limit)
    return _yaml(reader, collect, as_text)


def open_regular(path):
    """
    Open ``path`` for reading, binary, refusing anything but a regular file.

    A FIFO, a device or a socket is refused (reading one could block or never end); the
    file is opened without blocking and checked after opening, so a swap between a check
    and the open changes nothing. Raises :class:`DocumentError` (not a regular file) or
    OSError (absent, unreadable).
    """
    descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    try:
        mode = os.fstat(descriptor).st_mode
        if not stat.S_ISREG(mode):
            raise DocumentError(f'{path}: {file_kind(mode)}, not a regular file: refused')
        os.set_blocking(descriptor, True)
        return os.fdopen(descriptor, 'rb')
    except BaseException:
        os.close(descriptor)
        raise


def file_kind(mode):
    """Name the kind of file ``mode`` (``st_mode``) is: 'a FIFO (named pipe)', ..."""
    for test, name in ((stat.S_ISDIR, 'a directory'), (stat.S_ISFIFO, 'a FIFO (named pipe)'),
                       (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
                       (stat.S_ISSOCK, 'a socket'), (stat.S_ISREG, 'a regular file')):
        if test(mode):
            return name
    return 'not a file'


def read_document(path, limit, as_text=False):
    """
    Return the value of the YAML 1.2 or JSON document in the regular file at ``path``.

    ``limit``: the most bytes the file may have; ``as_text`` as :func:`load_document`'s.
    Raises :class:`DocumentError` naming the path (not a regular file, too large, not
    valid) or OSError (absent, unreadable).
    """
    with open_regular(path) as stream:
        try:
            size = os.fstat(stream.fileno()).st_size
            if size > limit:
                raise DocumentError(f'{size} bytes, over the limit of {limit} bytes')
            start = stream.read(64)
            if looks_like_json(start):
                data = start + stream.read(limit + 1 - len(start))
                if len(data) > limit:                           # grown since
                    raise DocumentError(f'over the limit of {limit} bytes')
                return load_document(data, as_text=as_text)
            return load_stream(stream, start, limit, as_text=as_text)
        except DocumentError as error:
            raise DocumentError(f'{path}: {error}') from None


class _Dumper(yaml.SafeDumper):
    """PyYAML's safe dumper, quoting text that YAML 1.2 would read as something else."""

    def resolve(self, kind, value, implicit):
        """Resolve as YAML 1.1 does, but never to text what the 1.2 core reads otherwise."""
        tag = super().resolve(kind, value, implicit)
        if kind is yaml.ScalarNode and implicit[0] and tag == _TAG + 'str' \
                and type(plain_scalar(value)) is not str:
            return _TAG + 'float'              # not text: the emitter quotes the text
        return tag


def dump_document(data):
    """
    Return ``data`` (plain data) as YAML text that YAML 1.1 and 1.2 readers read back alike.

    PyYAML writes text such as ``1e5`` plain (YAML 1.1 reads it as text, 1.2 as a
    number); here such text is quoted. Keys in the order given.
    """
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=False)
