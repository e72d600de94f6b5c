"""
A layout's components held as columns: the form a big layout is read into.

A layout of 10^6 point masses read into 10^6 :class:`~cvc_balance.physics.layout.Component`
objects costs about 1 us each before any physics is done; as columns (the names and four
float arrays) it costs nothing more than reading them. :class:`ComponentTable` is that:
a read-only sequence of Components, made one by one only when asked for, whose
:attr:`~ComponentTable.placement` is the columns themselves and whose canonical JSON (the
layout digest's text) is written by msgspec's float formatting instead of Python's
(0.67 us per float). It equals, and digests like, the tuple of the same Components.

Components with a shape or an inertia tensor (bodies) are kept whole beside the columns.
"""

from collections.abc import Sequence
from itertools import repeat

import msgspec
import numpy as np

from cvc_balance.physics.layout import component_json, point_mass

REPR_RANGE = (1e-4, 1e16)
"""|x| (or 0) for which msgspec writes a float as Python's repr does: the same shortest
round-trip digits (both pick the nearest of the shortest), and positional notation; outside
it repr writes 1e-05 and 1e+16 where msgspec writes 0.00001 and 1e16."""


class _PointMassJSON(msgspec.Struct, gc=False):
    """A point mass's canonical JSON object: the Component's fields, keys sorted."""

    angle: float
    inertia: None
    mass: float
    name: str
    radius: float
    shape: None
    z: float


class ComponentTable(Sequence):
    """
    Components as columns, a read-only sequence of Components.

    ``names``; ``placement`` (mass kg, R m, theta rad, z m: four read-only (n,) arrays, as
    :attr:`Layout.placement`); ``bodies``, {index: Component} of the components with a
    shape or an inertia, in index order (their placement is in the columns too).
    Validated by whoever makes it (:mod:`~cvc_balance.physics.layout_file`).
    """

    __slots__ = ('names', 'placement', 'bodies')

    def __init__(self, names, placement, bodies):
        """Hold ``names`` (list of str), ``placement`` (4 arrays (n,)), ``bodies`` (dict)."""
        self.names = names
        self.placement = tuple(np.asarray(v, dtype=float) for v in placement)
        for column in self.placement:
            column.flags.writeable = False
        self.bodies = dict(sorted(bodies.items()))

    def __len__(self):
        """Return the number of components."""
        return len(self.names)

    def __getitem__(self, index):
        """Return component ``index`` (a Component), or a tuple of them for a slice."""
        if isinstance(index, slice):
            return tuple(self[k] for k in range(*index.indices(len(self))))
        k = range(len(self))[index]              # IndexError, negative indices as a tuple's
        body = self.bodies.get(k)
        if body is not None:
            return body
        mass, radius, angle, z = self.placement
        return point_mass(self.names[k], float(mass[k]), float(radius[k]), float(angle[k]),
                          float(z[k]))

    def __iter__(self):
        """Yield the components in order, each made when reached."""
        columns = (column.tolist() for column in self.placement)
        for k, row in enumerate(zip(self.names, *columns)):
            body = self.bodies.get(k)
            yield body if body is not None else point_mass(*row)

    def __eq__(self, other):
        """Equal to a table or a tuple of the same components (as a tuple would be)."""
        if isinstance(other, ComponentTable):
            return (self.names == other.names and self.bodies == other.bodies
                    and all(np.array_equal(a, b) for a, b in zip(self.placement,
                                                                 other.placement)))
        if isinstance(other, tuple):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        return NotImplemented

    def __hash__(self):
        """Hash as the tuple of the same components."""
        return hash(tuple(self))

    def __add__(self, other):
        """Return a tuple: these components, then ``other``'s (a tuple's concatenation)."""
        if not isinstance(other, (tuple, ComponentTable)):
            return NotImplemented
        return tuple(self) + tuple(other)

    def __repr__(self):
        """Say what it holds, not 10^6 components."""
        return f'ComponentTable({len(self)} components, {len(self.bodies)} with own inertia)'

    def canonical_json(self):
        """
        Return the components' canonical JSON, UTF-8 (as :meth:`Layout.canonical_json`).

        Written by msgspec (keys sorted; a body as its dataclasses, which msgspec writes
        field by field) where that is certain to give the same text as json.dumps: names
        of printable ASCII without quotes or backslashes, numbers in :data:`REPR_RANGE`.
        Other rows are written as the tuple's are.
        """
        joined = ''.join(self.names)
        if not (joined.isascii() and joined.isprintable() and '"' not in joined
                and '\\' not in joined):
            return ('[' + ','.join(map(component_json, self)) + ']').encode()
        low, high = REPR_RANGE
        other = np.zeros(len(self), dtype=bool)
        for column in self.placement:
            size = np.abs(column)
            other |= ((size < low) | (size >= high)) & (column != 0.0)
        mass, radius, angle, z = (column.tolist() for column in self.placement)
        items = list(map(_PointMassJSON, angle, repeat(None), mass, self.names, radius,
                         repeat(None), z))
        for k, body in self.bodies.items():
            items[k] = body if _repr_safe(_numbers(body)) else \
                msgspec.Raw(component_json(body).encode())
        for k in np.flatnonzero(other).tolist():
            items[k] = msgspec.Raw(component_json(self[k]).encode())
        return msgspec.json.encode(items, order='sorted')


def _numbers(body):
    """Return the numbers of a body's own inertia: its shape's lengths or its tensor."""
    if body.inertia is not None:
        return body.inertia
    shape = body.shape
    return (shape.radius, shape.length, shape.inner_radius, shape.outer_radius, *shape.size)


def _repr_safe(values):
    """Tell whether msgspec writes each of ``values`` as repr does (:data:`REPR_RANGE`)."""
    low, high = REPR_RANGE
    return all(v == 0.0 or low <= abs(v) < high for v in values)
