"""The layout file: what is accepted, and one clear line with exit code 2 for what is not."""

import json
import math
from pathlib import Path
import subprocess
import sys

import pytest
import yaml

from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import LayoutError, parse_layout
from cvc_balance.physics.layout_file import layout_from_text, load_layout
from in_process import cvc

ROOT = Path(__file__).resolve().parents[1]
GANTRY = ROOT / 'config' / 'ct_gantry.yaml'


def good():
    return {'name': 'ok',
            'components': [{'name': 'tube', 'mass': 60.0, 'radius': 0.6, 'angle_deg': 0.0,
                            'z': 0.05, 'shape': {'type': 'cylinder', 'radius': 0.09,
                                                 'length': 0.35, 'axis': 'tangential'}},
                           {'name': 'detector', 'mass': 50.0, 'radius': 0.6,
                            'angle_deg': 180.0}],
            'supports': [{'name': 'front', 'z': -0.25}, {'name': 'rear', 'z': 0.25,
                                                         'axial': True}]}


def edited(change):
    layout = good()
    change(layout)
    return layout


def run_solve(path, *extra):
    # In this process: the layout's refusal is tested here, `solve` as a process below.
    return cvc('solve', path, '--omega', '20', *extra)


def assert_one_line_error(run, *needles):
    assert run.returncode == 2, run.stderr
    assert run.stdout == ''
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, run.stderr
    assert 'Traceback' not in run.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


BAD_LAYOUTS = {
    'missing mass': (lambda d: d['components'][1].pop('mass'), ("'detector'", 'mass')),
    'negative mass': (lambda d: d['components'][0].update(mass=-1.0), ("'tube'", 'mass')),
    'nan mass': (lambda d: d['components'][0].update(mass=math.nan), ("'tube'", 'mass')),
    'inf radius': (lambda d: d['components'][1].update(radius=math.inf),
                   ("'detector'", 'radius')),
    'text mass': (lambda d: d['components'][0].update(mass='heavy'), ("'tube'", 'mass')),
    'duplicate name': (lambda d: d['components'][1].update(name='tube'),
                       ("'tube'", 'duplicate')),
    'unknown shape': (lambda d: d['components'][0].update(shape={'type': 'cone'}),
                      ("'tube'", 'shape.type', 'cone')),
    'unknown component key': (lambda d: d['components'][1].update(colour='red'),
                              ("'detector'", 'colour')),
    'unknown shape key': (lambda d: d['components'][0]['shape'].update(width=1.0),
                          ("'tube'", 'width')),
    'unknown top-level key': (lambda d: d.update(speed=3.0), ('layout', 'speed')),
    'no supports': (lambda d: d.update(supports=[]), ('supports', '0')),
    'three supports': (lambda d: d['supports'].append({'name': 'mid', 'z': 0.0}),
                       ('supports', '3')),
    'two angles': (lambda d: d['components'][1].update(angle=1.0), ("'detector'", 'angle')),
    'no angle': (lambda d: d['components'][1].pop('angle_deg'), ("'detector'", 'angle')),
    'zero shape radius': (lambda d: d['components'][0]['shape'].update(radius=0.0),
                          ("'tube'", 'shape.radius')),
    'tube inside out': (lambda d: d['components'][0].update(
        shape={'type': 'tube', 'inner_radius': 0.2, 'outer_radius': 0.1, 'length': 0.1}),
        ("'tube'", 'inner_radius')),
    'bad axis': (lambda d: d['components'][0]['shape'].update(axis='diagonal'),
                 ("'tube'", 'axis')),
    'impossible inertia': (lambda d: d['components'][1].update(
        inertia={'ixx': 1.0, 'iyy': 1.0, 'izz': 5.0, 'ixy': 0, 'ixz': 0, 'iyz': 0}),
        ("'detector'", 'inertia')),
    'shape and inertia': (lambda d: d['components'][0].update(
        inertia={'ixx': 1.0, 'iyy': 1.0, 'izz': 1.0, 'ixy': 0, 'ixz': 0, 'iyz': 0}),
        ("'tube'", 'inertia')),
    'supports at one z': (lambda d: d['supports'][1].update(z=-0.25), ('supports', 'z')),
    'no axial support': (lambda d: d['supports'][1].pop('axial'), ('supports', 'axial')),
    'support without z': (lambda d: d['supports'][0].pop('z'), ("'front'", 'z')),
    'gravity of two': (lambda d: d.update(gravity=[0.0, -9.8]), ('gravity',)),
    'no components': (lambda d: d.update(components=[]), ('components',)),
    'component not a mapping': (lambda d: d['components'].append(3), ('#3', 'mapping')),
    'planes reversed': (lambda d: d.update(balancing={'planes': [0.2, -0.2]}),
                        ('balancing.planes',)),
}


@pytest.mark.parametrize('case', sorted(BAD_LAYOUTS))
def test_bad_layout_gets_one_line_and_exit_code_2(case, tmp_path):
    change, needles = BAD_LAYOUTS[case]
    layout = edited(change)
    path = tmp_path / 'layout.json'
    # allow_nan: JSON's NaN / Infinity, as a program might write them.
    path.write_text(json.dumps(layout, allow_nan=True))
    assert_one_line_error(run_solve(path), *needles)
    with pytest.raises(LayoutError):
        parse_layout(layout)


def test_yaml_nan_is_rejected(tmp_path):
    path = tmp_path / 'layout.yaml'
    path.write_text(yaml.safe_dump(good()).replace('mass: 60.0', 'mass: .nan'))
    assert_one_line_error(run_solve(path), "'tube'", 'mass', 'finite')


def test_unreadable_and_malformed_files(tmp_path):
    assert_one_line_error(run_solve(tmp_path / 'absent.yaml'), 'absent.yaml', 'cannot read')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: x\ncomponents: [\n  - {name: a\n')
    assert_one_line_error(run_solve(broken), 'broken.yaml', 'YAML')
    scalar = tmp_path / 'scalar.yaml'
    scalar.write_text('42\n')
    assert_one_line_error(run_solve(scalar), 'layout', 'mapping')


@pytest.mark.parametrize('value', ['nan', 'inf', 'fast'])
def test_bad_speed_on_the_command_line(value):
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve', str(GANTRY),
                          '--omega', value], capture_output=True, text=True)
    assert run.returncode == 2
    assert 'omega' in run.stderr and 'Traceback' not in run.stderr


def test_bundled_gantry_is_a_realistic_ct_rotor():
    layout = load_layout(GANTRY)
    model = RotorModel.from_layout(layout)
    assert 800.0 <= model.mass <= 1000.0
    off_axis = [c for c in layout.components if c.radius > 0.0]
    assert all(0.3 <= c.radius <= 0.7 for c in off_axis)
    period = 2 * math.pi / layout.balancing.service_speed
    assert 0.25 <= period <= 0.3
    names = {c.name for c in layout.components}
    assert {'xray_tube', 'hv_generator', 'detector', 'tube_cooling', 'data_acquisition'} <= names
    assert any(n.startswith('counterweight') for n in names)


def test_angle_in_degrees_equals_angle_in_radians():
    in_degrees = parse_layout(good())
    in_radians = parse_layout(edited(lambda d: d['components'][1].update(
        angle=math.pi) or d['components'][1].pop('angle_deg')))
    assert in_degrees.components[1].angle == pytest.approx(in_radians.components[1].angle,
                                                           rel=1e-15)


def test_json_and_yaml_texts_give_the_same_layout():
    from_json = layout_from_text(json.dumps(good()))
    from_yaml = layout_from_text(yaml.safe_dump(good()))
    assert from_json == from_yaml
    assert from_json.digest() == from_yaml.digest()
    heavier = parse_layout(edited(lambda d: d['components'][0].update(mass=61.0)))
    assert heavier.digest() != from_json.digest()


def test_defaults():
    layout = parse_layout(good())
    assert layout.gravity == (0.0, -9.80665, 0.0)
    assert layout.components[1].z == 0.0 and layout.components[1].shape is None
    assert layout.correction_planes() == (-0.25, 0.25)
    assert layout.correction_radius() == 0.6
    assert layout.balancing.grade == 6.3
    one_support = parse_layout(edited(lambda d: d.update(supports=[{'name': 'b', 'z': 0}])))
    assert one_support.correction_planes() is None


def test_solve_table_names_every_support_and_the_verdict():
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve', str(GANTRY),
                          '--omega', '23.27'], capture_output=True, text=True, check=True)
    for needle in ('front', 'rear (axial)', 'drive torque', 'static', 'couple',
                   'G 6.3', 'WITHIN'):
        assert needle in run.stdout
