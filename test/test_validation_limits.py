"""
Input validation by meaning (issue 24): the range of every number, YAML 1.2, regular files.

Each finding of the hostile review is reproduced here (each of these failed before the
change): a grade of 5e-324 mm/s (a ZeroDivisionError at the node's start), supports
5e-324 m apart (409 infinite wrenches), a tiny weight site or correction radius (infinite
correction masses), ``angle_deg: 3:00`` read as 180 (YAML 1.1's base 60), ``default:``
twice in a tolerance file, ``sweep --points 0``, ``simulate-fleet --machines 10^9`` and
``--rate 1e9``, ``fleet --workers 1000``, ``solve`` and ``replay`` given a FIFO, and a big
YAML layout's memory (57 times its text).

The limits are written here from the issue's figures, independently of
``cvc_balance.physics.limits``: grades 0.1-4000 mm/s, supports and correction planes at
least 1 mm apart, a radius a correction mass is divided by at least 1 um; and, where the
issue gives no figure, the table's own (stated): masses at least a milligram, speeds
1e-3-1e5 rad/s, shapes at least 1 um. A property test draws layouts at, just inside and
just beyond every range and checks that a layout is refused exactly when a value is
beyond, and that an accepted one gives finite numbers everywhere: loads (one sample and
vectorised), unbalance, the verdict and its JSON, correction masses, the weights at
sites, the plausibility warnings.
"""

import ast
from contextlib import contextmanager
import json
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tracemalloc

from hypothesis import event, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
import yaml

from cvc_balance.cli import parser
from cvc_balance.design.tolerances import load_tolerances, ToleranceError
from cvc_balance.field.plan import round_to_kit, vector_split
from cvc_balance.physics.assessment import judge_balance, verdict_record
from cvc_balance.physics.component_table import ComponentTable
from cvc_balance.physics.documents import (DocumentError, dump_document, load_document,
                                           read_document)
from cvc_balance.physics.engine import loads, RotorModel, sample_loads
from cvc_balance.physics.layout import LayoutError, parse_layout
from cvc_balance.physics.layout_file import layout_from_text, load_layout
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance

ROOT = Path(__file__).resolve().parents[1]
TINY = 5e-324
"""The smallest positive double: what the hostile review typed."""

# The limits, from the issue (and, where it gives none, the table's stated figure).
GRADE = (0.1, 4000.0)                   # mm/s (issue)
SPACING = 1e-3                          # m, supports and planes (issue: 1 mm)
DIVISOR_RADIUS = 1e-6                   # m, correction and site radius (issue: 1 um)
MASS = 1e-6                             # kg, components and weights (table: 1 mg)
SHAPE = 1e-6                            # m, a shape's lengths (table: 1 um)
SPEED = (1e-3, 1e5)                     # rad/s, the service speed (table)
BIG = 1e12                              # kg, m, m/s^2: the magnitude bound (unchanged)

BASE = {
    'name': 'limits',
    'components': [{'name': 'tube', 'mass': 60.0, 'radius': 0.6, 'angle': 0.0, 'z': 0.05},
                   {'name': 'detector', 'mass': 110.0, 'radius': 0.58, 'angle': 3.1,
                    'z': -0.02}],
    'supports': [{'name': 'front', 'z': -0.25}, {'name': 'rear', 'z': 0.25, 'axial': True}],
}


def with_changes(**changes):
    """Return BASE with top-level fields replaced."""
    return json.loads(json.dumps(dict(BASE, **changes)))


def refused(data):
    """Return the one-line LayoutError of the layout mapping or text ``data``."""
    with pytest.raises(LayoutError) as caught:
        if isinstance(data, str):
            layout_from_text(data, source='test')
        else:
            parse_layout(data)
    message = str(caught.value)
    assert '\n' not in message and len(message) < 300, message
    return message


# -- the findings, one by one --------------------------------------------------------------

def test_a_grade_of_5e_324_is_refused_in_one_line_naming_field_value_range_and_unit():
    text = yaml.safe_dump(with_changes(balancing={'grade': TINY}))
    assert refused(text) == (
        'test: layout: field balancing.grade must be from 0.1 to 4000 mm/s (ISO 21940-11 '
        'grades run from G 0.4 to G 4000), got 5e-324 mm/s')
    # The node's layout worker gets the same line where it used to put the layout in force
    # and raise on every /diagnostics period (a ZeroDivisionError at its start).
    from cvc_balance.ros.balance_monitor import prepare_layout
    assert prepare_layout(text, 'layout message') == (
        'layout message: layout: field balancing.grade must be from 0.1 to 4000 mm/s '
        '(ISO 21940-11 grades run from G 0.4 to G 4000), got 5e-324 mm/s')


@pytest.mark.parametrize('low, high', [(GRADE[0], GRADE[1])])
def test_the_grades_at_the_ends_of_their_range_are_taken_and_beyond_refused(low, high):
    for grade in (low, high):
        assert parse_layout(with_changes(balancing={'grade': grade})).balancing.grade == grade
    for grade in (math.nextafter(low, 0.0), math.nextafter(high, math.inf), 0.0, -6.3):
        assert 'balancing.grade must be from 0.1 to 4000 mm/s' in \
            refused(with_changes(balancing={'grade': grade}))


def test_supports_5e_324_m_apart_are_refused_as_yaml_json_and_a_mapping():
    supports = [{'name': 'front', 'z': 0.0}, {'name': 'rear', 'z': TINY, 'axial': True}]
    expected = ('layout: field supports: the spacing of the two supports must be from 0.001 '
                'to 2e+12 m (a millimetre or more: closer is one bearing or plane, and '
                'moments are divided by the spacing), got 5e-324 m')
    data = with_changes(supports=supports)
    assert refused(data) == expected
    assert refused(json.dumps(data)) == 'test: ' + expected
    # YAML 1.1 read 5e-324 as text (refused as "not a number"); YAML 1.2 reads a number.
    text = 'name: x\ncomponents: [{name: a, mass: 1, radius: 0.1, angle: 0}]\n' \
        'supports: [{name: front, z: 0}, {name: rear, z: 5e-324, axial: true}]\n'
    assert refused(text) == 'test: ' + expected
    for spacing in (SPACING, 2.0):
        ok = with_changes(supports=[{'name': 'front', 'z': 0.0},
                                    {'name': 'rear', 'z': spacing, 'axial': True}])
        assert parse_layout(ok).supports[1].z == spacing
    for spacing in (math.nextafter(SPACING, 0.0), 1e-4):
        planes = with_changes(balancing={'planes': [0.0, spacing]})
        assert 'balancing.planes: the spacing z_II - z_I must be from 0.001' in refused(planes)


SITE = {'angles_deg': [0, 90, 180, 270], 'radius': 0.6, 'masses': [0.01, 0.02]}


@pytest.mark.parametrize('balancing, field, shown', [
    ({'correction_radius': TINY}, 'balancing.correction_radius', 'got 5e-324 m'),
    ({'correction_radius': math.nextafter(DIVISOR_RADIUS, 0.0)},
     'balancing.correction_radius', 'got 9.999999999999997e-07 m'),
    ({'sites': {'I': dict(SITE, radius=TINY)}}, 'balancing.sites.I.radius', 'got 5e-324 m'),
    ({'sites': {'I': dict(SITE, masses=[0.01, TINY])}}, 'balancing.sites.I.masses[1]',
     'got 5e-324 kg'),
    ({'sites': {'II': dict(SITE, masses=[1e-9])}}, 'balancing.sites.II.masses[0]',
     'got 1e-09 kg'),
])
def test_a_tiny_positive_radius_or_weight_is_refused(balancing, field, shown):
    message = refused(with_changes(balancing=balancing))
    assert message.startswith(f'layout: field {field} must be from 1e-06 to 1e+12 ')
    assert message.endswith(shown)


def test_the_smallest_radius_and_weights_are_taken_and_their_masses_finite_below_refused():
    # At the limits, the values that used to give inf: a radius of 1 um, weights of 1 mg;
    # just below them, refused.
    below = math.nextafter(DIVISOR_RADIUS, 0.0)
    assert 'sites.I.radius must be from 1e-06' in refused(with_changes(balancing={
        'sites': {'I': dict(SITE, radius=below)}}))
    assert 'sites.I.masses[0] must be from 1e-06' in refused(with_changes(balancing={
        'sites': {'I': dict(SITE, masses=[math.nextafter(MASS, 0.0)])}}))
    layout = parse_layout(with_changes(balancing={
        'correction_radius': DIVISOR_RADIUS, 'service_speed': 1.0,
        'sites': {'I': dict(SITE, radius=DIVISOR_RADIUS, masses=[MASS])}}))
    model = RotorModel.from_layout(layout)
    for plane in plane_unbalances(model, *layout.correction_planes(),
                                  layout.correction_radius()):
        # amount / radius, by hand
        assert plane.correction_mass == pytest.approx(plane.amount / DIVISOR_RADIUS, rel=1e-15)
        assert math.isfinite(plane.correction_mass)


def test_a_component_mass_below_a_milligram_is_refused_by_every_reader():
    # The careful reader, the JSON columns (a big layout) and the YAML stream: one rule.
    items = [{'name': f'c{k}', 'mass': 1.0 + k, 'radius': 0.1, 'angle': 0.01 * k, 'z': 0.0}
             for k in range(300)]
    items[137]['mass'] = 5e-7
    data = with_changes(components=items)
    expected = ("component 'c137': field mass must be from 1e-06 to 1e+12 kg (a milligram or "
                'more: lighter is no part, and divides mass ratios to inf), got 5e-07 kg')
    assert refused(data) == expected
    assert refused(json.dumps(data)) == 'test: ' + expected
    assert refused(yaml.safe_dump(data)) == 'test: ' + expected
    data['components'][137]['mass'] = MASS
    assert layout_from_text(json.dumps(data)).components[137].mass == MASS
    assert layout_from_text(yaml.safe_dump(data)).components[137].mass == MASS


def test_angle_deg_3_00_is_text_not_180_degrees():
    text = yaml.safe_dump(BASE).replace('angle: 3.1', 'angle_deg: 3:00')
    assert 'angle_deg: 3:00' in text
    assert refused(text) == ("test: component 'detector': field angle_deg must be a number, "
                             "got '3:00'")


def test_a_tolerance_file_with_default_twice_is_refused(tmp_path):
    layout = parse_layout(BASE)
    path = tmp_path / 'tolerances.yaml'
    path.write_text('default: {mass: 0.05}\ntube: {radius: 0.001}\ndefault: {mass: 0.5}\n')
    with pytest.raises(ToleranceError) as caught:
        load_tolerances(path, layout)
    assert str(caught.value) == f"{path}: line 3: key 'default' given twice"
    # YAML 1.2 numbers: 1e-3 is a number (YAML 1.1 read it as text and refused it).
    path.write_text('default: {mass: 1e-3, radius: 5e-4}\n')
    tolerances = load_tolerances(path, layout)
    assert tolerances.values[:, :2].tolist() == [[1e-3, 5e-4], [1e-3, 5e-4]]


def test_a_scenario_at_a_billion_samples_a_second_is_refused_in_one_line(tmp_path):
    from cvc_balance.bag.scenario import load_scenario, ScenarioError
    path = tmp_path / 'scenario.yaml'
    text = (ROOT / 'bags' / 'loose_bracket.yaml').read_text().replace(
        'layout: ../config/ct_gantry.yaml', f'layout: {ROOT / "config" / "ct_gantry.yaml"}')
    # Before: 1e9 was YAML 1.1 text, which float() took: a MemoryError of 7 GB of samples.
    path.write_text(text.replace('rate: 500', 'rate: 1e9'))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert str(caught.value) == (f'{path}: field rate must be from 1 to 100000 Hz (an encoder '
                                 'or a load cell: every sample is held in memory), got 1e+09 Hz')
    path.write_text(text.replace('rate: 500', 'rate: 5e2'))          # a YAML 1.2 number
    scenario = load_scenario(path)
    assert scenario.rate == 500.0 and len(scenario.time) == int(scenario.time[-1] * 500) + 1


# -- YAML 1.2, everywhere ------------------------------------------------------------------

@pytest.mark.parametrize('text, value', [
    ('3:00', '3:00'), ('190:20:30', '190:20:30'),          # YAML 1.1: base 60
    ('yes', 'yes'), ('no', 'no'), ('on', 'on'), ('off', 'off'), ('y', 'y'),   # 1.1: booleans
    ('010', 10), ('0o17', '0o17'), ('0x1F', '0x1F'), ('0b101', '0b101'),     # 1.1: 8, ints
    ('1_000', '1_000'),                                      # 1.1: 1000
    ('1e5', 1e5), ('1.5e5', 1.5e5), ('-2E-3', -2e-3), ('+.5', 0.5), ('5e-324', TINY),
    ('true', True), ('False', False), ('TRUE', True), ('~', None), ('null', None),
    ('2026-01-05', '2026-01-05'),                            # 1.1: a date
    ('.inf', math.inf), ('-.Inf', -math.inf),
])
def test_plain_scalars_are_read_by_the_yaml_1_2_core_schema(text, value):
    read = load_document(f'a: {text}\n')['a']
    assert read == value and type(read) is type(value)


def test_a_key_twice_is_refused_in_yaml_and_json_everywhere(tmp_path):
    for text, line in (('a: 1\nb: {c: 1, c: 2}\n', 'line 2: '), ('{"a": 1, "a": 2}', '')):
        with pytest.raises(DocumentError, match=f"^{line}key '[ac]' given twice$"):
            load_document(text)
    # A coefficient record and rosbag2 metadata go through the same reader.
    path = tmp_path / 'record.yaml'
    path.write_text('kind: cvc_balance influence coefficients\nversion: 1\nversion: 1\n')
    done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'correct',
                           str(ROOT / 'bags' / 'field_baseline.mcap'), '--coefficients',
                           str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr == f"cvc-balance: error: {path}: line 3: key 'version' given twice\n"


def test_a_yaml_1_1_merge_key_is_refused_saying_so():
    text = ('name: merged\n'
            'components:\n'
            '  - &tube {name: tube, mass: 60.0, radius: 0.6, angle: 0.0}\n'
            '  - {<<: *tube, name: tube2, angle: 3.0}\n'
            'supports: [{name: front, z: 0.0}]\n')
    assert yaml.safe_load(text)['components'][1]['mass'] == 60.0       # YAML 1.1 merges
    assert refused(text) == ('test: line 4: a merge key (<<) is YAML 1.1, not 1.2: write the '
                             'fields out')


def test_a_machine_id_that_yaml_1_1_would_take_for_a_boolean_stays_text():
    from cvc_balance.bag.machine import _yaml_custom_data
    text = 'rosbag2_bagfile_information:\n  custom_data:\n    machine_id: no\n    n: 1e5\n'
    # Its values are text (rosbag2's custom_data is a map of strings): read as written.
    assert _yaml_custom_data(text) == {'machine_id': 'no', 'n': '1e5'}


@pytest.mark.parametrize('word', ['1e5', '1.5e5', 'yes', '3:00', '0x10', 'null', '010'])
def test_text_written_is_read_back_as_text_by_yaml_1_1_and_1_2(word):
    text = dump_document({'name': word, 'items': [word]})
    assert load_document(text) == {'name': word, 'items': [word]}
    assert yaml.safe_load(text) == {'name': word, 'items': [word]}     # PyYAML: YAML 1.1


def test_every_yaml_the_package_reads_or_writes_goes_through_the_one_reader():
    """No module but physics/documents.py calls PyYAML's loaders or dumpers."""
    calls = []
    for path in sorted((ROOT / 'cvc_balance').rglob('*.py')):
        if path.name == 'documents.py':
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id == 'yaml':
                calls.append(f'{path.relative_to(ROOT)}:{node.lineno}: yaml.{node.attr}')
    assert calls == []


# -- big YAML layouts -------------------------------------------------------------------------

def block_yaml(n):
    """Return a block-YAML layout of n point masses (as people write them)."""
    rng = np.random.default_rng(7)
    lines = ['name: big', 'components:']
    for k, (m, r, a, z) in enumerate(zip(rng.uniform(0.1, 50, n), rng.uniform(0, 0.8, n),
                                         rng.uniform(-3, 3, n), rng.uniform(-0.2, 0.2, n))):
        lines += [f'  - name: c{k:07d}', f'    mass: {m:.9g}', f'    radius: {r:.9g}',
                  f'    angle: {a:.9g}', f'    z: {z:.9g}']
    lines += ['supports:', '  - {name: front, z: -0.25}', '  - {name: rear, z: 0.25, axial: true}']
    return '\n'.join(lines) + '\n'


@pytest.fixture(scope='module')
def big_yaml(tmp_path_factory):
    path = tmp_path_factory.mktemp('big') / 'layout.yaml'
    path.write_text(block_yaml(10_000))
    return path


def test_a_yaml_layout_is_read_as_columns_within_3x_its_size(big_yaml):
    size = big_yaml.stat().st_size
    tracemalloc.start()
    try:
        layout = load_layout(big_yaml)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # Before: a node per scalar, then a dict per component: 57 times the text's size.
    assert peak < 3 * size, (peak, size)
    assert isinstance(layout.components, ComponentTable)
    # PyYAML reads these decimal numbers as YAML 1.2 does: a second, independent reader.
    reference = parse_layout(yaml.load(big_yaml.read_text(), Loader=yaml.CSafeLoader))
    assert layout == reference and layout.digest() == reference.digest()


def test_a_yaml_layout_over_its_limit_is_refused_before_reading_with_the_advice(tmp_path):
    path = tmp_path / 'huge.yaml'
    with open(path, 'w') as stream:
        stream.write('name: huge\ncomponents:\n')
        stream.truncate(64 * 2**20 + 1)           # sparse: no time, no disk
    with pytest.raises(LayoutError) as caught:
        load_layout(path)
    assert str(caught.value) == (
        f'{path}: a YAML layout of 67108865 bytes is over the limit of 67108864 bytes for '
        'YAML: write it as JSON (read as columns, 10^6 components in about 3 s)')


# -- commands: bounds and files that are not regular ------------------------------------------

def command_error(argv, capsys):
    """Parse a command line as ``cvc-balance`` does; return (exit code, its stderr line)."""
    with pytest.raises(SystemExit) as stop:      # refused while parsing: before any work
        parser().parse_args(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in err, err
    return stop.value.code, lines[0]


SWEEP = ['sweep', 'config/ct_gantry.yaml', '--component', 'xray_tube', '--parameter', 'mass',
         '--range', '50', '70']
FLEET = ['simulate-fleet', 'config/ct_gantry.yaml', '-o', 'OUT']
TOLERANCE = ['tolerance', 'config/ct_gantry.yaml', '--tolerances',
             'config/ct_gantry_tolerances.yaml']


@pytest.mark.parametrize('argv, option, good, bad, words', [
    (SWEEP, '--points', ['2', '2001'], '0',
     'argument --points: must be from 2 to 2001 points (per parameter; a map takes at most '
     '501 a side), got 0 points'),
    (FLEET, '--machines', ['1', '1000'], '1000000000',
     'argument --machines: must be from 1 to 1000 machines (a folder of bags each), got '
     '1000000000 machines'),
    (FLEET, '--rate', ['1', '1e5'], '1e9', 'argument --rate: must be from 1 to 100000 Hz'),
    (['fleet', 'bags', '--out', 'OUT/r.parquet'], '--workers', ['1', str(4 * os.cpu_count())],
     '1000', f'argument --workers: must be from 1 to {4 * os.cpu_count()} processes'),
    (['solve', 'config/ct_gantry.yaml'], '--omega', ['-1e5', '0', '1e5'], '1e9',
     'argument --omega: must be within +-100000 rad/s'),
    (TOLERANCE, '--seed', ['0', str(2**63 - 1)], '-1',
     'argument --seed: must be from 0 to 9223372036854775807 (a 64-bit seed), got -1'),
    (['record', '-o', 'OUT/x.mcap'], '--chunk-kib', ['1', '65536'], '100000000',
     'argument --chunk-kib: must be from 1 to 65536 KiB'),
    (['replay', 'bags/spin_up_tube_swap.mcap'], '--max-speed', ['1e-3', '1e5'], '1e9',
     'argument --max-speed: must be from 0.001 to 100000 rad/s'),
])
def test_every_numeric_option_is_bounded_and_says_its_range(
        argv, option, good, bad, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    argv = [str(tmp_path / a[4:]) if a.startswith('OUT/') else
            str(tmp_path / 'out') if a == 'OUT' else a for a in argv]
    for value in good:                            # the ends are taken
        args = parser().parse_args(argv + [f'{option}={value}'])
        expected = int(value) if value.lstrip('-').isdigit() else float(value)
        assert getattr(args, option[2:].replace('-', '_')) == expected
    code, line = command_error(argv + [f'{option}={bad}'], capsys)
    assert code == 2 and words in line, line
    assert os.listdir(tmp_path) == []            # refused before any work


@contextmanager
def alarm(seconds):
    """Raise TimeoutError if the block takes longer (a read that blocks, before the change)."""
    def ring(signum, frame):
        raise TimeoutError(f'still blocked after {seconds} s')
    previous = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / 'layout.yaml'
    os.mkfifo(path)
    return path


def test_a_fifo_or_a_device_is_refused_by_every_file_reader(fifo, tmp_path):
    from cvc_balance.bag.scenario import load_scenario, ScenarioError
    device = tmp_path / 'zero.yaml'
    device.symlink_to('/dev/zero')
    for path, kind in ((fifo, 'a FIFO (named pipe)'), (device, 'a character device')):
        with alarm(10):
            with pytest.raises(LayoutError) as caught:
                load_layout(path)
            assert str(caught.value) == f'{path}: {kind}, not a regular file: refused'
            said = f'{path}: {kind}, not a regular file: refused'
            with pytest.raises(ToleranceError, match=f'^{re.escape(said)}$'):
                load_tolerances(path, parse_layout(BASE))
            with pytest.raises(ScenarioError, match=f'^{re.escape(said)}$'):
                load_scenario(path)
            with pytest.raises(DocumentError, match=f'^{re.escape(said)}$'):
                read_document(path, 1000)


@pytest.mark.parametrize('argv', [
    ['solve', 'FIFO', '--omega', '1'],
    ['replay', 'FIFO'],
    ['replay', 'bags/spin_up_tube_swap.mcap', '--layout-file', 'FIFO'],
    ['tolerance', 'config/ct_gantry.yaml', '--tolerances', 'FIFO'],
    ['simulate', 'FIFO', '-o', 'OUT'],
])
def test_a_command_given_a_fifo_says_so_at_once(argv, fifo, tmp_path):
    argv = [str(fifo) if a == 'FIFO' else str(tmp_path / 'out.mcap') if a == 'OUT' else a
            for a in argv]
    # Before: solve and replay blocked in open() until the subprocess timeout.
    done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and f'{fifo}: a FIFO (named pipe), not a regular file' in lines[0]
    assert not (tmp_path / 'out.mcap').exists()


# -- at the limits: refused beyond, finite within -------------------------------------------------

def edges(low, high, high_beyond=True):
    """(inside values, beyond values) of the range [low, high] (low > 0)."""
    inside = [low, math.nextafter(low, math.inf), math.sqrt(low * high),
              math.nextafter(high, 0.0), high]
    beyond = [TINY, 1e-300, math.nextafter(low, 0.0)] \
        + ([math.nextafter(high, math.inf), 10 * high] if high_beyond else [])
    return inside, beyond


RANGES = {
    'mass': edges(MASS, BIG),
    'weight': edges(MASS, BIG),
    'shape': edges(SHAPE, BIG),
    'spacing': edges(SPACING, BIG, high_beyond=False),        # the positions bound them
    'plane_spacing': edges(SPACING, BIG, high_beyond=False),
    'correction_radius': edges(DIVISOR_RADIUS, BIG),
    'site_radius': edges(DIVISOR_RADIUS, BIG),
    'grade': edges(*GRADE),
    'service_speed': edges(*SPEED),
}
"""The quantities a layout divides by, or that are physically bounded, and their edges."""


@st.composite
def drawn_layouts(draw):
    """Draw a layout mapping; return it and whether a value is beyond the limits above."""
    beyond_field = draw(st.sampled_from([None] * 4 + sorted(RANGES)))
    used = []                     # a value drawn beyond its range, and put in the layout

    def value(field):
        inside, beyond = RANGES[field]
        if field == beyond_field:
            if 'spacing' not in field:       # a spacing: judged below as the layout holds it
                used.append(field)
            return draw(st.sampled_from(beyond))
        return draw(st.sampled_from(inside))

    def anywhere(limit):
        return draw(st.one_of(st.sampled_from([-limit, limit, 0.0, TINY, -TINY]),
                              st.floats(-limit, limit)))
    components = []
    for k in range(draw(st.integers(1, 4))):
        item = {'name': f'c{k}', 'mass': value('mass'),
                'radius': draw(st.sampled_from([0.0, TINY, 1e-9, 0.5, BIG])),
                'angle': anywhere(1e9), 'z': anywhere(BIG)}
        shape = draw(st.sampled_from([None, 'box', 'sphere', 'tube']))
        if shape == 'box':
            item['shape'] = {'type': 'box', 'size': [value('shape'), value('shape'), 0.1]}
        elif shape == 'sphere':
            item['shape'] = {'type': 'sphere', 'radius': value('shape')}
        elif shape == 'tube':
            inner = draw(st.sampled_from([SHAPE, 0.5]))
            item['shape'] = {'type': 'tube', 'inner_radius': inner,
                             'outer_radius': draw(st.sampled_from(
                                 [math.nextafter(inner, math.inf), 2 * inner, BIG])),
                             'length': value('shape')}
        components.append(item)
    front = draw(st.sampled_from([-0.25, 0.0, -BIG / 2]))
    supports = [{'name': 'front', 'z': front}]
    if draw(st.booleans()):
        rear = front + value('spacing')
        supports.append({'name': 'rear', 'z': rear, 'axial': True})
    balancing = {'grade': value('grade')}
    if len(supports) == 1 or draw(st.booleans()):
        z_i = draw(st.sampled_from([-0.3, 0.0, -BIG / 2]))
        balancing['planes'] = [z_i, z_i + value('plane_spacing')]
    if draw(st.booleans()):
        balancing['correction_radius'] = value('correction_radius')
    if draw(st.booleans()):
        balancing['service_speed'] = value('service_speed')
    if draw(st.booleans()):
        balancing['sites'] = {'I': {'angles_deg': [0, 120, 240], 'radius': value('site_radius'),
                                    'masses': [value('weight')]}}
    gravity = [anywhere(BIG), anywhere(BIG), anywhere(BIG)]
    mapping = {'name': 'drawn', 'components': components, 'supports': supports,
               'gravity': gravity, 'balancing': balancing}
    beyond = bool(used)
    # A spacing is that of the sum, which rounds: judge what the layout holds.
    if len(supports) == 2:
        beyond = beyond or not SPACING <= supports[1]['z'] - supports[0]['z']
    if 'planes' in balancing:
        z_i, z_ii = balancing['planes']
        beyond = beyond or not SPACING <= z_ii - z_i
    return mapping, beyond


def assert_finite(*values, where=''):
    for value in values:
        array = np.asarray(value, dtype=float)
        assert np.all(np.isfinite(array)), (where, value)


def motions():
    return st.tuples(st.floats(-1e9, 1e9), st.floats(-SPEED[1], SPEED[1]),
                     st.floats(-BIG, BIG))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(drawn_layouts(), st.lists(motions(), min_size=1, max_size=4))
def test_at_the_limits_a_layout_is_refused_beyond_and_finite_everywhere_within(
        drawn, samples):
    mapping, beyond = drawn
    try:
        layout = parse_layout(mapping)
    except LayoutError as error:
        event('refused')
        assert beyond, f'refused within the limits: {error}'
        assert '\n' not in str(error) and len(str(error)) < 300
        return
    assert not beyond, f'accepted beyond the limits: {mapping}'
    event('accepted')
    model = RotorModel.from_layout(layout)
    # Loads, one sample and vectorised.
    for q, omega, alpha in samples:
        one = sample_loads(model, q, omega, alpha)
        assert_finite(one.force_rotor, one.moment_rotor, one.force_stator, one.moment_stator,
                      one.drive_torque, where='sample')
        for force, moment in one.supports.values():
            assert_finite(force, moment, where='support')
    q, omega, alpha = (np.array(column) for column in zip(*samples))
    many = loads(model, q, omega, alpha)
    assert_finite(*many.support_force.values(), *many.support_moment.values(),
                  many.drive_torque, where='vectorised')
    # Unbalance and correction masses.
    assert_finite(static_unbalance(model), couple_unbalance(model), where='unbalance')
    planes = layout.correction_planes()
    if planes is not None:
        for plane in plane_unbalances(model, *planes, layout.correction_radius()):
            assert_finite(plane.amount, plane.angle, plane.correction_angle, where='plane')
            assert plane.correction_mass is None or math.isfinite(plane.correction_mass)
            sites = layout.balancing.sites_of('I')
            if sites is not None and plane.z == planes[0]:
                correction = -complex(*plane.vector)
                try:
                    split = vector_split(correction, sites)
                except ValueError:               # sites half a turn apart: said, not inf
                    split = ()
                for _, mass in split:
                    assert math.isfinite(mass)
                    assert all(map(math.isfinite, round_to_kit(mass, sites)))
    # The verdict, at every kind of top speed seen (a service speed wins when there is one).
    for top in (0.0, TINY, 1e-4, SPEED[0], 23.27, SPEED[1]):
        verdict = judge_balance(model, top)
        json.dumps(verdict_record(verdict), allow_nan=False)    # raises on inf or nan
        assert 'inf' not in verdict.text and 'nan' not in verdict.text, verdict.text
    # Plausibility warnings: text people read.
    for warning in layout_warnings(layout):
        words = warning.replace(',', ' ').replace('(', ' ').split()
        assert 'inf' not in words and 'nan' not in words, warning


def test_the_nodes_balance_grade_is_0_or_a_grade(tmp_path):
    """balance_grade:=1e-300 would divide to inf fractions: one line naming it, exit 2."""
    import subprocess
    import sys
    from ros_harness import ros_environment
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.ros.balance_monitor', '--ros-args',
                          '-p', 'balance_grade:=1e-300'], env=ros_environment(),
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    (line,) = [x for x in run.stderr.splitlines() if x.strip()]
    assert line == ('balance_monitor: error: parameter balance_grade must be from 0.1 to 4000 '
                    'mm/s (ISO 21940-11 grades run from G 0.4 to G 4000), got 1e-300 mm/s')
