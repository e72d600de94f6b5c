"""
Design parameters: a component's mass, radius, angle or axial position, named.

A parameter is one of :data:`PARAMETERS` of one component; people name it
``COMPONENT.PARAMETER`` (``counterweight_rear.angle``). Values are SI inside
(kg, m, rad, m); degrees only where people read or type them.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from cvc_balance.physics.engine import own_elements

PARAMETERS = ('mass', 'radius', 'angle', 'z')
"""A component's design parameters, in the order of every (..., 4) array here."""

UNITS = {'mass': 'kg', 'radius': 'm', 'angle': 'rad', 'z': 'm'}
"""SI unit of each parameter."""


@dataclass(frozen=True)
class DesignParameter:
    """Parameter ``name`` (one of :data:`PARAMETERS`) of the component at ``index``."""

    index: int
    component: str
    name: str

    @property
    def column(self):
        """Column of this parameter in (..., 4) arrays."""
        return PARAMETERS.index(self.name)

    @property
    def label(self):
        """``COMPONENT.PARAMETER``, as people type it."""
        return f'{self.component}.{self.name}'


def all_parameters(layout):
    """Return every parameter of every component, component by component."""
    return tuple(DesignParameter(i, c.name, name) for i, c in enumerate(layout.components)
                 for name in PARAMETERS)


def component_index(layout, name):
    """Return the index of component ``name``; ValueError (one line) if there is none."""
    for i, component in enumerate(layout.components):
        if component.name == name:
            return i
    known = ', '.join(c.name for c in layout.components[:12])
    more = ', ...' if len(layout.components) > 12 else ''
    raise ValueError(f"unknown component {name!r} (layout {layout.name!r} has: {known}{more})")


def design_parameter(layout, component, name):
    """Return the :class:`DesignParameter` ``name`` of ``component`` (names, checked)."""
    if name not in PARAMETERS:
        raise ValueError(f"unknown parameter {name!r} (one of {', '.join(PARAMETERS)})")
    return DesignParameter(component_index(layout, component), component, name)


def parse_parameter(layout, text):
    """Read ``COMPONENT.PARAMETER`` (the last dot splits: names may hold dots)."""
    component, dot, name = text.rpartition('.')
    if not dot or not component:
        raise ValueError(f"parameter {text!r}: give COMPONENT.PARAMETER, PARAMETER one of "
                         f"{', '.join(PARAMETERS)}")
    return design_parameter(layout, component, name)


def value_of(layout, parameter):
    """Return the layout's value of ``parameter`` (SI)."""
    return getattr(layout.components[parameter.index], parameter.name)


def with_values(layout, values):
    """
    Return a copy of ``layout`` with ``values`` ({DesignParameter: SI value}) set.

    The layout contract's limits hold: mass > 0, radius >= 0, finite values;
    ValueError (one line) otherwise. A shape's own inertia follows its mass;
    a given ``inertia`` stays as given.
    """
    components = list(layout.components)
    for parameter, value in values.items():
        value = float(value)
        where = f"component {parameter.component!r}: {parameter.name}"
        if not math.isfinite(value):
            raise ValueError(f'{where} must be finite, got {value}')
        if parameter.name == 'mass' and not value > 0.0:
            raise ValueError(f'{where} must be > 0 kg, got {value:g}')
        if parameter.name == 'radius' and value < 0.0:
            raise ValueError(f'{where} must be >= 0 m, got {value:g}')
        components[parameter.index] = replace(components[parameter.index],
                                              **{parameter.name: value})
    return replace(layout, components=tuple(components))


def own_products(layout):
    """
    Return the components' own products of inertia (P_xz, P_yz), own frame: (n, 2).

    Positive integrals (int x z dm, int y z dm) about its centre of mass in its
    (radial, tangential, axial) frame. Every parametric shape is symmetric in
    that frame (none), so only a given ``inertia`` has them; they do not change
    with the component's mass, radius, angle or z (the angle turns them).
    """
    products = np.zeros((len(layout.components), 2))
    for i, component in enumerate(layout.components):
        if component.inertia is not None:
            elements = own_elements(component)
            products[i] = (-elements[4], -elements[5])       # tensor elements: minus P
    return products
