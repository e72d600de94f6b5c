"""
The layout contract in full: every refusal's whole message, the balancing settings' effect.

The messages are part of the contract (docs: layout file; one line naming the component and the
field, then what is wrong and the value given); their whole text is written here, so that
a changed message is a decision and not an accident. In-process and fast, so that the
mutation run (benchmarks/mutation.py) can afford them; test_layout.py checks the command
line's exit code and single line for the same kinds of mistake.
"""

from collections import OrderedDict
import hashlib
import json
import math

import numpy as np
import pytest

from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import (check_count, DEFAULT_GRADE, LayoutError, one_line,
                                        parse_layout, plain_columns, short)


def good():
    """Return a valid layout mapping: two components, two supports, no balancing settings."""
    return {'name': 'ok',
            'components': [{'name': 'tube', 'mass': 60.0, 'radius': 0.6, 'angle_deg': 0.0,
                            'z': 0.05, 'shape': {'type': 'cylinder', 'radius': 0.09,
                                                 'length': 0.35, 'axis': 'tangential'}},
                           {'name': 'detector', 'mass': 50.0, 'radius': 0.4,
                            'angle_deg': 180.0}],
            'supports': [{'name': 'front', 'z': -0.25},
                         {'name': 'rear', 'z': 0.25, 'axial': True}]}


def component(index, **change):
    def edit(layout):
        layout['components'][index].update(change)
    return edit


def drop(index, key, where='components'):
    def edit(layout):
        layout[where][index].pop(key)
    return edit


def top(**change):
    def edit(layout):
        layout.update(change)
    return edit


def shape(**spec):
    return component(0, shape=spec)


def support(index, **change):
    def edit(layout):
        layout['supports'][index].update(change)
    return edit


BOX = {'ixx': 1.0, 'iyy': 1.0, 'izz': 1.0, 'ixy': 0.0, 'ixz': 0.0, 'iyz': 0.0}
REFUSED = [
    # layout
    (lambda d: d.clear() or d.update(name='x'), 'layout: missing field components'),
    (lambda d: d.pop('name'), 'layout: missing field name'),
    (lambda d: d.pop('supports'), 'layout: missing field supports'),
    (top(name=''), "layout: field name must be a non-empty string, got ''"),
    (top(name=3), 'layout: field name must be a non-empty string, got 3'),
    (top(description=4), 'layout: field description must be a non-empty string, got 4'),
    (top(components={}), 'layout: field components: expected a list, got dict'),
    (top(components=[]), 'layout: field components: needs at least one component'),
    (top(colour='red'), "layout: unknown field 'colour' (known: name, description, "
                        'components, supports, gravity, balancing)'),
    (top(gravity=[0.0, -9.8]), 'layout: field gravity must be a list of 3 numbers, got '
                               '[0.0, -9.8]'),
    (top(gravity=[0.0, 'down', 0.0]), "layout: field gravity[1] must be a number, got 'down'"),
    (top(gravity=[0.0, math.inf, 0.0]), 'layout: field gravity[1] must be finite, got inf'),
    # components
    (lambda d: d['components'].append([]), 'component #3: expected a mapping of fields, '
                                           'got list'),
    (drop(1, 'name'), 'component #2: missing field name'),
    (component(1, name=''), "component #2: field name must be a non-empty string, got ''"),
    (component(1, name='tube'), "component 'tube': duplicate name (names must be unique)"),
    (drop(1, 'mass'), "component 'detector': missing field mass"),
    (component(0, mass=True), "component 'tube': field mass must be a number, got True"),
    (component(0, mass=0.0), "component 'tube': field mass must be from 1e-06 to 1e+12 kg "
                             '(a milligram or more: lighter is no part, and divides mass '
                             'ratios to inf), got 0 kg'),
    (component(0, mass=math.nan), "component 'tube': field mass must be finite, got nan"),
    (drop(1, 'radius'), "component 'detector': missing field radius"),
    (component(1, radius=-0.1), "component 'detector': field radius must be from 0 to "
                                '1e+12 m (0 on the spin axis), got -0.1 m'),
    (component(1, angle=1.0), "component 'detector': give exactly one of fields angle (rad) "
                              'and angle_deg'),
    (drop(1, 'angle_deg'), "component 'detector': give exactly one of fields angle (rad) "
                           'and angle_deg'),
    (component(1, angle_deg='north'), "component 'detector': field angle_deg must be a "
                                      "number, got 'north'"),
    (lambda d: d['components'][1].pop('angle_deg') and d['components'][1].update(angle=None),
     "component 'detector': field angle must be a number, got None"),
    (component(1, z=math.inf), "component 'detector': field z must be finite, got inf"),
    (component(1, colour='red'), "component 'detector': unknown field 'colour' (known: "
                                 'name, mass, radius, angle, angle_deg, z, shape, inertia)'),
    (component(0, inertia=BOX), "component 'tube': give field shape or field inertia, not "
                                'both'),
    # shapes
    (component(0, shape='round'), "component 'tube': field shape: expected a mapping of "
                                  'fields, got str'),
    (shape(type='cone'), "component 'tube': field shape.type: unknown shape 'cone', "
                         'expected one of point, cylinder, tube, box, sphere'),
    (shape(type='cylinder', radius=0.1), "component 'tube': field shape: missing field "
                                         'length'),
    (shape(type='cylinder', radius=0.0, length=0.2), "component 'tube': field shape.radius "
                                                     'must be from 1e-06 to 1e+12 m (a '
                                                     'micrometre or more: no solid part is '
                                                     'thinner, and a density is the mass over '
                                                     'the volume), got 0 m'),
    (shape(type='cylinder', radius=0.1, length=0.2, axis='diagonal'),
     "component 'tube': field shape.axis: unknown axis 'diagonal', expected one of radial, "
     'tangential, axial'),
    (shape(type='sphere', radius=0.1, axis='radial'),
     "component 'tube': field shape (sphere): unknown field 'axis' (known: type, radius)"),
    (shape(type='box'), "component 'tube': field shape: missing field size"),
    (shape(type='box', size=[0.1, 0.2]), "component 'tube': field shape.size must be a list "
                                         'of 3 numbers, got [0.1, 0.2]'),
    (shape(type='box', size=[0.1, 0.0, 0.2]), "component 'tube': field shape.size[1] must be "
                                              'from 1e-06 to 1e+12 m (a micrometre or more: '
                                              'no solid part is thinner, and a density is '
                                              'the mass over the volume), got 0 m'),
    (shape(type='tube', inner_radius=0.2, outer_radius=0.2, length=0.1),
     "component 'tube': field shape.inner_radius must be less than outer_radius"),
    (shape(type='point', radius=0.1), "component 'tube': field shape (point): unknown field "
                                      "'radius' (known: type)"),
    # given inertia
    (lambda d: d['components'][1].update(inertia=[1, 1, 1]),
     "component 'detector': field inertia: expected a mapping of fields, got list"),
    (lambda d: d['components'][1].update(inertia={k: v for k, v in BOX.items()
                                                  if k != 'iyz'}),
     "component 'detector': field inertia: missing field iyz"),
    (lambda d: d['components'][1].update(inertia=dict(BOX, ixz='big')),
     "component 'detector': field inertia.ixz must be a number, got 'big'"),
    (lambda d: d['components'][1].update(inertia=dict(BOX, jxx=1.0)),
     "component 'detector': field inertia: unknown field 'jxx' (known: ixx, iyy, izz, ixy, "
     'ixz, iyz)'),
    (lambda d: d['components'][1].update(inertia=dict(BOX, izz=3.0)),
     "component 'detector': field inertia: not the inertia of a body (principal moments 1, "
     '1, 3 kg m^2 must be >= 0 and satisfy the triangle inequality)'),
    # supports
    (top(supports={}), 'layout: field supports: expected a list, got dict'),
    (top(supports=[]), 'layout: field supports: needs 1 or 2 supports, got 0'),
    (lambda d: d['supports'].append({'name': 'mid', 'z': 0.0}),
     'layout: field supports: needs 1 or 2 supports, got 3'),
    (lambda d: d['supports'].__setitem__(0, 'front'), 'support #1: expected a mapping of '
                                                      'fields, got str'),
    (drop(0, 'name', 'supports'), 'support #1: missing field name'),
    (support(1, name=5), 'support #2: field name must be a non-empty string, got 5'),
    (drop(1, 'z', 'supports'), "support 'rear': missing field z"),
    (support(1, z='far'), "support 'rear': field z must be a number, got 'far'"),
    (support(1, stiffness=1e9), "support 'rear': unknown field 'stiffness' (known: name, z, "
                                'axial, bearing)'),
    (support(1, axial='yes'), "support 'rear': field axial must be true or false, got 'yes'"),
    (support(1, name='front'), "support 'front': duplicate name (names must be unique)"),
    (support(1, z=-0.25), 'layout: field supports: the two supports need different z'),
    (support(0, axial=True), 'layout: field supports: mark exactly one of the two supports '
                             'axial: true (it takes the axial force)'),
    (drop(1, 'axial', 'supports'), 'layout: field supports: mark exactly one of the two '
                                   'supports axial: true (it takes the axial force)'),
    # balancing
    (top(balancing=[]), 'layout: field balancing: expected a mapping of fields, got list'),
    (top(balancing={'radius': 0.6}), "layout: field balancing: unknown field 'radius' "
                                     '(known: planes, correction_radius, grade, '
                                     'service_speed, sites)'),
    (top(balancing={'planes': [0.2]}), 'layout: field balancing.planes must be a list of 2 '
                                       'numbers, got [0.2]'),
    (top(balancing={'planes': [0.2, 0.2]}), 'layout: field balancing.planes: give [z_I, '
                                            'z_II] with z_I < z_II'),
    (top(balancing={'correction_radius': 0.0}), 'layout: field balancing.correction_radius '
                                                'must be from 1e-06 to 1e+12 m (a micrometre '
                                                'or more: a correction mass is the unbalance '
                                                'over it), got 0 m'),
    (top(balancing={'grade': 0.0}), 'layout: field balancing.grade must be from 0.1 to 4000 '
                                    'mm/s (ISO 21940-11 grades run from G 0.4 to G 4000), '
                                    'got 0 mm/s'),
    (top(balancing={'grade': 'G6.3'}), "layout: field balancing.grade must be a number, "
                                       "got 'G6.3'"),
    (top(balancing={'service_speed': -1.0}), 'layout: field balancing.service_speed must be '
                                             'from 0.001 to 100000 rad/s (a turn in 100 '
                                             'minutes to 955 000 rpm: slower is no balancing '
                                             'speed, faster no rotor), got -1 rad/s'),
]


def test_a_layout_must_be_a_mapping():
    with pytest.raises(LayoutError) as error:
        parse_layout([good()])
    assert str(error.value) == 'layout: expected a mapping of fields, got list'


@pytest.mark.parametrize('change, message', REFUSED, ids=[m[:60] for _, m in REFUSED])
def test_refusal_names_what_is_wrong_in_one_line(change, message):
    layout = good()
    change(layout)
    with pytest.raises(LayoutError) as error:
        parse_layout(layout)
    assert str(error.value) == message


def test_what_is_accepted_at_the_edges():
    """Zero radius, negative z and angles, point shapes, bodies on the triangle's edge."""
    layout = good()
    layout['components'][1].update(radius=0.0, z=-0.3, angle_deg=-720.0)
    layout['components'].append({'name': 'screw', 'mass': 1e-6, 'radius': 0.5, 'angle': -7.0,
                                 'shape': {'type': 'point'}})
    # A thin disc (izz = ixx + iyy), a thin rod (one principal moment 0) and a small body
    # (trace 1e-4 kg m^2) on the edge: bodies, given to the last bit.
    layout['components'].append({'name': 'disc', 'mass': 2.0, 'radius': 0.3, 'angle': 1.0,
                                 'inertia': {'ixx': 0.1, 'iyy': 0.2, 'izz': 0.30000000000000004,
                                             'ixy': 0.0, 'ixz': 0.0, 'iyz': 0.0}})
    layout['components'].append({'name': 'rod', 'mass': 1.0, 'radius': 0.3, 'angle': 2.0,
                                 'inertia': {'ixx': 0.0, 'iyy': 0.05, 'izz': 0.05,
                                             'ixy': 0.0, 'ixz': 0.0, 'iyz': 0.0}})
    layout['components'].append({'name': 'chip', 'mass': 0.01, 'radius': 0.3, 'angle': 3.0,
                                 'inertia': {'ixx': 2e-5, 'iyy': 3e-5, 'izz': 5e-5,
                                             'ixy': 0.0, 'ixz': 0.0, 'iyz': 0.0}})
    layout['supports'] = [{'name': 'slewing', 'z': 0.0, 'axial': False}]
    layout['description'] = 'a gantry with a screw, a disc, a rod and a chip'
    parsed = parse_layout(layout)
    assert parsed.description == layout['description']
    assert [c.name for c in parsed.components] == ['tube', 'detector', 'screw', 'disc', 'rod',
                                                   'chip']
    assert parsed.components[1].angle == pytest.approx(-4 * math.pi, rel=1e-15)
    assert parsed.components[2].shape.type == 'point'
    assert parsed.supports[0].axial is False and parsed.correction_planes() is None


@pytest.mark.parametrize('elements, scale', [
    # Off the triangle by 1e-6 of the trace: refused, however small the body.
    ((1.0, 1.0, 2.000002, 0.0, 0.0, 0.0), 1.0),
    ((1.0, 1.0, 2.000002, 0.0, 0.0, 0.0), 1e-5),
    # A principal moment below zero by 1e-6 of the trace.
    ((-2e-6, 1.0, 1.0, 0.0, 0.0, 0.0), 1.0),
    ((-2e-6, 1.0, 1.0, 0.0, 0.0, 0.0), 1e-5),
])
def test_tensors_no_body_has_are_refused_at_any_size(elements, scale):
    layout = good()
    layout['components'][1]['inertia'] = dict(zip(('ixx', 'iyy', 'izz', 'ixy', 'ixz', 'iyz'),
                                                  (v * scale for v in elements)))
    with pytest.raises(LayoutError, match="component 'detector': field inertia: not the "
                                          'inertia of a body'):
        parse_layout(layout)


def test_digest_is_a_short_sha256_of_the_canonical_json():
    """
    12 hex digits of SHA-256 over the layout's fields as JSON, keys sorted, no spaces.

    The same layout (from a mapping in another order) has the same digest; any change of a
    number changes it.
    """
    layout = parse_layout(good())
    fields = {'name': 'ok', 'description': '', 'gravity': [0.0, -9.80665, 0.0],
              'balancing': {'planes': None, 'correction_radius': None, 'grade': 6.3,
                            'service_speed': None},
              'supports': [{'name': 'front', 'z': -0.25, 'axial': False},
                           {'name': 'rear', 'z': 0.25, 'axial': True}],
              'components': [
                  {'name': 'tube', 'mass': 60.0, 'radius': 0.6, 'angle': 0.0, 'z': 0.05,
                   'shape': {'type': 'cylinder', 'radius': 0.09, 'length': 0.35,
                             'inner_radius': 0.0, 'outer_radius': 0.0, 'size': [],
                             'axis': 'tangential'}, 'inertia': None},
                  {'name': 'detector', 'mass': 50.0, 'radius': 0.4, 'angle': math.pi,
                   'z': 0.0, 'shape': None, 'inertia': None}]}
    canonical = json.dumps(fields, sort_keys=True, separators=(',', ':'))
    assert layout.digest() == hashlib.sha256(canonical.encode()).hexdigest()[:12]
    reordered = {k: good()[k] for k in ('supports', 'components', 'name')}
    assert parse_layout(reordered).digest() == layout.digest()
    heavier = good()
    heavier['components'][0]['mass'] = 60.000000001
    assert parse_layout(heavier).digest() != layout.digest()


def test_balancing_settings_take_effect():
    """
    Planes, correction radius, grade and service speed as given; defaults otherwise.

    By hand: the two-plane split of ISO 21940-2 per component, U_per = G m / Omega.
    """
    layout = good()
    layout['balancing'] = {'planes': [-0.1, 0.3], 'correction_radius': 0.5, 'grade': 2.5,
                           'service_speed': 30.0}
    parsed = parse_layout(layout)
    assert parsed.correction_planes() == (-0.1, 0.3)
    assert parsed.correction_radius() == 0.5
    assessment = assess_balance(RotorModel.from_layout(parsed))
    assert (assessment.omega, assessment.grade) == (30.0, 2.5)
    u = [(60.0 * 0.6 * complex(1.0, 0.0), 0.05), (50.0 * 0.4 * complex(-1.0, 0.0), 0.0)]
    plane_1 = sum(ui * (0.3 - z) / 0.4 for ui, z in u)
    plane_2 = sum(ui * (z + 0.1) / 0.4 for ui, z in u)
    for plane, ref, z in zip(assessment.planes, (plane_1, plane_2), (-0.1, 0.3)):
        assert plane.z == z
        assert abs(complex(*plane.vector) - ref) < 1e-15 * 60.0   # measured: 1 ulp
        assert plane.correction_radius == 0.5
        assert plane.correction_mass == pytest.approx(abs(ref) / 0.5, rel=1e-15)
    assert assessment.permissible == pytest.approx(2.5e-3 * 110.0 / 30.0, rel=1e-15)
    defaults = parse_layout(good())
    assert defaults.balancing.grade == DEFAULT_GRADE == 6.3
    assert defaults.balancing.service_speed is None and defaults.balancing.planes is None
    assert defaults.correction_radius() == 0.6
    with pytest.raises(ValueError, match='service speed'):
        assess_balance(RotorModel.from_layout(defaults))
    np.testing.assert_array_equal(defaults.placement[0], [60.0, 50.0])


@pytest.mark.parametrize('change, message', [
    ({'name': ''}, "component #2: field name must be a non-empty string, got ''"),
    ({'name': 5}, 'component #2: field name must be a non-empty string, got 5'),
    ({'radius': 'x'}, "component 'detector': field radius must be a number, got 'x'"),
    ({'z': 'x'}, "component 'detector': field z must be a number, got 'x'"),
    ({'mass': 0.0}, "component 'detector': field mass must be from 1e-06 to 1e+12 kg"
                    " (a milligram or more: lighter is no part, and divides mass ratios to inf),"
                    " got 0 kg"),
])
def test_a_plain_component_is_refused_in_the_same_words(change, message):
    """A component of only name, mass, radius, angle, z is read on a fast path first."""
    layout = good()
    layout['components'][1] = {'name': 'detector', 'mass': 50.0, 'radius': 0.4,
                               'angle': 3.0, **change}
    with pytest.raises(LayoutError) as error:
        parse_layout(layout)
    assert str(error.value) == message


def test_one_line_joins_the_lines_and_cuts_at_the_limit():
    """Any whitespace run is one space; past the limit the text is cut and its length said."""
    assert one_line('a\n  b\tc ') == 'a b c'
    assert one_line(ValueError('x\ny')) == 'x y'
    words = 'word ' * 100                                     # 499 characters once joined
    assert one_line(words, 20) == 'word word word word ... (499 characters)'
    assert one_line('w' * 300) == 'w' * 300                   # the default limit: whole
    assert one_line('w' * 301) == 'w' * 300 + '... (301 characters)'


def test_point_masses_of_the_wrong_types_are_refused_not_taken_fast():
    """The fast path for plain point masses takes only str names and float or int numbers."""
    plain = {'name': 'a', 'mass': 1.0, 'radius': 0.5, 'angle': 0.0, 'z': 0.1}
    for change, said in (
            ({'name': 5}, 'component #1: field name must be a non-empty string, got 5'),
            ({'name': ''}, "component #1: field name must be a non-empty string, got ''"),
            ({'radius': '0.5'}, "component 'a': field radius must be a number, got '0.5'"),
            ({'z': '0.1'}, "component 'a': field z must be a number, got '0.1'")):
        layout = good()
        layout['components'] = [dict(plain, **change)]
        with pytest.raises(LayoutError) as refused:
            parse_layout(layout)
        assert str(refused.value) == said, change


def test_shapes_of_the_wrong_sizes_are_refused_and_any_mapping_is_read():
    """A cylinder's radius as a list, a box of 4 sizes: refused; an OrderedDict as a dict."""
    for shape, said in (
            ({'type': 'cylinder', 'radius': [0.1, 0.1, 0.1], 'length': 0.3},
             "component 'tube': field shape.radius must be a number, got [0.1, 0.1, 0.1]"),
            ({'type': 'box', 'size': [0.1, 0.2, 0.3, 0.4]},
             "component 'tube': field shape.size must be a list of 3 numbers, got "
             '[0.1, 0.2, 0.3, 0.4]')):
        layout = good()
        layout['components'][0]['shape'] = shape
        with pytest.raises(LayoutError) as refused:
            parse_layout(layout)
        assert str(refused.value) == said, shape
    ordered = good()
    ordered['components'][0]['shape'] = OrderedDict(ordered['components'][0]['shape'])
    assert parse_layout(ordered) == parse_layout(good())
    assert parse_layout(ordered).components[0].shape.axis == 'tangential'


def test_plain_columns_says_false_for_anything_the_careful_reader_would_name():
    """Names non-empty, at most 200 printable characters, unique; numbers within limits."""
    def columns(names, mass=1.0):
        n = len(names)
        return (names, np.full(n, mass), np.full(n, 0.5), np.zeros(n), np.zeros(n))
    assert plain_columns(*columns(['a', 'b'])) is True
    assert plain_columns(*columns(['a', 'b' * 200])) is True
    for names, mass in ((['a', ''], 1.0), (['a', 'b' * 201], 1.0), (['a', 'b\n'], 1.0),
                        (['a', 'a'], 1.0), (['a', 'b'], math.nan), ([], 1.0)):
        assert plain_columns(*columns(names, mass)) is False, (names, mass)


def test_short_shows_a_value_in_at_most_about_40_characters():
    """Short lists of short scalars printed, containers described, the rest cut (by hand)."""
    big = 1234567890
    cases = [
        ([0.0, -9.8], '[0.0, -9.8]'),
        ([1, 2, 3, 4, 5, 6], '[1, 2, 3, 4, 5, 6]'),
        ([1, 2, 3, 4, 5, 6, 7], 'a list of 7 items'),
        ([big, big, big, 12], '[1234567890, 1234567890, 1234567890, 12]'),    # 40: whole
        ([big, big, big, 123], 'a list of 4 items'),                           # 41
        ([{'a': 1}], 'a list of 1 items'), ([[1]], 'a list of 1 items'),
        ([2 ** 63], '[9223372036854775808]'), ([2 ** 64], 'a list of 1 items'),
        (['a' * 20], "['" + 'a' * 20 + "']"), (['a' * 21], 'a list of 1 items'),
        (2 ** 127, str(2 ** 127)),                                             # 39 digits
        (2 ** 128, 'an integer of about 39 digits'),
        ('a' * 38, "'" + 'a' * 38 + "'"),                                      # 40: whole
        ('a' * 39, "'" + 'a' * 39 + '...'),
        ('a' * 40, "'" + 'a' * 39 + '...'),
        ('a' * 41, "'" + 'a' * 40 + "'... (41 characters)"),
    ]
    for value, said in cases:
        assert short(value) == said, value


def test_supports_and_bearings_refused_word_for_word():
    """A support's name, the supports' and the planes' spacing, a bearing: the exact words."""
    spacing = ('must be from 0.001 to 2e+12 m (a millimetre or more: closer is one bearing or '
               'plane, and moments are divided by the spacing), got 0.0005 m')
    long_name = 'a' * 201

    def supports(front, rear=None):
        return lambda layout: layout.update(supports=[
            dict({'name': 'front', 'z': -0.25}, **front),
            dict({'name': 'rear', 'z': 0.25, 'axial': True}, **(rear or {}))])
    for change, said in (
            (supports({'name': '1front'}), "support '1front': field name must be a ROS name "
             'token (letters, digits and _, not starting with a digit): it names the topic '
             'supports/<name>/load'),
            (supports({'name': long_name}), f"support {short(long_name)}: field name must be "
             f'one line of at most 200 printable characters, got {short(long_name)}'),
            (supports({'z': 0.0}, {'z': 0.0005}),
             f'layout: field supports: the spacing of the two supports {spacing}'),
            (lambda layout: layout.update(balancing={'planes': [0.0, 0.0005]}),
             f'layout: field balancing.planes: the spacing z_II - z_I {spacing}'),
            (supports({'bearing': 3.0}),
             "support 'front': field bearing: expected a mapping of fields, got float"),
            (supports({'bearing': {'C': 0.0}}), "support 'front': field bearing.C must be from "
             "1 to 1e+09 N (a newton or more: the loads are divided by it, and the largest "
             "slewing bearings' C is below 10^8 N), got 0 N")):
        layout = good()
        change(layout)
        with pytest.raises(LayoutError) as refused:
            parse_layout(layout)
        assert str(refused.value) == said
    # A thrust bearing (X 0, Y 1) is a bearing; one without a limiting speed says None.
    layout = good()
    supports({'bearing': {'C': 1e5, 'X': 0.0, 'Y': 1.0}}, {'bearing': {'C': 1e5}})(layout)
    front, rear = parse_layout(layout).supports
    assert (front.bearing.X, front.bearing.Y) == (0.0, 1.0) and rear.bearing.limit_speed is None


def test_the_limits_edges_and_what_is_said_first():
    """At most 2 000 000 components, names of 200, ints at a limit; the name before components."""
    check_count(1)
    check_count(2_000_000)
    with pytest.raises(LayoutError) as refused:
        check_count(2_000_001)
    assert str(refused.value) == ('layout: field components: 2000001 components, over the '
                                  'limit of 2000000')
    layout = good()
    layout['name'] = 'n' * 200
    layout['components'][1]['z'] = 10 ** 12                  # an int at the limit, 1e12 m
    assert parse_layout(layout).components[1].z == 1e12
    layout['name'] = 'n' * 201
    layout['components'][1]['mass'] = -1.0                   # the name is said first
    with pytest.raises(LayoutError) as refused:
        parse_layout(layout)
    assert str(refused.value) == ('layout: field name must be one line of at most 200 printable '
                                  f"characters, got {short('n' * 201)}")
    for field, value, said in (
            ('angle', 2e9, 'angle must be within +-1e+09 rad (the reduction to a turn stays '
             'exact), got 2e+09 rad'),
            ('angle_deg', 1e11, 'angle_deg must be within +-5.72958e+10 deg (the reduction to '
             'a turn stays exact), got 1e+11 deg')):
        layout = good()
        layout['components'][1].pop('angle_deg')
        layout['components'][1][field] = value
        with pytest.raises(LayoutError) as refused:
            parse_layout(layout)
        assert str(refused.value) == f"component 'detector': field {said}"
    ordered = good()
    ordered['components'][0]['shape'] = OrderedDict(type='cylinder', radius=0.09, length=0.35)
    assert parse_layout(ordered).components[0].shape.axis == 'axial'


def test_the_correction_radius_of_a_rotor_centred_on_its_axis():
    """Every component on the axis: the largest half-extent of the shapes, from a micrometre."""
    def radius(first, second):
        layout = good()
        layout['components'][0].update(first)
        layout['components'][1].update(second)
        return parse_layout(layout).correction_radius()
    on_axis = {'radius': 0.0}
    assert radius(on_axis, on_axis) == 0.175                  # the tube: 0.35 m long, / 2
    sphere = {'radius': 0.0, 'shape': {'type': 'sphere', 'radius': 1e-6}}
    assert radius(sphere, on_axis) == 1e-6                    # a micrometre: still a rim
    layout = good()
    del layout['components'][0]['shape']
    layout['components'][0]['radius'] = 0.0
    layout['components'][1]['radius'] = 1e-6                  # a micrometre off the axis
    assert parse_layout(layout).correction_radius() == 1e-6
    layout['components'][1]['radius'] = 0.0
    assert parse_layout(layout).correction_radius() == 0.0    # no rim at all


def test_the_units_and_limits_of_each_kind_of_number():
    """An int radius of 0 on a body; an inertia element's limit in kg m^2; a micrometre box."""
    layout = good()
    layout['components'][0]['radius'] = 0                     # an int at the low end
    assert parse_layout(layout).components[0].radius == 0.0
    layout['components'][0]['mass'] = 10 ** 13               # an int beyond the limit
    with pytest.raises(LayoutError) as refused:
        parse_layout(layout)
    assert str(refused.value) == ("component 'tube': field mass must be from 1e-06 to 1e+12 kg "
                                  '(a milligram or more: lighter is no part, and divides mass '
                                  'ratios to inf), got 10000000000000 kg')
    layout = good()
    del layout['components'][0]['shape']
    layout['components'][0]['inertia'] = dict(ixx=1e13, iyy=1.0, izz=1.0, ixy=0.0, ixz=0.0,
                                              iyz=0.0)
    with pytest.raises(LayoutError) as refused:
        parse_layout(layout)
    assert str(refused.value) == ("component 'tube': field inertia.ixx must be within +-1e+12 "
                                  'kg m^2 (products stay finite), got 1e+13 kg m^2')
    layout = good()                                           # every component on the axis
    layout['components'][0].update(radius=0.0, shape={'type': 'box', 'size': [1e-6] * 3})
    layout['components'][1]['radius'] = 0.0
    assert parse_layout(layout).correction_radius() == 0.0    # a rim of 0.5 um: none
