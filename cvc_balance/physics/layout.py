"""
The layout: which components sit where on the rotor, and its supports.

This module owns the layout contract (docs/reference/layout_file.md is written from it): it
turns a mapping (parsed from YAML or JSON) into a validated, immutable
:class:`Layout`, or raises :class:`LayoutError` with one line naming the
component and the field that is wrong. Lengths m, masses kg, angles rad
(``angle_deg`` accepted at the edge), gravity m/s^2 in the stator frame.
No file I/O: :mod:`cvc_balance.physics.layout_file` reads files and text.
"""

from dataclasses import asdict, dataclass, replace
from functools import cached_property
import hashlib
import json
import math
import re

import numpy as np

from cvc_balance.physics import limits
from cvc_balance.physics.frames import DEFAULT_GRAVITY, radians, tensor_from_elements
from cvc_balance.physics.limits import MAX_ANGLE, MAX_MAGNITUDE  # noqa: F401 (for field/)

SHAPE_FIELDS = {
    'point': (),
    'cylinder': ('radius', 'length'),
    'tube': ('inner_radius', 'outer_radius', 'length'),
    'box': ('size',),
    'sphere': ('radius',),
}
AXIAL_SHAPES = ('cylinder', 'tube')
AXES = ('radial', 'tangential', 'axial')
INERTIA_FIELDS = ('ixx', 'iyy', 'izz', 'ixy', 'ixz', 'iyz')
DEFAULT_GRADE = 6.3
"""ISO 21940-11 grade (mm/s) when a layout names none: general machinery."""
MAX_COMPONENTS = 2_000_000
"""Most components a layout may have (aggregating 10^6 is the tested extreme)."""
MAX_NAME = 200
"""Longest name of a layout, component or support, characters."""
SITE_PLANES = ('I', 'II')
"""Names of the correction planes that ``balancing.sites`` may give weight sites for."""
ROTATIONS = ('positive', 'negative')
"""balancing.sites.rotation: the sense of omega (positive: rotor X toward rotor Y)."""
NUMBERINGS = ('with_rotation', 'against_rotation')
"""balancing.sites.<plane>.numbering: which way the hole numbers run."""
MAX_SITES = 720
"""Most weight sites per plane (threaded holes every half degree)."""
MAX_WEIGHT_SIZES = 20
"""Most weight sizes a kit may list per plane."""
MAX_STACK = 20
"""Most weights that may stack at one site."""
SUPPORT_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
"""A support's name: a ROS name token, since it names the topic supports/<name>/load."""


class LayoutError(ValueError):
    """A layout that cannot be used; ``str()`` is one line naming what is wrong."""


@dataclass(frozen=True)
class Shape:
    """A component's solid shape, lengths in m, ``size`` = (radial, tangential, axial)."""

    type: str
    radius: float = 0.0
    length: float = 0.0
    inner_radius: float = 0.0
    outer_radius: float = 0.0
    size: tuple = ()
    axis: str = 'axial'

    @property
    def extent(self):
        """Largest dimension of the shape, m (0 for a point)."""
        if self.type == 'box':
            return max(self.size)
        if self.type in ('cylinder', 'tube'):
            return max(2.0 * max(self.radius, self.outer_radius), self.length)
        return 2.0 * self.radius


@dataclass(frozen=True)
class Component:
    """
    One rigid component bolted to the rotor.

    ``radius`` (m), ``angle`` (rad, from rotor X toward rotor Y) and ``z`` (m)
    place its centre of mass. Its own inertia is ``shape`` or ``inertia``
    (URDF tensor elements about the centre of mass, own frame); with neither
    it is a point mass.
    """

    name: str
    mass: float
    radius: float
    angle: float
    z: float = 0.0
    shape: Shape = None
    inertia: tuple = None


BEARING_TYPES = {'ball': 3.0, 'roller': 10.0 / 3.0}
"""A bearing's type and ISO 281's life exponent p for it."""
BEARING_FIELDS = ('C', 'type', 'X', 'Y', 'e', 'a1', 'limit_speed')
"""The fields of a support's ``bearing``, as the layout file names them."""


@dataclass(frozen=True)
class Bearing:
    """
    What a support's bearing is, for ISO 281's basic rating life.

    ``C``: the basic dynamic load rating, N (the maker's catalogue); ``type``: 'ball' or
    'roller' (the life exponent p 3 or 10/3); ``X``, ``Y``: the radial and axial load
    factors of P = X Fr + Y Fa (default 1 and 0: radial only); ``e``: the Fa / Fr beyond
    which they hold (up to it P = Fr; None: always); ``a1``: the life adjustment factor
    for reliability (1: L10, 90 %); ``limit_speed``: the maker's limiting speed, rad/s
    (None: not said).
    """

    C: float
    type: str = 'ball'
    X: float = 1.0
    Y: float = 0.0
    e: float = None
    a1: float = 1.0
    limit_speed: float = None

    @property
    def exponent(self):
        """Return ISO 281's life exponent p: 3 for ball, 10/3 for roller bearings."""
        return BEARING_TYPES[self.type]


@dataclass(frozen=True)
class Support:
    """
    A bearing on the spin axis at ``z`` (m); ``axial`` takes the thrust.

    ``bearing``: what the bearing is (:class:`Bearing`), None when the layout does not say.
    """

    name: str
    z: float
    axial: bool = False
    bearing: Bearing = None


@dataclass(frozen=True)
class WeightSites:
    """
    Where correction weights can go in one correction plane, and the kit's weights.

    ``plane`` 'I' or 'II'; ``angles`` rad (rotor frame, from rotor X toward rotor Y) of
    the threaded holes or weight-stack sites; ``radius`` m of the weights' centres of
    mass; ``masses`` kg, the weight sizes the kit has (ascending), any number of each;
    ``stack`` how many weights may go on one site. ``first_hole`` rad: the site numbered 1
    (the reference mark), and ``numbering`` 'with_rotation' or 'against_rotation': which
    way the numbers run (None: the sites are not numbered); ``rotation`` 'positive' (the
    rotor turns from rotor X toward rotor Y, omega > 0) or 'negative' (``sites.rotation``,
    None when not said).
    """

    plane: str
    angles: tuple
    radius: float
    masses: tuple
    stack: int = 1
    first_hole: float = None
    numbering: str = None
    rotation: str = None


@dataclass(frozen=True)
class Balancing:
    """
    Balancing settings: correction planes, radius, ISO grade, service speed, weight sites.

    ``planes`` = (z_I, z_II), m, z_I < z_II, or None (then the two supports';
    with one support, no two-plane resolution). ``correction_radius`` m or
    None (then the largest component radius). ``grade`` mm/s.
    ``service_speed`` rad/s or None (then the speed asked about). ``sites``: a
    :class:`WeightSites` per plane that has fixed sites (empty: weights anywhere).
    """

    planes: tuple = None
    correction_radius: float = None
    grade: float = DEFAULT_GRADE
    service_speed: float = None
    sites: tuple = ()

    def sites_of(self, plane):
        """Return the :class:`WeightSites` of plane 'I' or 'II', or None."""
        return next((s for s in self.sites if s.plane == plane), None)


@dataclass(frozen=True)
class Layout:
    """
    A validated layout; ``gravity`` m/s^2 in the stator frame.

    ``components``: a tuple of :class:`Component`, or the same sequence held as columns
    (a :class:`~cvc_balance.physics.component_table.ComponentTable`, as big JSON layouts
    are read), which offers its own ``placement``, ``bodies`` and ``canonical_json``.
    """

    name: str
    components: tuple
    supports: tuple
    gravity: tuple = DEFAULT_GRAVITY
    balancing: Balancing = Balancing()
    description: str = ''

    @cached_property
    def placement(self):
        """Components' mass (kg), R (m), theta (rad), z (m): four read-only (n,) arrays."""
        columns = getattr(self.components, 'placement', None)    # a ComponentTable's own
        if columns is None:
            columns = tuple(np.array([getattr(c, key) for c in self.components], dtype=float)
                            for key in ('mass', 'radius', 'angle', 'z'))
            for column in columns:
                column.flags.writeable = False
        return columns

    @cached_property
    def bodies(self):
        """(index, Component) of the components with a shape or an inertia, in order."""
        bodies = getattr(self.components, 'bodies', None)         # a ComponentTable's own
        if bodies is not None:
            return tuple(bodies.items())                             # kept in index order
        return tuple((k, c) for k, c in enumerate(self.components)
                     if c.shape is not None or c.inertia is not None)

    def digest(self):
        """Short SHA-256 of the layout's canonical JSON: same layout, same digest."""
        return self._digest

    @cached_property
    def _digest(self):
        sha = hashlib.sha256()
        for part in self._canonical_parts():
            sha.update(part if isinstance(part, bytes) else part.encode())
        return sha.hexdigest()[:12]

    def canonical_json(self):
        """
        Return the layout's canonical JSON: that of dataclasses.asdict, keys sorted, compact.

        Built part by part (a point mass's text by one format), without asdict's deep
        copies: 10^6 components took 16 s through asdict and json.dumps, here 3-3.5 s on
        the loaded 2-core machine, most of it Python's exact float repr (0.67 us each);
        components read as columns (a ComponentTable) write theirs faster, the same text.
        Layouts without weight sites keep the digest they had before sites existed.
        """
        return ''.join(part if isinstance(part, str) else part.decode()
                       for part in self._canonical_parts())

    def _canonical_parts(self):
        """Yield the canonical JSON in parts (str; bytes for a ComponentTable's components)."""
        def dumps(value):
            return json.dumps(value, sort_keys=True, separators=(',', ':'))
        balancing = asdict(self.balancing)
        if not self.balancing.sites:
            del balancing['sites']
        # Fields added later appear only when given: older layouts keep their digests.
        for plane_sites in balancing.get('sites', ()):
            for key in ('first_hole', 'numbering', 'rotation'):
                if plane_sites[key] is None:
                    del plane_sites[key]
        fast = getattr(self.components, 'canonical_json', None)   # a ComponentTable's own
        parts = {'balancing': dumps(balancing), 'description': dumps(self.description),
                 'gravity': dumps(self.gravity), 'name': dumps(self.name),
                 'supports': dumps([_support_record(s) for s in self.supports]),
                 'components': fast() if fast is not None
                 else '[' + ','.join(map(component_json, self.components)) + ']'}
        for k, key in enumerate(sorted(parts)):
            yield f'{"," if k else "{"}{dumps(key)}:'
            yield parts[key]
        yield '}'

    def correction_planes(self):
        """(z_I, z_II) in m, or None when neither given nor two supports."""
        if self.balancing.planes is not None:
            return self.balancing.planes
        if len(self.supports) == 2:
            return tuple(sorted(s.z for s in self.supports))
        return None

    def correction_radius(self):
        """
        Radius (m) at which correction masses go.

        Default: the largest component radius; when every component is centred on the
        axis (within :data:`limits.DIVISOR_RADIUS`'s micrometre), the largest half-extent of
        their shapes (a drum's rim); 0 when there is none of a micrometre either (then no
        correction mass can be given).
        """
        if self.balancing.correction_radius is not None:
            return self.balancing.correction_radius
        # A radius a mass is divided by: below its limit (a micrometre) there is no rim.
        least = limits.DIVISOR_RADIUS.low
        radius = float(self.placement[1].max())
        if radius >= least:
            return radius
        radius = max((c.shape.extent / 2 for _, c in self.bodies if c.shape is not None),
                     default=0.0)
        return radius if radius >= least else 0.0


def _support_record(support):
    """Return a support as its canonical mapping: ``bearing`` only when given (old digests)."""
    record = asdict(support)
    if support.bearing is None:
        del record['bearing']
    return record


def _json_string(text):
    """Return json.dumps(text): at once for printable ASCII without quotes or backslashes."""
    if text.isascii() and text.isprintable() and '"' not in text and '\\' not in text:
        return f'"{text}"'
    return json.dumps(text)


def component_json(c):
    """Return a component's canonical JSON (json.dumps of its asdict, keys sorted, compact)."""
    if c.shape is None and c.inertia is None:     # floats: json writes float.__repr__
        return (f'{{"angle":{c.angle!r},"inertia":null,"mass":{c.mass!r},"name":'
                f'{_json_string(c.name)},"radius":{c.radius!r},"shape":null,"z":{c.z!r}}}')
    return json.dumps({'name': c.name, 'mass': c.mass, 'radius': c.radius, 'angle': c.angle,
                       'z': c.z, 'shape': None if c.shape is None else asdict(c.shape),
                       'inertia': c.inertia}, sort_keys=True, separators=(',', ':'))


_LAYOUT_FIELDS = ('name', 'description', 'components', 'supports', 'gravity', 'balancing')


def parse_layout(data):
    """
    Validate a mapping (parsed YAML/JSON) into a :class:`Layout`.

    Raises :class:`LayoutError` naming the first thing that is wrong.
    """
    components = check_head(data)
    _list(components, 'layout: field components')
    check_count(len(components))
    parsed = tuple(_plain_component(item) or _component(item, i)
                   for i, item in enumerate(components))
    unique_names([c.name for c in parsed])
    return layout_with_components(data, parsed)


def check_head(data):
    """
    Check what a layout mapping says before its components: a mapping, known fields, a name.

    Returns its field ``components`` (not checked). Raises :class:`LayoutError`: the name's
    error comes before any component's (the name is kept by :func:`layout_with_components`).
    """
    _mapping(data, 'layout')
    _known_keys(data, _LAYOUT_FIELDS, 'layout')
    _text(_required(data, 'name', 'layout'), 'layout: field name', limit=MAX_NAME)
    return _required(data, 'components', 'layout')


def check_count(count):
    """Refuse a layout of ``count`` components unless 1 <= count <= MAX_COMPONENTS."""
    if count < 1:
        raise LayoutError('layout: field components: needs at least one component')
    if count > MAX_COMPONENTS:
        raise LayoutError(f'layout: field components: {count} components, over the '
                          f'limit of {MAX_COMPONENTS}')


def unique_names(names):
    """Refuse components' ``names`` (a list) when one is given twice, naming it."""
    _unique(names, 'component')


def component(item, index):
    """Validate component ``item`` (a mapping; ``index`` from 0) into a Component."""
    return _plain_component(item) or _component(item, index)


def layout_with_components(data, components):
    """
    Validate the rest of a layout mapping around its validated ``components``.

    ``components``: a tuple of Components or a ComponentTable. The rest: name, supports,
    gravity, balancing, description.

    ``data``'s own ``components`` field is not read. Raises :class:`LayoutError`.
    """
    _mapping(data, 'layout')
    _known_keys(data, _LAYOUT_FIELDS, 'layout')
    name = _text(_required(data, 'name', 'layout'), 'layout: field name', limit=MAX_NAME)
    supports = _supports(_required(data, 'supports', 'layout'))
    gravity = DEFAULT_GRAVITY
    if 'gravity' in data:
        gravity = _vector(data['gravity'], 3, 'layout: field gravity', limits.GRAVITY)
    balancing = _balancing(data.get('balancing', {}))
    if balancing.sites and balancing.planes is None and len(supports) != 2:
        raise LayoutError('layout: field balancing.sites: weight sites need two correction '
                          'planes (give balancing.planes, or two supports)')
    description = _text(data.get('description', ''), 'layout: field description',
                        allow_empty=True)
    if len(description) > 100 * MAX_NAME:
        raise LayoutError(f'layout: field description: {len(description)} characters, over '
                          f'the limit of {100 * MAX_NAME}')
    return Layout(name, components, supports, gravity, balancing, description)


_COMPONENT_FIELDS = ('name', 'mass', 'radius', 'angle', 'angle_deg', 'z', 'shape', 'inertia')
_PLAIN_FIELDS = frozenset({'name', 'mass', 'radius', 'angle', 'z'})
_FLOAT = (float, int)


def _plain_component(item):
    """
    Return the point-mass component ``item`` describes when all is plainly well, else None.

    The common case of a big layout, checked without building a message per field (10^6
    components); anything unusual or wrong goes to :func:`_component`, which names it.
    """
    if type(item) is not dict or not item.keys() <= _PLAIN_FIELDS or len(item) < 4:
        return None
    name, mass, radius = item.get('name'), item.get('mass'), item.get('radius')
    angle, z = item.get('angle'), item.get('z', 0.0)
    if not (type(name) is str and 0 < len(name) <= MAX_NAME and name.isprintable()
            and type(mass) in _FLOAT and type(radius) in _FLOAT and type(angle) in _FLOAT
            and type(z) in _FLOAT):
        return None
    try:
        mass, radius, angle, z = float(mass), float(radius), float(angle), float(z)
    except OverflowError:                  # an integer of hundreds of digits
        return None
    if not (limits.MASS.contains(mass) and limits.RADIUS.contains(radius)
            and limits.ANGLE.contains(angle) and limits.POSITION.contains(z)):
        return None
    return point_mass(name, mass, radius, angle, z)


def plain_columns(names, mass, radius, angle, z):
    """
    Tell whether point masses given as columns are all plainly well (vectorised).

    The checks of :func:`_plain_component` over ``names`` (list) and four float arrays,
    plus unique names: a layout read as columns (10^6 components) is checked this way,
    and read the careful way, which names what is wrong, when this says False.
    """
    n = len(names)
    if not 0 < n <= MAX_COMPONENTS:
        return False
    lengths = np.fromiter(map(len, names), dtype=np.int64, count=n)
    joined = ''.join(names)
    return bool(lengths.min() > 0 and lengths.max() <= MAX_NAME and joined.isprintable()
                and np.all(plain_rows(mass, radius, angle, z)) and len(set(names)) == n)


def plain_rows(mass, radius, angle, z):
    """Tell, row by row, whether point masses' numbers (float arrays) are within limits."""
    def within(values, limit):
        return (values >= limit.low) & (values <= limit.high)      # NaN: False
    return within(mass, limits.MASS) & within(radius, limits.RADIUS) \
        & within(angle, limits.ANGLE) & within(z, limits.POSITION)


def point_mass(name, mass, radius, angle, z, shape=None, inertia=None):
    """
    Return Component(name, mass, radius, angle, z, shape, inertia), made at speed.

    For values already validated (a point mass unless ``shape`` or ``inertia``).
    """
    # The frozen dataclass's __init__ sets each field through object.__setattr__ (1 us
    # of 3 per component); its fields set at once give the same value.
    component = object.__new__(Component)
    component.__dict__.update(name=name, mass=mass, radius=radius, angle=angle, z=z,
                              shape=shape, inertia=inertia)
    return component


def _component(item, index):
    where = f'component #{index + 1}'
    _mapping(item, where)
    if isinstance(item.get('name'), str) and item['name']:
        where = f"component {short(item['name'])}"
    _known_keys(item, _COMPONENT_FIELDS, where)
    name = _text(_required(item, 'name', where), f'{where}: field name', limit=MAX_NAME)
    mass = _number(_required(item, 'mass', where), f'{where}: field mass', limits.MASS)
    radius = _number(_required(item, 'radius', where), f'{where}: field radius',
                     limits.RADIUS)
    angle = _angle(item, where)
    z = _number(item.get('z', 0.0), f'{where}: field z')
    return Component(name, mass, radius, angle, z, *_own_inertia(item, where))


def body_component(name, mass, radius, angle, z, given):
    """
    Return a Component read as columns with the fields in ``given`` (parsed values).

    For readers that check name, mass (kg), radius (m), angle (rad; NaN: not given) and
    z (m) over whole columns (:func:`plain_columns`): ``given`` holds what the columns
    do not, angle_deg, shape or inertia, validated here as for any component. Raises
    :class:`LayoutError`.
    """
    where = f'component {short(name)}'
    fields = dict(given) if math.isnan(angle) else {'angle': angle, **given}
    return point_mass(name, mass, radius, _angle(fields, where), z,
                      *_own_inertia(fields, where))


def _angle(item, where):
    """Return the angle (rad) of a component's mapping: its field angle, or angle_deg."""
    if ('angle' in item) == ('angle_deg' in item):
        raise LayoutError(f'{where}: give exactly one of fields angle (rad) and angle_deg')
    if 'angle' in item:
        return _number(item['angle'], f'{where}: field angle', limits.ANGLE)
    return radians(_number(item['angle_deg'], f'{where}: field angle_deg', limits.ANGLE_DEG))


def _own_inertia(item, where):
    """Return (shape, inertia) of a component's mapping, each None when not given."""
    if 'shape' in item and 'inertia' in item:
        raise LayoutError(f'{where}: give field shape or field inertia, not both')
    shape = _shape(item['shape'], where) if 'shape' in item else None
    inertia = _inertia(item['inertia'], where) if 'inertia' in item else None
    return shape, inertia


def _plain_shape(spec):
    """
    Return the Shape ``spec`` describes when all is plainly well, else None.

    As :func:`_plain_component` for the common case (10^5 shaped components), without a
    message per field; anything unusual or wrong goes to :func:`_shape`, which names it.
    """
    kind = spec.get('type') if type(spec) is dict else None
    fields = SHAPE_FIELDS.get(kind) if type(kind) is str else None
    axis = spec.get('axis', 'axial') if fields is not None else None
    if fields is None or len(spec) != 1 + len(fields) + ('axis' in spec) or (
            'axis' in spec and kind not in AXIAL_SHAPES) or type(axis) is not str \
            or axis not in AXES:
        return None
    values = {}
    for key in fields:
        value = spec.get(key)
        numbers = value if key == 'size' and type(value) is list and len(value) == 3 \
            else (value,)
        if not all(type(v) in _FLOAT and limits.SHAPE_LENGTH.contains(v) for v in numbers):
            return None
        values[key] = tuple(map(float, numbers)) if key == 'size' else float(value)
    if kind == 'tube' and not values['inner_radius'] < values['outer_radius']:
        return None
    return Shape(kind, axis=axis, **values)


def _shape(spec, where):
    plain = _plain_shape(spec)
    if plain is not None:
        return plain
    _mapping(spec, f'{where}: field shape')
    kind = spec.get('type')
    if not isinstance(kind, str) or kind not in SHAPE_FIELDS:
        raise LayoutError(f'{where}: field shape.type: unknown shape {short(kind)}, '
                          f'expected one of {", ".join(SHAPE_FIELDS)}')
    allowed = ('type',) + SHAPE_FIELDS[kind] + (('axis',) if kind in AXIAL_SHAPES else ())
    _known_keys(spec, allowed, f'{where}: field shape ({kind})')
    values = {}
    for key in SHAPE_FIELDS[kind]:
        field = f'{where}: field shape.{key}'
        if key == 'size':
            values[key] = _vector(_required(spec, key, f'{where}: field shape'), 3, field,
                                  limits.SHAPE_LENGTH)
        else:
            values[key] = _number(_required(spec, key, f'{where}: field shape'), field,
                                  limits.SHAPE_LENGTH)
    if kind == 'tube' and not values['inner_radius'] < values['outer_radius']:
        raise LayoutError(f'{where}: field shape.inner_radius must be less than outer_radius')
    if 'axis' in spec and (not isinstance(spec['axis'], str) or spec['axis'] not in AXES):
        raise LayoutError(f'{where}: field shape.axis: unknown axis {short(spec["axis"])}, '
                          f'expected one of {", ".join(AXES)}')
    return Shape(kind, axis=spec.get('axis', 'axial'), **values)


def _inertia(spec, where):
    _mapping(spec, f'{where}: field inertia')
    _known_keys(spec, INERTIA_FIELDS, f'{where}: field inertia')
    values = tuple(_number(_required(spec, k, f'{where}: field inertia'),
                           f'{where}: field inertia.{k}', limits.INERTIA)
                   for k in INERTIA_FIELDS)
    _check_physical(values, where)
    return values


def _check_physical(elements, where):
    """Reject tensors no body has: principal moments >= 0, triangle inequality."""
    moments = sorted(np.linalg.eigvalsh(tensor_from_elements(*elements)))
    slack = 1e-9 * max(abs(sum(moments)), 1e-300)
    low, mid, high = moments
    if low < -slack or low + mid < high - slack:
        raise LayoutError(f'{where}: field inertia: not the inertia of a body (principal '
                          f'moments {low:.6g}, {mid:.6g}, {high:.6g} kg m^2 must be >= 0 '
                          'and satisfy the triangle inequality)')


def _supports(value):
    items = _list(value, 'layout: field supports')
    if not 1 <= len(items) <= 2:
        raise LayoutError(f'layout: field supports: needs 1 or 2 supports, got {len(items)}')
    supports = []
    for i, item in enumerate(items):
        where = f'support #{i + 1}'
        _mapping(item, where)
        if isinstance(item.get('name'), str) and item['name']:
            where = f"support {short(item['name'])}"
        _known_keys(item, ('name', 'z', 'axial', 'bearing'), where)
        name = _text(_required(item, 'name', where), f'{where}: field name', limit=MAX_NAME)
        if not SUPPORT_NAME.fullmatch(name):
            raise LayoutError(f'{where}: field name must be a ROS name token (letters, digits '
                              'and _, not starting with a digit): it names the topic '
                              'supports/<name>/load')
        z = _number(_required(item, 'z', where), f'{where}: field z')
        axial = item.get('axial', False)
        if not isinstance(axial, bool):
            raise LayoutError(f'{where}: field axial must be true or false, got {short(axial)}')
        bearing = _bearing(item['bearing'], where) if 'bearing' in item else None
        supports.append(Support(name, z, axial, bearing))
    _unique([s.name for s in supports], 'support')
    if len(supports) == 2:
        if supports[0].z == supports[1].z:
            raise LayoutError('layout: field supports: the two supports need different z')
        limits.check(abs(supports[1].z - supports[0].z), limits.SPACING,
                     'layout: field supports: the spacing of the two supports', LayoutError)
        if sum(s.axial for s in supports) != 1:
            raise LayoutError('layout: field supports: mark exactly one of the two supports '
                              'axial: true (it takes the axial force)')
    return tuple(supports)


def _bearing(spec, where):
    """Validate a support's ``bearing`` mapping into a :class:`Bearing`."""
    where = f'{where}: field bearing'
    _mapping(spec, where)
    _known_keys(spec, BEARING_FIELDS, where)
    rating = _number(_required(spec, 'C', where), f'{where}.C', limits.LOAD_RATING)
    kind = spec.get('type', 'ball')
    if not isinstance(kind, str) or kind not in BEARING_TYPES:
        raise LayoutError(f'{where}.type: unknown bearing type {short(kind)}, expected one of '
                          f'{", ".join(BEARING_TYPES)} (life exponent 3 or 10/3)')
    factors = {key: _number(spec[key], f'{where}.{key}', limits.LOAD_FACTOR)
               for key in ('X', 'Y') if key in spec}
    if factors.get('X', 1.0) == 0.0 and factors.get('Y', 0.0) == 0.0:
        raise LayoutError(f'{where}: X and Y are both 0: the equivalent load would be 0 '
                          '(radial only: X 1, Y 0)')
    e = _number(spec['e'], f'{where}.e', limits.LIMIT_RATIO) if 'e' in spec else None
    a1 = _number(spec.get('a1', 1.0), f'{where}.a1', limits.RELIABILITY_FACTOR)
    speed = None
    if 'limit_speed' in spec:
        speed = _number(spec['limit_speed'], f'{where}.limit_speed', limits.LIMITING_SPEED)
    return Bearing(rating, kind, factors.get('X', 1.0), factors.get('Y', 0.0), e, a1, speed)


def _balancing(spec):
    _mapping(spec, 'layout: field balancing')
    _known_keys(spec, ('planes', 'correction_radius', 'grade', 'service_speed', 'sites'),
                'layout: field balancing')
    planes = None
    if 'planes' in spec:
        planes = _vector(spec['planes'], 2, 'layout: field balancing.planes', limits.POSITION)
        if not planes[0] < planes[1]:
            raise LayoutError('layout: field balancing.planes: give [z_I, z_II] with '
                              'z_I < z_II')
        limits.check(planes[1] - planes[0], limits.SPACING,
                     'layout: field balancing.planes: the spacing z_II - z_I', LayoutError)
    radius = None
    if 'correction_radius' in spec:
        radius = _number(spec['correction_radius'], 'layout: field balancing.correction_radius',
                         limits.DIVISOR_RADIUS)
    grade = _number(spec.get('grade', DEFAULT_GRADE), 'layout: field balancing.grade',
                    limits.GRADE)
    speed = None
    if 'service_speed' in spec:
        speed = _number(spec['service_speed'], 'layout: field balancing.service_speed',
                        limits.SPEED)
    sites = _sites(spec['sites']) if 'sites' in spec else ()
    return Balancing(planes, radius, grade, speed, sites)


def _sites(spec):
    where = 'layout: field balancing.sites'
    _mapping(spec, where)
    _known_keys(spec, SITE_PLANES + ('rotation',), where)
    rotation = spec.get('rotation')
    if rotation not in (None,) + ROTATIONS:
        raise LayoutError(f'{where}.rotation must be one of {", ".join(ROTATIONS)}, got '
                          f'{short(rotation)}')
    sites = tuple(replace(_plane_sites(spec[plane], plane), rotation=rotation)
                  for plane in SITE_PLANES if plane in spec)
    numbered = [s.plane for s in sites if s.numbering is not None]
    if numbered and rotation is None:
        raise LayoutError(f'{where}.{numbered[0]}.numbering counts with or against the '
                          f'rotation: give {where}.rotation (positive: rotor X toward rotor Y)')
    return sites


def _plane_sites(spec, plane):
    where = f'layout: field balancing.sites.{plane}'
    _mapping(spec, where)
    _known_keys(spec, ('angles', 'angles_deg', 'radius', 'masses', 'stack',
                       'first_hole_angle_deg', 'numbering'), where)
    if ('angles' in spec) == ('angles_deg' in spec):
        raise LayoutError(f'{where}: give exactly one of fields angles (rad) and angles_deg')
    key = 'angles' if 'angles' in spec else 'angles_deg'
    values = _bounded_list(spec[key], f'{where}.{key}', MAX_SITES)
    bound = limits.ANGLE if key == 'angles' else limits.ANGLE_DEG
    angles = [_number(v, f'{where}.{key}[{i}]', bound) for i, v in enumerate(values)]
    if key == 'angles_deg':
        angles = [radians(a) for a in angles]
    wrapped = sorted(math.remainder(a, 2.0 * math.pi) % (2.0 * math.pi) for a in angles)
    gaps = [b - a for a, b in zip(wrapped, wrapped[1:] + [wrapped[0] + 2.0 * math.pi])]
    if len(angles) > 1 and min(gaps) < 1e-9:
        raise LayoutError(f'{where}.{key}: two sites at the same angle')
    radius = _number(_required(spec, 'radius', where), f'{where}.radius',
                     limits.DIVISOR_RADIUS)
    masses = _bounded_list(_required(spec, 'masses', where), f'{where}.masses',
                           MAX_WEIGHT_SIZES)
    masses = sorted(_number(v, f'{where}.masses[{i}]', limits.WEIGHT_MASS)
                    for i, v in enumerate(masses))
    if len(set(masses)) != len(masses):
        raise LayoutError(f'{where}.masses: each weight size once')
    stack = spec.get('stack', 1)
    if isinstance(stack, bool) or not isinstance(stack, int) or not 1 <= stack <= MAX_STACK:
        raise LayoutError(f'{where}.stack must be a whole number from 1 to {MAX_STACK}, '
                          f'got {short(stack)}')
    first_hole = numbering = None
    if ('first_hole_angle_deg' in spec) != ('numbering' in spec):
        raise LayoutError(f'{where}: give both first_hole_angle_deg and numbering, or neither')
    if 'numbering' in spec:
        numbering = spec['numbering']
        if numbering not in NUMBERINGS:
            raise LayoutError(f'{where}.numbering must be one of {", ".join(NUMBERINGS)}, got '
                              f'{short(numbering)}')
        first = radians(_number(spec['first_hole_angle_deg'], f'{where}.first_hole_angle_deg',
                                limits.ANGLE_DEG))
        first_hole = next((a for a in angles if abs(math.remainder(a - first, 2.0 * math.pi))
                           < 1e-9), None)
        if first_hole is None:
            raise LayoutError(f'{where}.first_hole_angle_deg: no site at '
                              f'{math.degrees(first):g} deg (hole 1 is one of the sites)')
    return WeightSites(plane, tuple(angles), radius, tuple(masses), stack, first_hole,
                       numbering)


def _bounded_list(value, where, limit):
    if not isinstance(value, list) or not 1 <= len(value) <= limit:
        raise LayoutError(f'{where} must be a list of 1 to {limit} numbers, got {short(value)}')
    return value


def _required(mapping, key, where):
    if key not in mapping:
        raise LayoutError(f'{where}: missing field {key}')
    return mapping[key]


def _mapping(value, where):
    if not isinstance(value, dict):
        raise LayoutError(f'{where}: expected a mapping of fields, got {_kind(value)}')


def _list(value, where):
    if not isinstance(value, list):
        raise LayoutError(f'{where}: expected a list, got {_kind(value)}')
    return value


def _known_keys(mapping, allowed, where):
    for key in mapping:
        if key not in allowed:
            raise LayoutError(f'{where}: unknown field {short(key)} (known: {", ".join(allowed)})')


def _text(value, where, allow_empty=False, limit=None):
    if not isinstance(value, str) or (not value and not allow_empty):
        raise LayoutError(f'{where} must be a non-empty string, got {short(value)}')
    if limit is not None and (len(value) > limit or not value.isprintable()):
        raise LayoutError(f'{where} must be one line of at most {limit} printable characters, '
                          f'got {short(value)}')
    return value


def _number(value, where, limit=limits.POSITION):
    """Return ``value`` as a float within ``limit`` (a :class:`limits.Limit`), or refuse it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LayoutError(f'{where} must be a number, got {short(value)}')
    if isinstance(value, int) and not limit.low <= value <= limit.high:
        # before float(): 10^400 overflows
        raise LayoutError(limit.message(where, short(value)))
    value = float(value)
    if not math.isfinite(value):
        raise LayoutError(f'{where} must be finite, got {value}')
    return limits.check(value, limit, where, LayoutError)


def _vector(value, length, where, limit):
    if not isinstance(value, list) or len(value) != length:
        raise LayoutError(f'{where} must be a list of {length} numbers, got {short(value)}')
    return tuple(_number(v, f'{where}[{i}]', limit) for i, v in enumerate(value))


def _unique(names, what):
    seen = set()
    for name in names:
        if name in seen:
            raise LayoutError(f"{what} '{name}': duplicate name (names must be unique)")
        seen.add(name)


def _kind(value):
    return type(value).__name__


def one_line(message, limit=300):
    """Return ``message`` (any object's str) on one line, cut to about ``limit`` characters."""
    text = ' '.join(str(message).split())
    return text if len(text) <= limit else text[:limit] + f'... ({len(text)} characters)'


def _plain_scalar(item):
    """Tell whether ``item`` prints in a few characters (a number, a short string, None)."""
    if item is None or isinstance(item, (bool, float)):
        return True
    if isinstance(item, int):
        return item.bit_length() <= 64
    return isinstance(item, str) and len(item) <= 20


def short(value, limit=40):
    """
    Return ``value`` for an error message: one line, at most about ``limit`` characters.

    Containers are described, not printed (a bad value may be megabytes), except a short
    list of plain scalars, which says more printed (``[0.0, -9.8]``).
    """
    if isinstance(value, (list, tuple)) and len(value) <= 6 and all(map(_plain_scalar, value)):
        text = repr(list(value))
        if len(text) <= limit:
            return text
    if isinstance(value, (dict, list, tuple, set)):
        return f'a {_kind(value)} of {len(value)} items'
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f'an integer of about {int(value.bit_length() * 0.30103) + 1} digits'
    if isinstance(value, str) and len(value) > limit:
        return repr(value[:limit]) + f'... ({len(value)} characters)'
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + '...'
