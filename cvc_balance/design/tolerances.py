"""
Tolerances of a layout's design parameters: the tolerance file, validated.

YAML (JSON accepted); the component names of the layout, or ``default``,
each with any of::

    default: {mass: 0.05, radius: 0.0005, angle_deg: 0.1, z: 0.0005}
    xray_tube: {mass: 0.3, distribution: uniform}

``mass`` kg, ``radius`` m, ``angle_deg`` (or ``angle``, rad) and ``z`` m:
the tolerance, +- about the layout's value. A component's entry overrides
``default`` field by field; what neither gives is exact (tolerance 0).
``distribution``: ``normal`` (the default: the tolerance is 3 sigma, and a
part outside it is rejected at inspection, so draws stay within it) or
``uniform`` (the tolerance is the half-width). Unknown names and fields,
negative or non-finite numbers, a mass tolerance not below the mass and an
angle tolerance over 180 deg are errors (:class:`ToleranceError`, one line).
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.design.parameters import PARAMETERS
from cvc_balance.physics import limits
from cvc_balance.physics.documents import DocumentError, load_document, read_document
from cvc_balance.physics.frames import degrees, radians

DISTRIBUTIONS = ('normal', 'uniform')
FIELDS = ('mass', 'radius', 'angle_deg', 'angle', 'z', 'distribution')
MAX_BYTES = 64 * 2**20
"""Largest tolerance file, bytes (a line per component of the largest layouts)."""
TRUNCATION = 3.0
"""A normal tolerance is TRUNCATION sigma, and draws beyond it are rejected parts."""


class ToleranceError(ValueError):
    """A tolerance file or value that cannot be used; ``str()`` is one line."""


@dataclass(frozen=True)
class Tolerances:
    """
    Tolerances of every component's parameters.

    ``values`` (n, 4): +- tolerance of mass (kg), radius (m), angle (rad), z
    (m), columns as :data:`cvc_balance.design.parameters.PARAMETERS`;
    ``normal`` (n,) bool: the component's distribution is the truncated
    normal (else uniform).
    """

    values: np.ndarray
    normal: np.ndarray

    def sigma(self):
        """Return the standard deviation of each parameter's draw, (n, 4), SI."""
        return self.values * np.where(self.normal, NORMAL_SIGMA, UNIFORM_SIGMA)[:, None]

    def scaled(self, factors):
        """Return these tolerances times ``factors`` ((n, 4) or scalar), same distributions."""
        return Tolerances(self.values * factors, self.normal)


def truncated_normal_sigma(bound=TRUNCATION):
    """Sigma of a standard normal truncated at +-b: sqrt(1 - 2 b phi(b) / (2 Phi(b) - 1))."""
    density = math.exp(-0.5 * bound * bound) / math.sqrt(2.0 * math.pi)
    inside = math.erf(bound / math.sqrt(2.0))
    return math.sqrt(1.0 - 2.0 * bound * density / inside)


NORMAL_SIGMA = truncated_normal_sigma() / TRUNCATION
"""Sigma per unit of tolerance, normal (tolerance = 3 sigma, truncated there): 0.3289."""
UNIFORM_SIGMA = 1.0 / math.sqrt(3.0)
"""Sigma per unit of tolerance (the half-width), uniform: 0.5774."""


TYPICAL = {'mass': 0.005, 'radius': 0.5e-3, 'angle': radians(0.1), 'z': 0.5e-3}
"""Typical tolerances to rank sensitivities by: mass 0.5 % of the component's, radius and
z 0.5 mm, angle 0.1 deg (about 1 mm at 0.6 m), each 3 sigma of a normal."""


def typical_tolerances(layout):
    """Return the :data:`TYPICAL` tolerances for every component of ``layout``."""
    mass = layout.placement[0]
    values = np.column_stack([TYPICAL['mass'] * mass]
                             + [np.full(len(mass), TYPICAL[name]) for name in PARAMETERS[1:]])
    return Tolerances(values, np.ones(len(mass), dtype=bool))


def tolerances_from_mapping(data, layout, source='tolerances'):
    """Validate a mapping (parsed YAML/JSON) against ``layout`` into :class:`Tolerances`."""
    if not isinstance(data, dict) or not data:
        raise ToleranceError(f'{source}: expected a mapping of component names (or default) '
                             f'to tolerances, got {_kind(data)}')
    names = [c.name for c in layout.components]
    for key in data:
        if key != 'default' and key not in names:
            known = ', '.join(names[:12]) + (', ...' if len(names) > 12 else '')
            raise ToleranceError(f"{source}: unknown component {key!r} (layout "
                                 f"{layout.name!r} has: {known}; or default)")
    default = _entry(data.get('default', {}), f'{source}: default')
    values = np.zeros((len(names), 4))
    normal = np.ones(len(names), dtype=bool)
    for i, component in enumerate(layout.components):
        where = f'{source}: component {component.name!r}'
        entry = dict(default)
        if component.name in data:
            entry.update(_entry(data[component.name], where))
        for column, name in enumerate(PARAMETERS):
            values[i, column] = entry.get(name, 0.0)
        normal[i] = entry.get('distribution', 'normal') == 'normal'
        if values[i, 0] >= component.mass:
            raise ToleranceError(f'{where}: mass tolerance {values[i, 0]:g} kg must be less '
                                 f'than its mass {component.mass:g} kg')
    return Tolerances(values, normal)


def tolerances_from_text(text, layout, source='tolerances'):
    """Parse YAML 1.2 or JSON text (keys once) into :class:`Tolerances` for ``layout``."""
    try:
        data = load_document(text)
    except DocumentError as error:
        raise ToleranceError(f'{source}: {error}') from None
    return tolerances_from_mapping(data, layout, source)


def load_tolerances(path, layout):
    """Read and validate the tolerance file at ``path`` (a regular file) for ``layout``."""
    try:
        data = read_document(path, MAX_BYTES)
    except OSError as error:
        raise ToleranceError(f'{path}: cannot read tolerance file: {error.strerror}') from None
    except DocumentError as error:
        message = str(error)
        raise ToleranceError(message if message.startswith(str(path)) else f'{path}: {message}') \
            from None
    return tolerances_from_mapping(data, layout, str(path))


def describe(tolerances, index, column):
    """Describe a tolerance for people: '+-0.5 mm (3 sigma)', '+-0.1 deg (uniform)'."""
    value = tolerances.values[index, column]
    name = PARAMETERS[column]
    if name == 'angle':
        text = f'+-{degrees(value):.4g} deg'
    elif name == 'mass':
        text = f'+-{value:.4g} kg'
    else:
        text = f'+-{value * 1e3:.4g} mm'
    return text + (' (3 sigma)' if tolerances.normal[index] else ' (uniform)')


def _entry(spec, where):
    """One entry's fields in SI: {parameter: tolerance, 'distribution': name}."""
    if not isinstance(spec, dict):
        raise ToleranceError(f'{where}: expected a mapping of fields, got {_kind(spec)}')
    for key in spec:
        if key not in FIELDS:
            raise ToleranceError(f"{where}: unknown field {key!r} (known: {', '.join(FIELDS)})")
    if 'angle' in spec and 'angle_deg' in spec:
        raise ToleranceError(f'{where}: give field angle_deg or angle (rad), not both')
    entry = {}
    for key in ('mass', 'radius', 'angle_deg', 'angle', 'z'):
        if key in spec:
            entry[key] = _tolerance(spec[key], f'{where}: field {key}',
                                    limits.LENGTH_TOLERANCE if key in ('radius', 'z') else None)
    if 'angle_deg' in entry:
        entry['angle'] = radians(entry.pop('angle_deg'))
    if entry.get('angle', 0.0) > math.pi:
        raise ToleranceError(f'{where}: angle tolerance {degrees(entry["angle"]):g} deg must '
                             'be at most 180 deg')
    if 'distribution' in spec:
        if spec['distribution'] not in DISTRIBUTIONS:
            raise ToleranceError(f"{where}: field distribution: unknown distribution "
                                 f"{spec['distribution']!r}, expected one of "
                                 f"{', '.join(DISTRIBUTIONS)}")
        entry['distribution'] = spec['distribution']
    return entry


def _tolerance(value, where, limit=None):
    """Return a +- tolerance: a finite number >= 0, within ``limit`` (a limits.Limit)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ToleranceError(f'{where} must be a number, got {_kind(value)} {value!r}'[:300])
    try:
        value = float(value)
    except OverflowError:                             # an integer of hundreds of digits
        value = math.inf
    if not math.isfinite(value):
        raise ToleranceError(f'{where} must be finite, got {value}')
    if value < 0.0:
        raise ToleranceError(f'{where} must be >= 0 (a +- tolerance), got {value:g}')
    if limit is not None:
        limits.check(value, limit, where, ToleranceError)
    return value


def _kind(value):
    return type(value).__name__
