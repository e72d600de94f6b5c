"""
Read a layout from a YAML or JSON file or text (the layout topic's payload), safely.

Text from anyone (a file, a latched topic) goes through limits before it costs anything:
its size, its nesting depth, YAML aliases (an alias "bomb" of a few hundred bytes expands
to hundreds of millions of nodes), duplicate keys (YAML and JSON would silently take the
last). Whatever goes wrong, the caller gets one :class:`LayoutError` naming it, never
another exception type.
"""

from array import array
from contextlib import contextmanager
import gc
import math
from operator import attrgetter
import os
from typing import Any

import msgspec
import numpy as np

from cvc_balance.physics import documents
from cvc_balance.physics.component_table import ComponentTable
from cvc_balance.physics.documents import DocumentError
from cvc_balance.physics.layout import (body_component, check_count, check_head, component,
                                        layout_with_components, LayoutError, MAX_COMPONENTS,
                                        MAX_NAME, parse_layout, plain_columns, plain_rows,
                                        unique_names)

MAX_TEXT_BYTES = 256 * 2**20
"""Largest layout text, bytes (10^6 components as JSON take about 90 MB)."""
MAX_YAML_BYTES = 64 * 2**20
"""Largest YAML layout, bytes (about 600 000 components): YAML is read event by event,
about 20 times slower than JSON's columns; bigger layouts are to be written as JSON."""


def layout_from_text(text, source='layout'):
    """
    Parse YAML or JSON text into a validated Layout.

    JSON (which YAML mostly contains) is tried first so that JSON's NaN and
    Infinity are read as numbers and then rejected by the validation. YAML 1.2
    (:mod:`~cvc_balance.physics.documents`), its components collected as columns.
    Raises :class:`LayoutError` with one line naming the problem, whatever it is.
    """
    if isinstance(text, (bytes, bytearray)):
        try:
            text = text.decode('utf-8')
        except UnicodeDecodeError:
            raise LayoutError(f'{source}: layout is not UTF-8 text') from None
    if not isinstance(text, str):
        raise LayoutError(f'{source}: layout must be text, got {type(text).__name__}')
    _check_size(len(text), documents.looks_like_json(text[:64]), source)
    with _one_line(source):
        layout = _read_columns(text)
        return layout if layout is not None else _layout_of(
            documents.load_document(text, collect=_COLLECT))


def load_layout(path):
    """
    Read and validate the layout file at ``path`` (a regular file: never a FIFO or device).

    JSON is read whole (as columns when plainly well); YAML as a stream, its components
    collected as columns, so the text is never held whole. Raises :class:`LayoutError`.
    """
    source = str(path)
    try:
        stream = documents.open_regular(path)
    except OSError as error:
        raise LayoutError(f'{path}: cannot read layout file: {error.strerror}') from None
    except DocumentError as error:
        raise LayoutError(str(error)) from None
    with stream, _one_line(source):
        size = os.fstat(stream.fileno()).st_size
        start = stream.read(64)
        is_json = documents.looks_like_json(start)
        _check_size(size, is_json, source)
        if is_json:
            data = start + stream.read(MAX_TEXT_BYTES + 1 - len(start))
            try:
                text = data.decode('utf-8')
            except UnicodeDecodeError:
                raise LayoutError(f'{path}: layout file is not UTF-8 text') from None
            del data
            return layout_from_text(text, source)
        return _layout_of(documents.load_stream(stream, start, MAX_YAML_BYTES,
                                                collect=_COLLECT))


def _check_size(size, is_json, source):
    """Refuse a layout text of ``size`` bytes over its limit (YAML's is lower: use JSON)."""
    if size > MAX_TEXT_BYTES:
        raise LayoutError(f'{source}: layout text of {size} bytes is over the limit of '
                          f'{MAX_TEXT_BYTES} bytes')
    if not is_json and size > MAX_YAML_BYTES:
        raise LayoutError(f'{source}: a YAML layout of {size} bytes is over the limit of '
                          f'{MAX_YAML_BYTES} bytes for YAML: write it as JSON (read as '
                          'columns, 10^6 components in about 3 s)')


@contextmanager
def _one_line(source):
    """Turn whatever reading a layout raises into one LayoutError that starts with ``source``."""
    try:
        with collector_paused():
            yield
    except (LayoutError, DocumentError) as error:
        message = str(error)
        raise LayoutError(message if message.startswith(source) else f'{source}: {message}') \
            from None
    except RecursionError:      # the JSON parser recurses per level of nesting
        raise LayoutError(f'{source}: nested too deeply (a layout needs 5 levels)') from None
    except MemoryError:
        raise LayoutError(f'{source}: layout too large for memory') from None


@contextmanager
def collector_paused():
    """
    Pause Python's cyclic garbage collector while a layout is read (or prepared).

    Reading makes objects by the million and holds them all (no garbage): each of the
    collector's full passes over them was wasted, ~1 s of 3.5 s for 10^6 components
    with 10^5 shapes. Reference counting goes on; the collector is resumed after, if it
    ran before (so pauses may nest).
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _layout_of(value):
    """Validate a parsed layout document (components as columns or a list) into a Layout."""
    components = check_head(value)
    if not isinstance(components, _ComponentColumns):
        return parse_layout(value)
    table = components.table()
    return layout_with_components(value, table)


_PLAIN_FIELDS = frozenset(('name', 'mass', 'radius', 'angle', 'z'))


class _ComponentColumns:
    """
    A YAML layout's components, collected item by item as columns (names, four arrays).

    A point mass plainly written (fields name, mass, radius, angle and z, of the right
    types) costs a name and four floats; any other item (a shape, angle_deg, a wrong
    value) is kept whole and validated at the end as :func:`parse_layout` would, which
    names what is wrong.
    """

    def __init__(self):
        """Start with no components."""
        self.names = []
        self.columns = tuple(array('d') for _ in range(4))      # mass, radius, angle, z
        self.items = {}                                         # index: item kept whole

    def add(self, item, line):
        """Take the next component (a parsed item) at ``line`` of the text."""
        index = len(self.names)
        if index >= MAX_COMPONENTS:
            raise LayoutError(f'layout: field components: more than {MAX_COMPONENTS} '
                              'components, over the limit')
        row = _plain_row(item)
        if row is None:
            self.items[index] = item
            row = (None, math.nan, math.nan, math.nan, math.nan)
        self.names.append(row[0])
        for column, value in zip(self.columns, row[1:]):
            column.append(value)

    def finish(self):
        """Return itself: the list's value in the document."""
        return self

    def table(self):
        """
        Return the components as a ComponentTable, validated; raises :class:`LayoutError`.

        The first wrong component (in order) is named as :func:`parse_layout` names it.
        """
        names = self.names
        check_count(len(names))
        mass, radius, angle, z = (np.frombuffer(c, dtype=float) if len(c) else
                                  np.zeros(0) for c in self.columns)
        # Items kept whole, and rows out of range, in order: the first wrong one raises.
        wrong = np.flatnonzero(~plain_rows(mass, radius, angle, z)).tolist()
        suspects = set(self.items) | set(wrong)
        bodies = {}
        if suspects:
            mass, radius, angle, z = (np.array(c) for c in (mass, radius, angle, z))
        for k in sorted(suspects):
            item = self.items.get(k)
            if item is None:                  # a row: its mapping again, for the message
                item = {'name': names[k], 'mass': float(mass[k]), 'radius': float(radius[k]),
                        'angle': float(angle[k]), 'z': float(z[k])}
            parsed = component(item, k)
            names[k] = parsed.name
            mass[k], radius[k], angle[k], z[k] = parsed.mass, parsed.radius, parsed.angle, \
                parsed.z
            if parsed.shape is not None or parsed.inertia is not None:
                bodies[k] = parsed
        unique_names(names)
        return ComponentTable(names, (mass, radius, angle, z), bodies)


def _plain_row(item):
    """Return (name, mass, radius, angle, z) of a plainly written point mass, else None."""
    if type(item) is not dict or not item.keys() <= _PLAIN_FIELDS or len(item) < 4:
        return None
    name, mass, radius, angle = (item.get('name'), item.get('mass'), item.get('radius'),
                                 item.get('angle'))
    z = item.get('z', 0.0)
    if not (type(name) is str and 0 < len(name) <= MAX_NAME and name.isprintable()
            and type(mass) in _NUMBERS and type(radius) in _NUMBERS
            and type(angle) in _NUMBERS and type(z) in _NUMBERS):
        return None
    try:
        return name, float(mass), float(radius), float(angle), float(z)
    except OverflowError:                 # an integer of hundreds of digits
        return None


_COLLECT = {'components': _ComponentColumns}


class _ComponentDoc(msgspec.Struct, forbid_unknown_fields=True, gc=False):
    """A component as JSON gives it; NaN (which JSON cannot write) marks a field not given."""

    name: str
    mass: float
    radius: float
    angle: float = math.nan
    z: float = math.nan
    angle_deg: Any = msgspec.UNSET
    shape: Any = msgspec.UNSET
    inertia: Any = msgspec.UNSET


class _LayoutDoc(msgspec.Struct, forbid_unknown_fields=True, gc=False):
    """A layout as JSON gives it, its components typed."""

    name: Any
    components: list[_ComponentDoc]
    supports: Any
    description: Any = msgspec.UNSET
    gravity: Any = msgspec.UNSET
    balancing: Any = msgspec.UNSET


_LAYOUT_DECODER = msgspec.json.Decoder(_LayoutDoc)
_BODY_FIELDS = ('angle_deg', 'shape', 'inertia')
_HEADER_FIELDS = ('name', 'supports', 'description', 'gravity', 'balancing')


def _read_columns(text):
    r"""
    Read a JSON layout into columns (a ComponentTable) at speed, or return None.

    None whenever anything is not plainly well: then the careful reader reads the text
    again, and names what is wrong in its words. For 10^6 point masses (135 MB) this is
    msgspec's typed decoding and numpy's checks, 1-2 s, where json.loads, a dict per
    component and a Component each took 5-7 s.

    msgspec keeps the last of a key given twice where the careful reader refuses it: a
    JSON text's colons are its keys' plus those inside its strings, so a text with more
    colons than the decoded keys and strings hold had a key twice (unless a colon was
    written as the escape \u003a: then this declines).
    """
    if not text[:64].lstrip().startswith('{') or '\\' in text and (
            '\\u003a' in text or '\\u003A' in text):
        return None
    try:
        doc = _LAYOUT_DECODER.decode(text)
    except (msgspec.DecodeError, RecursionError, MemoryError):
        return None
    docs = doc.components
    n = len(docs)
    names = list(map(attrgetter('name'), docs))
    mass, radius, angle, z = (np.fromiter(map(attrgetter(key), docs), dtype=float, count=n)
                              for key in ('mass', 'radius', 'angle', 'z'))
    keys = 3 * n + int(np.count_nonzero(~np.isnan(angle))) + int(np.count_nonzero(~np.isnan(z)))
    colons = ''.join(names).count(':')
    z[np.isnan(z)] = 0.0
    header = {f: getattr(doc, f) for f in _HEADER_FIELDS
              if getattr(doc, f) is not msgspec.UNSET}
    keys += 1 + len(header)
    colons += sum(map(_colons, header.values()))
    written = text.count(':')
    bodies = {}
    # Colons beyond the point masses' keys: fields of bodies, or a key given twice.
    if written != keys + colons:
        none_given = (msgspec.UNSET,) * len(_BODY_FIELDS)
        unset = msgspec.UNSET
        for k in [k for k, fields in enumerate(map(attrgetter(*_BODY_FIELDS), docs))
                  if fields != none_given]:           # a tuple compares items by identity first
            item = docs[k]
            given = {f: getattr(item, f) for f in _BODY_FIELDS
                     if getattr(item, f) is not unset}
            keys += len(given)
            colons += sum(map(_colons, given.values()))
            try:
                component = body_component(names[k], float(mass[k]), float(radius[k]),
                                           float(angle[k]), float(z[k]), given)
            except LayoutError:
                return None
            angle[k] = component.angle
            if component.shape is not None or component.inertia is not None:
                bodies[k] = component
    if written != keys + colons or not plain_columns(names, mass, radius, angle, z):
        return None
    try:
        return layout_with_components(header, ComponentTable(names, (mass, radius, angle, z),
                                                             bodies))
    except LayoutError:
        return None


def _colons(value):
    """Keys and colons in strings within a decoded JSON value (dicts, lists, strings)."""
    count, stack = 0, [value]
    while stack:
        item = stack.pop()
        kind = type(item)
        if kind is str:
            count += item.count(':')
        elif kind is dict:
            count += len(item) + sum(key.count(':') for key in item)   # JSON keys: str
            stack.extend(item.values())
        elif kind is list:
            stack.extend(v for v in item if type(v) not in _NUMBERS)
    return count


_NUMBERS = (int, float)
