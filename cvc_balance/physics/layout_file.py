"""
Read a layout from a YAML or JSON file or text (the layout topic's payload), safely.

Text from anyone (a file, a latched topic) goes through limits before it costs anything:
its size, its nesting depth, YAML aliases (an alias "bomb" of a few hundred bytes expands
to hundreds of millions of nodes), duplicate keys (YAML and JSON would silently take the
last). Whatever goes wrong, the caller gets one :class:`LayoutError` naming it, never
another exception type.
"""

from contextlib import contextmanager
import gc
import json
import math
from operator import attrgetter
from typing import Any

import msgspec
import numpy as np
import yaml

from cvc_balance.physics.component_table import ComponentTable
from cvc_balance.physics.layout import (body_component, Layout, layout_with_components,
                                        LayoutError, parse_layout, plain_columns, short)

MAX_TEXT_BYTES = 256 * 2**20
"""Largest layout text, bytes (10^6 components as JSON take about 90 MB)."""
ALIAS_EXPANSION = 4
"""YAML aliases may at most multiply a document's nodes by this (plus ALIAS_ALLOWANCE)."""
ALIAS_ALLOWANCE = 10_000

try:    # libyaml's parser (C, events): fast, and it keeps its own stack, so it is safe
    from yaml._yaml import CParser as _Parser
except ImportError:                                  # pragma: no cover
    from yaml.parser import Parser as _Parser

    class _Stream(yaml.reader.Reader, yaml.scanner.Scanner, _Parser):
        pass
    _Parser = _Stream


class _LayoutLoader(yaml.composer.Composer, _Parser, yaml.constructor.SafeConstructor,
                    yaml.resolver.Resolver):
    """
    PyYAML's safe loading, with Python's composer, that refuses duplicate keys.

    The composer is PyYAML's Python one even over libyaml's parser: libyaml's own
    (Cython) composer recurses in C per level of nesting, so 10^5 nested lists crash the
    process; the Python one raises RecursionError, which becomes a LayoutError.
    """

    def __init__(self, stream):
        """Read ``stream`` (text)."""
        _Parser.__init__(self, stream)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        yaml.composer.Composer.__init__(self)

    def construct_mapping(self, node, deep=False):
        """Construct a mapping; a key given twice is an error (YAML says keys are unique)."""
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == 'tag:yaml.org,2002:merge':
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:
                    raise LayoutError(f'line {key_node.start_mark.line + 1}: a key must be a '
                                      f'number or text, got {short(key)}') from None
                if duplicate:
                    raise LayoutError(f'line {key_node.start_mark.line + 1}: key {short(key)} '
                                      'given twice')
                seen.add(key)
        return super().construct_mapping(node, deep)


_LayoutLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                              _LayoutLoader.construct_mapping)


def layout_from_text(text, source='layout'):
    """
    Parse YAML or JSON text into a validated Layout.

    JSON (which YAML mostly contains) is tried first so that JSON's NaN and
    Infinity are read as numbers and then rejected by the validation.
    Raises :class:`LayoutError` with one line naming the problem, whatever it is.
    """
    if isinstance(text, (bytes, bytearray)):
        try:
            text = text.decode('utf-8')
        except UnicodeDecodeError:
            raise LayoutError(f'{source}: layout is not UTF-8 text') from None
    if not isinstance(text, str):
        raise LayoutError(f'{source}: layout must be text, got {type(text).__name__}')
    if len(text) > MAX_TEXT_BYTES:
        raise LayoutError(f'{source}: layout text of {len(text)} bytes is over the limit of '
                          f'{MAX_TEXT_BYTES} bytes')
    try:
        with collector_paused():
            parsed = _parse(text, source)
            return parsed if isinstance(parsed, Layout) else parse_layout(parsed)
    except LayoutError as error:
        message = str(error)
        raise LayoutError(message if message.startswith(source) else f'{source}: {message}') \
            from None
    except RecursionError:      # the JSON and YAML parsers recurse per level of nesting
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


def _parse(text, source):
    layout = _read_columns(text)
    if layout is not None:
        return layout
    try:
        return json.loads(text, object_pairs_hook=_json_object)
    except json.JSONDecodeError:
        pass                    # not JSON: YAML then
    loader = _LayoutLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_aliases(node, source)
        return loader.construct_document(node)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        # libyaml marks a problem found at the end of the text on the line after the last.
        last_line = max(1, len(text.splitlines()))
        where = f' line {min(mark.line + 1, last_line)}' if mark is not None else ''
        problem = getattr(error, 'problem', None) or str(error).splitlines()[0]
        raise LayoutError(f'{source}:{where}: not valid YAML or JSON: {short(problem, 80)}') \
            from None
    except LayoutError:
        raise                   # said already (aliases), not wrapped below as a ValueError
    except (ValueError, TypeError, IndexError, OverflowError) as error:
        # PyYAML's constructors fail like this on e.g. `!!int ` or `!!float heavy`.
        raise LayoutError(f'{source}: not valid YAML: {type(error).__name__}: '
                          f'{short(str(error), 80)}') from None
    finally:
        loader.dispose()


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


def _json_object(pairs):
    mapping = dict(pairs)
    if len(mapping) < len(pairs):       # a key given twice: say which
        seen = set()
        for key, _ in pairs:
            if key in seen:
                raise LayoutError(f'key {short(key)} given twice')
            seen.add(key)
    return mapping


def _check_aliases(root, source):
    """Refuse a YAML document whose aliases expand it beyond ALIAS_EXPANSION times."""
    literal, stack, sizes, seen = 0, [(root, False)], {}, set()
    while stack:           # iterative post-order: sizes of shared (aliased) nodes once
        node, children_done = stack.pop()
        key = id(node)
        if children_done:
            children = _children(node)
            if any(id(child) not in sizes for child in children):
                # A child begun but not finished is an ancestor: the node holds itself.
                raise LayoutError(f'{source}: a YAML alias refers to a node that holds it '
                                  '(a recursive structure): refused')
            sizes[key] = 1 + sum(sizes[id(child)] for child in children)
            continue
        if key in seen:
            continue
        seen.add(key)
        literal += 1
        stack.append((node, True))
        stack.extend((child, False) for child in _children(node) if id(child) not in seen)
    expanded = sizes[id(root)]
    if expanded > ALIAS_EXPANSION * literal + ALIAS_ALLOWANCE:
        raise LayoutError(f'{source}: YAML aliases expand {literal} nodes to {expanded}: '
                          f'refused (at most {ALIAS_EXPANSION}x)')


def _children(node):
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def load_layout(path):
    """Read and validate the layout file at ``path``."""
    try:
        with open(path, 'rb') as stream:
            data = stream.read(MAX_TEXT_BYTES + 1)
    except OSError as error:
        raise LayoutError(f'{path}: cannot read layout file: {error.strerror}') from None
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError:
        raise LayoutError(f'{path}: layout file is not UTF-8 text') from None
    return layout_from_text(text, source=str(path))
