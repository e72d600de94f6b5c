"""
Hostile and mistaken layouts: one clear, short LayoutError for each, never another exception.

The cases are those a hostile but fair tester found (issue 12): each used to escape as
TypeError, IndexError, ValueError, RecursionError, OverflowError or ZeroDivisionError, or
to cost seconds and gigabytes. A fuzz run over the parser (hypothesis) then asserts the
same for arbitrary texts and structures.
"""

import json
import math
import subprocess
import sys

from hypothesis import given, HealthCheck, settings, strategies as st
import pytest

from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import LayoutError, MAX_ANGLE, parse_layout
from cvc_balance.physics.layout_file import layout_from_text
from fuzzing import fuzz_examples
from test_layout_columns import canonical_by_asdict

BASE = '''name: hostile
components:
  - {name: tube, mass: 60.0, radius: 0.6, angle: 0.0, z: 0.05%s}
supports:
  - {name: front, z: -0.25}
  - {name: rear, z: 0.25, axial: true}
'''
MAX_MESSAGE = 300
"""Characters an error line may take, whatever the bad value's size."""


def layout_yaml(extra):
    return BASE % extra


def rejected(text):
    """Return the LayoutError message for ``text``; fail on any other outcome."""
    with pytest.raises(LayoutError) as caught:
        layout_from_text(text, source='test')
    message = str(caught.value)
    assert '\n' not in message and len(message) <= MAX_MESSAGE, message[:500]
    return message


@pytest.mark.parametrize('extra, needle', [
    (', shape: {type: [cylinder]}', 'shape.type'),                   # was TypeError
    (', shape: {type: cylinder, radius: 0.1, length: 0.2, axis: [x]}', 'shape.axis'),
    (', inertia: [1, 2, 3]', 'inertia'),
])
def test_wrong_types_in_a_shape_name_the_field(extra, needle):
    assert needle in rejected(layout_yaml(extra))


@pytest.mark.parametrize('mass, needle', [
    ('!!int ', 'YAML'),                  # PyYAML's constructor: IndexError
    ('!!float heavy', 'YAML'),           # ValueError
    ('1' * 401, 'digits'),               # OverflowError in float()
    ('1.0e+400', 'finite'),              # YAML reads inf
    ('-0.0', 'mass'),
])
def test_bad_masses(mass, needle):
    text = BASE.replace('mass: 60.0', f'mass: {mass}') % ''
    assert needle in rejected(text)


def test_deep_nesting_is_refused():
    # 10^5 nested lists: the parsers recurse per level (RecursionError).
    for text in ('[' * 100_000 + ']' * 100_000, 'name: x\ncomponents: ' + '[' * 100_000):
        assert 'nested' in rejected(text) or 'YAML' in rejected(text)


def test_an_alias_bomb_is_refused_before_it_expands():
    # 9 levels of 9 aliases: 9^9 = 387 million nodes from a few hundred bytes.
    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x]']
    for level in range(1, 10):
        previous = f'*a{level - 1}'
        lines.append(f'a{level}: &a{level} [' + ', '.join([previous] * 9) + ']')
    text = '\n'.join(lines) + '\n'
    assert len(text) < 600
    assert 'aliases' in rejected(text)


def test_modest_aliases_are_fine():
    # An anchor for a shape used twice is what aliases are for.
    text = '''name: shared_shapes
components:
  - {name: a, mass: 1.0, radius: 0.5, angle: 0.0, shape: &can {type: sphere, radius: 0.1}}
  - {name: b, mass: 1.0, radius: 0.5, angle: 3.141592653589793, shape: *can}
supports: [{name: s, z: 0.0}]
'''
    layout = layout_from_text(text)
    assert layout.components[0].shape == layout.components[1].shape
    assert layout.components[1].shape.radius == 0.1


@pytest.mark.parametrize('text', [
    'name: a\nname: b\ncomponents: []\nsupports: []\n',
    '{"name": "a", "name": "b", "components": [], "supports": []}',
    BASE.replace('mass: 60.0', 'mass: 60.0, mass: 61.0') % '',
])
def test_duplicate_keys_are_refused(text):
    assert 'twice' in rejected(text)


def test_absurd_angles_are_refused_not_computed():
    # 1e18 rad: beyond the exact reduction; the engine gave -7.7e18 N. 1e308 deg: NaN.
    assert 'angle' in rejected(layout_yaml('').replace('angle: 0.0', 'angle: 1.0e+18'))
    assert 'angle_deg' in rejected(layout_yaml('').replace('angle: 0.0', 'angle_deg: 1e308'))
    near_bound = parse_layout({'name': 'n', 'components': [
        {'name': 'a', 'mass': 1.0, 'radius': 1.0, 'angle': MAX_ANGLE}],
        'supports': [{'name': 's', 'z': 0.0}]})
    model = RotorModel.from_layout(near_bound)
    # cos(1e9) to 16 digits, by an independent reduction (Python's math.cos is glibc's,
    # correctly reduced): the aggregate keeps it.
    assert model.s_x == pytest.approx(math.cos(MAX_ANGLE), rel=1e-15)


def test_huge_values_are_quoted_short():
    big = 'x' * 10_000_000
    message = rejected(layout_yaml('').replace('name: tube', f'name: {big}'))
    assert 'characters' in message
    message = rejected(json.dumps({'name': 'n', 'components': [{'name': 'a', 'mass': [0] * 10**6,
                                   'radius': 1, 'angle': 0}], 'supports': []}))
    assert 'list of 1000000 items' in message


def test_support_names_must_make_topic_names():
    text = layout_yaml('').replace('name: front', 'name: 2nd bearing')
    assert 'ROS name' in rejected(text)


def test_all_components_on_the_axis_have_no_correction_mass():
    # It divided by a zero correction radius (ZeroDivisionError in the node's diagnostics).
    layout = parse_layout({'name': 'axial', 'components': [
        {'name': 'hub', 'mass': 10.0, 'radius': 0.0, 'angle': 0.0, 'z': 0.1,
         'inertia': {'ixx': 1.0, 'iyy': 1.0, 'izz': 1.5, 'ixy': 0.0, 'ixz': 0.05, 'iyz': 0.0}}],
        'supports': [{'name': 'a', 'z': -0.2}, {'name': 'b', 'z': 0.2, 'axial': True}]})
    assessment = assess_balance(RotorModel.from_layout(layout), 20.0)
    # The hub's own product I_xz = -0.05 kg m^2 (tensor element 0.05) is a couple: by hand,
    # U_I = -U_II = P_xz / (z_II - z_I) = -0.05 / 0.4 kg m on rotor X.
    plane_i, plane_ii = assessment.planes
    assert plane_i.amount == pytest.approx(0.125, rel=1e-15)
    assert plane_ii.amount == pytest.approx(0.125, rel=1e-15)
    assert plane_i.correction_mass is None and plane_ii.correction_mass is None


def test_solve_says_when_there_is_no_correction_radius(tmp_path):
    path = tmp_path / 'axial.yaml'
    path.write_text('name: axial\ncomponents:\n  - {name: p, mass: 1.0, radius: 0.0, angle: 0.0,'
                    ' z: 0.1}\nsupports:\n  - {name: a, z: -0.2}\n  - {name: b, z: 0.2, axial:'
                    ' true}\n')
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve', str(path),
                          '--omega', '10'], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert 'give balancing.correction_radius' in run.stdout
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve', str(path),
                          '--omega', '10', '--json'], capture_output=True, text=True)
    data = json.loads(run.stdout)           # strict JSON: null, not NaN
    assert data['balance']['planes'][0]['correction_mass_kg'] is None


@pytest.mark.parametrize('omega', ['1e308', '-1e13'])
def test_solve_refuses_absurd_speeds(omega, tmp_path):
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve',
                          'config/ct_gantry.yaml', '--omega', omega], capture_output=True,
                         text=True)
    assert run.returncode == 2 and 'omega' in run.stderr and 'Traceback' not in run.stderr


# -- fuzz: arbitrary structures and texts give a Layout or a LayoutError, nothing else ------

scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(),
                    st.text(max_size=20), st.just('cylinder'), st.just('axial'))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(
        st.sampled_from(['name', 'mass', 'radius', 'angle', 'angle_deg', 'z', 'shape', 'type',
                         'inertia', 'components', 'supports', 'axial', 'gravity', 'balancing',
                         'planes', 'grade', 'length', 'size', 'ixx', 'x']), inner, max_size=6)),
    max_leaves=30)


def component_like():
    return st.fixed_dictionaries({'name': st.text(min_size=1, max_size=5),
                                  'mass': values, 'radius': values},
                                 optional={'angle': values, 'angle_deg': values, 'z': values,
                                           'shape': values, 'inertia': values})


layouts = st.fixed_dictionaries(
    {'name': values, 'components': st.lists(component_like(), max_size=4),
     'supports': st.lists(st.fixed_dictionaries({'name': values, 'z': values},
                                                optional={'axial': values}), max_size=3)},
    optional={'gravity': values, 'balancing': values})


@settings(max_examples=fuzz_examples(400), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(layouts)
def test_fuzzed_structures_give_a_layout_or_a_layout_error(data):
    try:
        layout = parse_layout(data)
    except LayoutError as error:
        assert '\n' not in str(error) and len(str(error)) <= MAX_MESSAGE
        return
    model = RotorModel.from_layout(layout)       # and what it gives is finite
    assert all(math.isfinite(v) for v in (model.mass, model.s_x, model.s_y, model.p_xz,
                                          model.p_yz, model.i_zz))


@settings(max_examples=fuzz_examples(300), deadline=None)
@given(st.text(max_size=200) | st.binary(max_size=200).map(lambda b: b.decode('latin-1')))
def test_fuzzed_texts_give_a_layout_or_a_layout_error(text):
    try:
        layout_from_text(text)
    except LayoutError as error:
        assert '\n' not in str(error) and len(str(error)) <= MAX_MESSAGE


@pytest.mark.parametrize('seed', range(20))
def test_the_fast_canonical_json_is_asdicts(seed):
    # The digest's text is built part by part for speed; it must be json.dumps(asdict(...)).
    import numpy as np
    from reference import random_layout
    rng = np.random.default_rng(seed)
    layout = parse_layout(random_layout(rng, n=int(rng.integers(1, 12)), supports=1 + seed % 2))
    assert layout.canonical_json() == canonical_by_asdict(layout)


@pytest.mark.parametrize('name', ['tube', 'a "quoted" name', 'back\\slash', 'tab\there',
                                  'del\x7f', 'Röhre', '管球', 'emoji \U0001f600', 'x' * 200,
                                  ' leading and trailing ', '</script>', "it's"])
def test_names_in_the_canonical_json_are_json_dumps(name):
    # Printable ASCII names skip json.dumps; every other name must come out as it would.
    try:
        layout = parse_layout({'name': name, 'components': [
            {'name': name, 'mass': 1.0, 'radius': 0.1, 'angle': 0.5}],
            'supports': [{'name': 'a', 'z': 0.0, 'axial': True}]})
    except LayoutError:
        return                          # names the contract refuses never reach the digest
    assert layout.canonical_json() == canonical_by_asdict(layout)
