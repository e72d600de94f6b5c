"""
Plausibility of a valid layout: warnings (never errors) for likely unit mistakes.

:mod:`cvc_balance.physics.layout` rejects what cannot be used; a layout can be valid
and still say something its author did not mean: ``angle: 90`` (degrees typed into
the radians field), ``radius: 620`` (millimetres for metres), ``mass: 60000`` (grams
for kilograms). :func:`layout_warnings` names each such field in one line, in the
layout contract's words, and leaves the layout as it is: the commands print the
warnings, the node logs them and puts them in its diagnostics, the rerun view shows
them with the layout.
"""

import math

import numpy as np

from cvc_balance.physics.frames import STANDARD_GRAVITY

LONGEST = 100.0
"""m: no rotor this package is for has a radius, length or axial position this long."""

MASS_RATIO = 1000.0
"""A point mass heavier than this many times the median of the others is suspect."""

DENSITY_RANGE = (5.0, 30000.0)
"""kg/m^3 a component's mass over its shape's volume may have: foam to beyond osmium
(22 590 kg/m^3, the densest element). Shapes stand for hollow housings too, so the low
end is generous."""

MASS_PEERS = 3
"""Fewest other components for a median to compare a mass with."""

GRAVITY_RANGE = (9.0, 10.5)
"""m/s^2: Earth's gravity is 9.78-9.83; 0 (no gravity) is allowed too."""


def layout_warnings(layout):
    """
    Return the plausibility warnings of a validated Layout, one line each (a tuple).

    Empty when nothing looks mistaken. Checks: angles beyond a full turn, lengths
    of :data:`LONGEST` m or more, a shaped component's density outside
    :data:`DENSITY_RANGE`, a point mass far above the others', gravity that is
    neither 0 nor Earth's.
    """
    warnings = []
    components = layout.components
    mass, radius, angle, z = layout.placement
    # Checked as arrays, then described one by one: a layout may have 10^6 components.
    suspects = (np.abs(angle) > 2.0 * math.pi) | (np.abs(radius) >= LONGEST) \
        | (np.abs(z) >= LONGEST)
    volumes = [(k, c, _volume(c.shape)) for k, c in layout.bodies]    # None: no volume
    shaped = [k for k, c, volume in volumes if c.shape is not None
              and _suspect_shape(c, volume)]
    for k in sorted(set(np.flatnonzero(suspects).tolist()) | set(shaped)):
        c = components[k]
        where = f"component '{c.name}'"
        if abs(c.angle) > 2.0 * math.pi:
            warnings.append(
                f'{where}: angle {c.angle:.6g} rad ({math.degrees(c.angle):.6g} deg) is more '
                'than a full turn: degrees in the radians field? (angle_deg takes degrees)')
        for field, value in _lengths(c):
            if abs(value) >= LONGEST:
                warnings.append(f'{where}: field {field} {value:g} m is {LONGEST:g} m or more: '
                                'millimetres for metres? (lengths are in m)')
        warnings += _density(c, where)
    points = np.ones(len(components), dtype=bool)          # no volume: point masses
    points[[k for k, _, volume in volumes if volume is not None]] = False
    warnings += _mass_outliers(mass[points], np.flatnonzero(points), components)
    for s in layout.supports:
        if abs(s.z) >= LONGEST:
            warnings.append(f"support '{s.name}': field z {s.z:g} m is {LONGEST:g} m or more: "
                            'millimetres for metres? (lengths are in m)')
    balancing = layout.balancing
    for field, value in ([('balancing.planes', z) for z in balancing.planes or ()]
                         + [('balancing.correction_radius', balancing.correction_radius)]):
        if value is not None and abs(value) >= LONGEST:
            warnings.append(f'layout: field {field} {value:g} m is {LONGEST:g} m or more: '
                            'millimetres for metres? (lengths are in m)')
    g = math.sqrt(sum(v * v for v in layout.gravity))
    low, high = GRAVITY_RANGE
    if g != 0.0 and not low <= g <= high:
        warnings.append(f'layout: field gravity has magnitude {g:.6g} m/s^2, neither 0 nor '
                        f"Earth's ({STANDARD_GRAVITY} m/s^2): other units?")
    return tuple(warnings)


def _suspect_shape(component, volume):
    """Tell whether a shaped component (``volume`` m^3) may warn: a length or density."""
    shape = component.shape
    if max(shape.radius, shape.length, shape.outer_radius, *shape.size) >= LONGEST:
        return True
    low, high = DENSITY_RANGE
    return bool(volume) and not low <= component.mass / volume <= high


def _lengths(component):
    """(field, value m) of a component's lengths: placement and shape."""
    yield 'radius', component.radius
    yield 'z', component.z
    shape = component.shape
    if shape is None:
        return
    for key in ('radius', 'length', 'inner_radius', 'outer_radius'):
        value = getattr(shape, key)
        if value:
            yield f'shape.{key}', value
    for i, value in enumerate(shape.size):
        yield f'shape.size[{i}]', value


def _density(component, where):
    """Warn (a list of one) when a shaped component's density is no material's."""
    volume = _volume(component.shape)
    if not volume:
        return []
    density = component.mass / volume
    low, high = DENSITY_RANGE
    if density > high:
        why = 'denser than any material: grams for kilograms? (masses are in kg)'
    elif density < low:
        why = 'lighter than foam: a mass or a shape in other units?'
    else:
        return []
    return [f'{where}: mass {component.mass:g} kg in its shape ({volume:.4g} m^3) is '
            f'{density:.4g} kg/m^3, {why}']


def _volume(shape):
    """Volume (m^3) of a shape; None for a point mass or no shape."""
    if shape is None or shape.type == 'point':
        return None
    if shape.type == 'cylinder':
        return math.pi * shape.radius ** 2 * shape.length
    if shape.type == 'tube':
        return math.pi * (shape.outer_radius ** 2 - shape.inner_radius ** 2) * shape.length
    if shape.type == 'box':
        return shape.size[0] * shape.size[1] * shape.size[2]
    return 4.0 / 3.0 * math.pi * shape.radius ** 3


def _mass_outliers(masses, indices, components):
    """
    Warnings for point masses above MASS_RATIO times the median of the others'.

    ``masses`` (kg) of the point masses, components[``indices``] (arrays).
    """
    if len(masses) <= MASS_PEERS:
        return []
    order = np.argsort(masses, kind='stable')
    ordered = masses[order]
    last = len(ordered) - 1
    # Where each mass sits in the sorted ones: (the place of) a copy of its own mass.
    # Any copy will do (taking out one of equal masses leaves the same others), so the
    # inverse of the sort, not a search (0.27 s for 10^6 in random order).
    where = np.empty(len(masses), dtype=np.intp)
    where[order] = np.arange(len(masses))

    def of_others(j):
        """Element j of the sorted masses without the component's own (one copy)."""
        return np.where(j < where, ordered[min(j, last)], ordered[min(j + 1, last)])
    middle = last // 2                              # the others are `last` masses
    median = of_others(middle) if last % 2 else 0.5 * (of_others(middle - 1) + of_others(middle))
    warnings = []
    for k in np.flatnonzero(masses > MASS_RATIO * median).tolist():
        c, m = components[int(indices[k])], float(median[k])
        warnings.append(f"component '{c.name}': mass {c.mass:g} kg is "
                        f'{c.mass / m:.0f} times the median of the others '
                        f'({m:g} kg): grams for kilograms? (masses are in kg)')
    return warnings
