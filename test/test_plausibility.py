"""
Plausibility warnings: mistaken units that pass validation are named, and good layouts are not.

The mistakes are those a person makes (the issue's own: ``angle: 90`` in the radians field,
``radius: 620`` in mm); the good layouts are every layout the project ships or tests
with, and 200 random plausible ones. A warning never changes the results: solve's JSON
with and without the warning agree, and the commands still exit 0.
"""

import copy
import json
from pathlib import Path
import random
import subprocess
import sys

import pytest
import yaml

from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.plausibility import layout_warnings
from in_process import cvc

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())


def gantry_with(index, **fields):
    layout = copy.deepcopy(GANTRY)
    component = layout['components'][index]
    if 'angle' in fields:
        component.pop('angle_deg')
    component.update(fields)
    return layout


MISTAKES = [
    # (layout, words the one warning must hold)
    (gantry_with(1, angle=90), ["component 'xray_tube'", 'angle 90 rad', 'angle_deg']),
    (gantry_with(1, angle=-7.0), ["component 'xray_tube'", 'angle -7 rad']),
    (gantry_with(1, radius=620), ["component 'xray_tube'", 'radius 620 m', 'millimetres']),
    (gantry_with(2, z=150), ["component 'collimator'", 'field z 150 m']),
    (gantry_with(3, shape={'type': 'box', 'size': [120, 900, 160]}),
     ["component 'detector'", 'shape.size[0] 120 m']),
    (gantry_with(1, mass=60000), ["component 'xray_tube'", 'mass 60000 kg', 'denser than any',
                                  'grams']),
    (dict(GANTRY, components=[dict(c, shape={'type': 'point'}) if c['name'] != 'xray_tube'
                              else dict(c, mass=60000.0, shape={'type': 'point'})
                              for c in GANTRY['components']]),
     ["component 'xray_tube'", 'mass 60000 kg', 'times the median', 'grams']),
    (dict(GANTRY, gravity=[0.0, -9806.65, 0.0]), ['gravity', '9806.65 m/s^2']),
    (dict(GANTRY, gravity=[0.0, -1.0, 0.0]), ['gravity', 'magnitude 1 m/s^2']),
    (dict(GANTRY, balancing=dict(GANTRY['balancing'], correction_radius=680)),
     ['balancing.correction_radius 680 m']),
    (dict(GANTRY, supports=[{'name': 'front', 'z': -120},
                            {'name': 'rear', 'z': 120, 'axial': True}]),
     ["support 'front'", 'z -120 m']),
]


@pytest.mark.parametrize('mistake, words', MISTAKES)
def test_each_mistake_is_named_once(mistake, words):
    warnings = layout_warnings(parse_layout(mistake))
    matching = [w for w in warnings if all(word in w for word in words)]
    assert len(matching) >= 1, warnings
    # Only what is wrong is named: nothing about the other components and fields.
    subject = words[0].split("'")[1] if "'" in words[0] else words[0]
    assert all(subject in w or 'support' in w for w in warnings), warnings


def good_layouts():
    yield GANTRY
    from test_balance_monitor import LAYOUT_A, LAYOUT_B
    from test_verdict_units import COUPLE, ISO_EXAMPLE
    yield from (LAYOUT_A, LAYOUT_B, COUPLE, ISO_EXAMPLE)
    # The 3 mm screws beside a 60 kg tank of test_rerun_view: too few to call an outlier.
    yield {'name': 'screws', 'supports': [{'name': 'a', 'z': -0.3},
                                          {'name': 'b', 'z': 0.3, 'axial': True}],
           'components': [{'name': 'screw', 'mass': 0.01, 'radius': 0.6, 'angle': 0.1},
                          {'name': 'pin', 'mass': 0.02, 'radius': 0.6, 'angle': 0.2},
                          {'name': 'tank', 'mass': 60.0, 'radius': 0.5, 'angle': 1.0}]}
    rng = random.Random(13)
    for k in range(200):
        # Plausible rotors: 3-30 point masses of 1-100 kg and a drum up to 30 times the
        # heaviest, radii up to 3 m, angles within a turn, Earth's gravity (tilted 30 deg)
        # or none.
        n = rng.randint(3, 30)
        yield {'name': f'random_{k}', 'gravity': rng.choice(
                   [[0.0, -9.80665, 0.0], [0.0, 0.0, 0.0], [0.0, -8.49, 4.9]]),
               'supports': [{'name': 'a', 'z': -rng.uniform(0.05, 2.0)},
                            {'name': 'b', 'z': rng.uniform(0.05, 2.0), 'axial': True}],
               'components': [{'name': f'c{i}', 'mass': 10 ** rng.uniform(0, 2),
                               'radius': rng.uniform(0.0, 3.0),
                               'angle': rng.uniform(-6.28, 6.28),
                               'z': rng.uniform(-2.0, 2.0)} for i in range(n)]
               + [{'name': 'drum', 'mass': rng.uniform(100.0, 3000.0), 'radius': 0.0,
                   'angle': 0.0, 'shape': {'type': 'tube', 'inner_radius': 0.7,
                                           'outer_radius': 0.8, 'length': 0.3}}]}


def test_good_layouts_get_no_warning():
    for layout in good_layouts():
        assert layout_warnings(parse_layout(layout)) == (), layout['name']


def cli(*args):
    return subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def here(*args):
    return cvc(*args)        # in this process (test/in_process.py): no Python start-up


def test_solve_warns_on_stderr_keeps_the_results_and_its_columns_apart(tmp_path):
    """radius: 620 (mm for m): warned; loads of tens of MN still in separate columns."""
    path = tmp_path / 'mm.yaml'
    path.write_text(yaml.safe_dump(gantry_with(1, radius=620)))
    run = cli('solve', path, '--omega', 23.27)
    assert run.returncode == 0
    assert run.stderr.count('warning:') == 1 and 'radius 620 m' in run.stderr
    for line in run.stdout.splitlines():
        if line.startswith(('front', 'rear', 'force', 'moment')):
            cells = [c for c in line.split('  ') if c.strip()]
            numbers = [c for c in cells if c.strip().lstrip('-').replace('.', '').isdigit()]
            assert len(numbers) >= 3, line        # each number its own cell
    data = json.loads(here('solve', path, '--omega', 23.27, '--json').stdout)
    assert data['warnings'] == [w for w in run.stderr.split('warning: ')[1:]
                                for w in [w.split(': ', 1)[1].strip()]]
    # The 620 m tube: U = 60 kg x 620 m more than the real gantry's, G in the thousands.
    assert data['balance']['equivalent_grade'] > 1000


def test_replay_and_the_view_say_the_warning_with_the_layout(tmp_path):
    scenario = tmp_path / 'degrees.yaml'
    scenario.write_text(yaml.safe_dump({
        'name': 'degrees', 'layout': gantry_with(1, angle=90), 'rate': 100,
        'profile': [{'type': 'spin_up', 'to': 10.0, 'alpha': 10.0}]}))
    bag = tmp_path / 'degrees.mcap'
    assert here('simulate', scenario, '-o', bag).returncode == 0
    run = here('replay', bag)
    assert run.returncode == 0
    assert "  warning: component 'xray_tube': angle 90 rad" in run.stdout
    rrd = tmp_path / 'degrees.rrd'
    assert here('view', bag, '-o', rrd).returncode == 0
    from rerun.chunk import RrdReader
    texts = []
    for chunk in RrdReader(str(rrd)).stream():
        if str(chunk.entity_path) == '/events':
            batch = chunk.to_record_batch()
            texts += [v[0] for v in batch.column('TextLog:text').to_pylist() if v]
    assert any("implausible? component 'xray_tube': angle 90 rad" in t for t in texts), texts
