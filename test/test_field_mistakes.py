"""
The layout's physics and the measured coefficients checking each other, and human mistakes.

The coefficients a layout predicts for load cells (:mod:`cvc_balance.field.model_check`,
through the engine) are checked against Pinocchio's RNEA of the layout with and without a
trial mass, demodulated here (straight and tilted gantries, one support and two). Then a
catalogue of mistakes people make at the trial stage (units, senses, planes, runs, cells)
is run through ``calibrate`` on simulated runs (:mod:`cvc_balance.bag.scenario`): each
must stop with exit code 2 and one line naming its cause. And 200 correct procedures
drawn at random (rotor, supports, tilt, speed, trial masses and angles, noise; the cells
read from Pinocchio's RNEA, not the engine) must raise no alarm.
"""

import copy
import math
from pathlib import Path
import re

import numpy as np
import pytest
import yaml

from cvc_balance.bag.scenario import load_scenario, write_bag
from cvc_balance.cli import main
from cvc_balance.field import calibrate, steady_window, track, Trial
from cvc_balance.field.model_check import check_coefficients, predicted_coefficients
from cvc_balance.physics import iso21940
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from independent import PinocchioRotor, tilted

ROOT = Path(__file__).resolve().parents[1]
FIELD_LAYOUT = ROOT / 'config' / 'ct_gantry_field.yaml'
HIDDEN = [{'name': 'heavier_hv_cover', 'mass': 0.35, 'radius': 0.6, 'angle_deg': 100.0,
           'z': 0.1},
          {'name': 'cable_clamp', 'mass': 0.25, 'radius': 0.5, 'angle_deg': 215.0, 'z': -0.13}]
TRIAL_I = {'name': 'trial_I', 'mass': 0.1, 'radius': 0.68, 'angle_deg': 30.0, 'z': -0.15}
TRIAL_II = {'name': 'trial_II', 'mass': 0.1, 'radius': 0.68, 'angle_deg': 120.0, 'z': 0.15}
TYPED = ['--trial', 'I:0.1@30,0.68', '--trial', 'II:0.1@120,0.68']


def demodulate(q, x):
    """Return the 1x phasor X of samples x at angles q over whole turns (x ~ c + Re(X e^{iq}))."""
    return 2.0 / len(q) * np.sum(np.asarray(x) * np.exp(-1j * np.asarray(q)))


def pinocchio_coefficients(layout, channels, z, omega):
    """Each channel's 1x change per kg m of a trial mass at z, by Pinocchio's RNEA."""
    trial = {'name': 'trial', 'mass': 0.3, 'radius': 0.5, 'angle': 0.0, 'z': z}
    with_trial = dict(copy.deepcopy(layout), components=layout['components'] + [trial])
    rotors = PinocchioRotor(layout), PinocchioRotor(with_trial)
    q = 2.0 * math.pi * np.arange(16) / 16
    out = []
    for name in channels:
        support, component = name.split('/')
        kind, axis = ('force' if component.startswith('force') else 'moment'), \
            'xyz'.index(component[-1])
        change = [rotors[1].loads(a, omega, 0.0)['supports'][support][kind == 'moment'][axis]
                  - rotors[0].loads(a, omega, 0.0)['supports'][support][kind == 'moment'][axis]
                  for a in q]
        out.append(demodulate(q, change) / (0.3 * 0.5))
    return np.array(out)


@pytest.mark.parametrize('supports, tilt, planes', [
    ([{'name': 'front', 'z': -0.12}, {'name': 'rear', 'z': 0.12, 'axial': True}], 0.0,
     [-0.15, 0.15]),
    ([{'name': 'a', 'z': -0.4}, {'name': 'b', 'z': 0.1, 'axial': True}], 25.0, [-0.2, 0.35]),
    ([{'name': 'slewing', 'z': 0.05, 'axial': True}], 20.0, [-0.1, 0.2])])
def test_the_layouts_coefficients_are_pinocchios(supports, tilt, planes):
    layout = yaml.safe_load(FIELD_LAYOUT.read_text())
    layout.update(supports=supports, gravity=tilted(tilt))
    layout['balancing'] = {'planes': planes, 'grade': 6.3}
    channels = [f"{s['name']}/force_{a}" for s in supports for a in 'xy']
    if len(supports) == 1:
        channels += [f"{supports[0]['name']}/torque_{a}" for a in 'xy']
    predicted, known = predicted_coefficients(parse_layout(layout), channels, ('I', 'II'), 17.3)
    assert known.all()
    for j, z in enumerate(planes):
        expected = pinocchio_coefficients(layout, channels, z, 17.3)
        assert np.max(np.abs(predicted[:, j] - expected)) < 1e-9 * np.max(np.abs(expected)), \
            (predicted[:, j], expected)


# -- the catalogue of mistakes -----------------------------------------------------------

def write_run(folder, name, extra, seed, cells=None):
    """Write a simulated run of the field gantry: the hidden unbalance and ``extra`` masses."""
    spec = {'name': name, 'layout': str(FIELD_LAYOUT), 'joint_name': 'gantry_joint',
            'rate': 250, 'seed': seed, 'noise': {'angle': 1e-4, 'speed': 0.005},
            'profile': [{'type': 'spin_up', 'to': 23.27, 'alpha': 12.0},
                        {'type': 'steady', 'duration': 3.0},
                        {'type': 'coast_down', 'to': 0.0, 'alpha': -12.0}],
            'hidden': [{'at': 0.0, 'add': dict(h)} for h in HIDDEN + extra],
            'load_cells': {'rate': 200, 'noise': 15.0,
                           'bias': {'front': [120.0, -340.0, 5.0],
                                    'rear': [-80.0, 55.0, -3.0]}}}
    path = folder / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec))
    scenario = load_scenario(path)
    if cells is not None:                # the cells installed wrong: what they then record
        readings = scenario.cell_readings()
        scenario.cell_readings = lambda: cells(readings)
    write_bag(scenario, folder / f'{name}.mcap')
    return folder / f'{name}.mcap'


def swap_cells(readings):
    return {'front': readings['rear'], 'rear': readings['front']}


def reverse_rear(readings):
    stamps, force, torque = readings['rear']
    return dict(readings, rear=(stamps, -force, -torque))


def front_in_kilonewtons(readings):
    stamps, force, torque = readings['front']
    return dict(readings, front=(stamps, force / 1000.0, torque / 1000.0))


def rear_axes_swapped(readings):
    stamps, force, torque = readings['rear']
    return dict(readings, rear=(stamps, force[:, [1, 0, 2]], torque))


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp('mistakes')
    bags = {'base': write_run(folder, 'base', [], 31),
            'I': write_run(folder, 'trial_I', [TRIAL_I], 32),
            'II': write_run(folder, 'trial_II', [TRIAL_II], 33),
            'II in plane I': write_run(folder, 'wrong_plane', [dict(TRIAL_II, z=-0.15)], 34),
            'II with I on': write_run(folder, 'kept', [TRIAL_I, TRIAL_II], 35),
            'II at 200 deg': write_run(folder, 'other_hole', [dict(TRIAL_II, angle_deg=200.0)],
                                       36)}
    for tag, cells in (('swapped', swap_cells), ('reversed', reverse_rear),
                       ('kN', front_in_kilonewtons), ('axes', rear_axes_swapped)):
        for k, (name, extra) in enumerate((('base', []), ('I', [TRIAL_I]),
                                           ('II', [TRIAL_II]))):
            bags[f'{name} {tag}'] = write_run(folder, f'{name}_{tag}', extra, 40 + k, cells)
    return bags


def calibrate_cli(capsys, *args):
    code = main(['calibrate', *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


MISTAKES = [
    # (what the person did, runs, typed trials, words the one line must name)
    ('trial mass in g typed as kg', ('base', 'I', 'II'),
     ['--trial', 'I:100@30,0.68', '--trial', 'II:0.1@120,0.68'],
     ('trial mass in g typed as kg', 'trial 1 (plane I')),
    ('both trial masses in g', ('base', 'I', 'II'),
     ['--trial', 'I:100@30,0.68', '--trial', 'II:100@120,0.68'],
     ('trial mass in g typed as kg', 'every trial')),
    ('radius in mm', ('base', 'I', 'II'),
     ['--trial', 'I:0.1@30,680', '--trial', 'II:0.1@120,680'], ('radius in mm typed as m',)),
    ('radius in cm', ('base', 'I', 'II'),
     ['--trial', 'I:0.1@30,68', '--trial', 'II:0.1@120,0.68'],
     ('radius in cm typed as m', 'trial 1 (plane I')),
    ('angles in the opposite sense', ('base', 'I', 'II'),
     ['--trial', 'I:0.1@-30,0.68', '--trial', 'II:0.1@-120,0.68'],
     ('opposite sense', 'every trial')),
    ('angle in radians', ('base', 'I', 'II'),
     ['--trial', 'I:0.1@30,0.68', '--trial', f'II:0.1@{math.radians(120.0)},0.68'],
     ('radians where degrees are read', 'trial 2 (plane II')),
    ('planes named the wrong way round', ('base', 'I', 'II'),
     ['--trial', 'II:0.1@30,0.68', '--trial', 'I:0.1@120,0.68'], ('planes swapped',)),
    ('trial runs given in the wrong order', ('base', 'II', 'I'), TYPED,
     ('another order than their --trial weights',)),
    ('trial bolted in the wrong plane', ('base', 'I', 'II in plane I'), TYPED,
     ('trial 2 (plane II', 'bolted in plane I')),
    ('trial left on for the next run', ('base', 'I', 'II with I on'), TYPED,
     ('stayed on', '--keep-trial')),
    ('--keep-trial but the trial was taken off', ('base', 'I', 'II'),
     TYPED + ['--keep-trial'], ('taken off before the next run',)),
    ('angles from another zero mark', ('base', 'I', 'II'),
     ['--trial', 'I:0.1@120,0.68', '--trial', 'II:0.1@210,0.68'],
     ('another zero mark', '-90 deg off')),
    ('trial at another hole than typed', ('base', 'I', 'II at 200 deg'), TYPED,
     ('trial 2 (plane II', 'another angle than typed', '+80 deg off')),
    ('cells of the two bearings swapped', ('base swapped', 'I swapped', 'II swapped'), TYPED,
     ('cells of supports front and rear swapped',)),
    ('a cell mounted the other way up', ('base reversed', 'I reversed', 'II reversed'), TYPED,
     ('cell of support rear reading with its sign reversed',)),
    ('a cell reading kN', ('base kN', 'I kN', 'II kN'), TYPED,
     ('cell of support front reading kN',)),
    ('a cell\'s x and y swapped', ('base axes', 'I axes', 'II axes'), TYPED,
     ('x and y axes of the cell of support rear swapped',)),
]
assert len(MISTAKES) >= 10                  # issue 23: a catalogue of ten mistakes at least


@pytest.mark.parametrize('what, runs, typed, named', MISTAKES, ids=[m[0] for m in MISTAKES])
def test_a_mistake_at_the_trial_stage_is_named(bags, capsys, what, runs, typed, named):
    code, out, err = calibrate_cli(capsys, *(bags[r] for r in runs), *typed)
    assert code == 2, (what, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and out == '', (what, err)
    assert lines[0].startswith('cvc-balance: error: the measured influence coefficients '
                               "disagree with the layout's physics"), lines[0]
    for words in named:
        assert words in lines[0], (what, words, lines[0])
    assert '--accept-mismatch to go on' in lines[0]


def test_the_correct_procedure_passes_and_says_so(bags, capsys):
    code, out, err = calibrate_cli(capsys, bags['base'], bags['I'], bags['II'], *TYPED)
    assert code == 0 and err == '', err
    line = next(li for li in out.splitlines() if 'physics' in li)
    said = re.fullmatch(r"the layout's physics predicts these coefficients: measured/predicted "
                        r'plane I (\S+) times ([+-]\d+) deg, plane II (\S+) times ([+-]\d+) deg',
                        line)
    assert said, line
    assert all(abs(float(said[k]) - 1.0) < 0.05 for k in (1, 3)), line
    assert all(abs(int(said[k])) <= 3 for k in (2, 4)), line


def test_an_accepted_mismatch_warns_and_is_kept(bags, capsys, tmp_path):
    record = tmp_path / 'c.yaml'
    code, out, err = calibrate_cli(capsys, bags['base'], bags['I'], bags['II'],
                                   '--trial', 'I:100@30,0.68', '--trial', 'II:0.1@120,0.68',
                                   '--accept-mismatch', '-o', record)
    assert code == 0
    assert err.startswith('cvc-balance: warning: the measured influence coefficients '
                          "disagree with the layout's physics"), err
    data = yaml.safe_load(record.read_text())
    check = data['model_check']
    assert check['agrees'] is False and 'trial mass in g typed as kg' in check['cause']
    factor = {p['plane']: p['factor'] for p in check['planes']}
    assert factor['I'] == pytest.approx(1e-3, rel=0.1)
    assert factor['II'] == pytest.approx(1.0, rel=0.1)
    assert "MISMATCH with the layout's physics (accepted)" in out
    # The stored record is refused again by correct unless accepted there too.
    code = main(['correct', str(bags['base']), '--coefficients', str(record)])
    _, err = capsys.readouterr()
    assert code == 2 and 'trial mass in g typed as kg' in err


# -- 200 correct procedures, drawn at random, cells by Pinocchio -------------------------

def random_procedure(rng):
    """Draw a random rotor and a correct trial procedure (layout mapping, hidden, trials, ...)."""
    count = int(rng.integers(1, 3))
    if count == 2:
        a = float(rng.uniform(-0.6, -0.05))
        supports = [{'name': 'front', 'z': a},
                    {'name': 'rear', 'z': a + float(rng.uniform(0.1, 0.9)), 'axial': True}]
    else:
        supports = [{'name': 'bearing', 'z': float(rng.uniform(-0.3, 0.3)), 'axial': True}]
    z_i = float(rng.uniform(-0.6, 0.3))
    planes = [z_i, z_i + float(rng.uniform(0.08, 0.8))]
    components = [{'name': 'drum', 'mass': float(rng.uniform(100.0, 600.0)), 'radius': 0.0,
                   'angle': 0.0, 'z': float(rng.uniform(-0.1, 0.1))}]
    for k in range(int(rng.integers(1, 5))):
        components.append({'name': f'part{k}', 'mass': float(rng.uniform(5.0, 120.0)),
                           'radius': float(rng.uniform(0.1, 0.8)),
                           'angle': float(rng.uniform(0.0, 2 * math.pi)),
                           'z': float(rng.uniform(-0.3, 0.3))})
    layout = {'name': 'random', 'components': components, 'supports': supports,
              'gravity': tilted(float(rng.uniform(-30.0, 30.0))),
              'balancing': {'planes': planes, 'correction_radius': 0.7, 'grade': 6.3}}
    hidden = [{'name': f'hidden{k}', 'mass': float(rng.uniform(0.05, 1.0)),
               'radius': float(rng.uniform(0.2, 0.8)),
               'angle': float(rng.uniform(0.0, 2 * math.pi)),
               'z': float(rng.uniform(-0.3, 0.3))} for k in range(2)]
    names = ['I', 'II'] + (['I'] if rng.random() < 0.25 else [])    # sometimes a third run
    trials = [Trial(p, float(rng.uniform(0.02, 0.5)), float(rng.uniform(-math.pi, math.pi)),
                    float(rng.uniform(0.3, 0.8))) for p in names]
    return layout, hidden, trials, planes, float(rng.uniform(8.0, 30.0)), \
        bool(rng.random() < 0.3)


def pinocchio_run(rotor, channels, omega, noise, rng, revolutions=3, per_turn=24):
    """Cell readings of a steady run by RNEA plus noise and a bias: their 1x and errors."""
    count = revolutions * per_turn + 1
    t = np.arange(count) / (per_turn * omega / (2 * math.pi))
    q = omega * t + 0.37
    samples = [rotor.loads(a, omega, 0.0)['supports'] for a in q]
    readings = {}
    for name in channels:
        support, component = name.split('/')
        kind, axis = component.startswith('torque'), 'xyz'.index(component[-1])
        values = np.array([sample[support][kind][axis] for sample in samples])
        readings[name] = values + rng.normal(0.0, noise, count) + rng.uniform(-300, 300)
    window = steady_window(t, q, np.full(count, omega))
    phasors = [track(t, readings[n], t, q, window) for n in channels]
    return np.array([p.value for p in phasors]), np.array([p.sigma for p in phasors])


def test_two_hundred_correct_procedures_raise_no_alarm():
    rng = np.random.default_rng(20240523)
    alarms, checked, factors, seen = [], 0, [], []
    for draw in range(200):
        layout, hidden, trials, planes, omega, keep = random_procedure(rng)
        channels = [f"{s['name']}/force_{a}" for s in layout['supports'] for a in 'xy']
        if len(layout['supports']) == 1:
            channels += [f"{layout['supports'][0]['name']}/torque_{a}" for a in 'xy']
        declared = parse_layout(layout)
        # The cells' noise such that the least visible trial is seen 6 to 300 standard
        # errors (the engine only sizes the noise; the readings come from Pinocchio).
        sizes, _ = predicted_coefficients(declared, channels, ('I', 'II'), omega)
        least = min(np.max(np.abs(sizes[:, ('I', 'II').index(t.plane)])) * abs(t.unbalance)
                    for t in trials)
        one_x = least / (math.sqrt(2.0) * math.exp(rng.uniform(math.log(6), math.log(300))))
        noise = one_x / math.sqrt(2.0 / (3 * 24))
        true = dict(copy.deepcopy(layout), components=layout['components'] + hidden)
        base, sigma = pinocchio_run(PinocchioRotor(true), channels, omega, noise, rng)
        on, runs, sigmas = [], [], []
        for k, trial in enumerate(trials):
            mass = {'name': f'trial{k}', 'mass': trial.mass, 'radius': trial.radius,
                    'angle': trial.angle, 'z': planes[('I', 'II').index(trial.plane)]}
            on = (on if keep else []) + [mass]
            rotor = PinocchioRotor(dict(true, components=true['components'] + on))
            values, errors = pinocchio_run(rotor, channels, omega, noise, rng)
            runs.append(values)
            sigmas.append(errors)
        calibration = calibrate(base, trials, runs, channels, keep, sigma, sigmas)
        seen += [c.snr for c in calibration.checks]
        model = RotorModel.from_layout(declared)
        check = check_coefficients(
            declared, calibration, omega, trials, keep,
            iso21940.permissible_unbalance(6.3, model.mass, omega))
        checked += check.checked
        factors += [p.factor for p in check.planes]
        if check.mismatch:
            alarms.append((draw, check.message))
    assert checked == 200
    assert alarms == []
    assert min(seen) < 10 and max(seen) > 200         # the noise drawn as meant
    # The agreement is close, not merely within a factor 3 and 45 deg.
    worst = max(abs(f - 1.0) for f in factors)
    print(f'trials seen {min(seen):.3g}-{max(seen):.3g} standard errors; measured/predicted '
          f'within {worst:.3g} of 1')
    assert worst < 0.35
