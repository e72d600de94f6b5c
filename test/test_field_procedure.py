"""
The field procedure's guards, and the trial weight advised before the trial runs.

One layout segment at a time, no plan that makes things worse, coefficients that cannot be
used refused.

Expected values come from outside the code under test: the layout messages' log times and
texts as rosbags reads them, the simulator's true rotor per segment (its scenario file)
reduced by ISO 21940-2's formulas, hand statics of the rigid rotor, and the readings'
standard errors recomputed here from the cells by least squares.
"""

from html.parser import HTMLParser
import json
import math
from pathlib import Path
import re

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
import yaml

from cvc_balance.bag.scenario import load_scenario, write_bag
from cvc_balance.cli import main
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.layout_file import layout_from_text

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / 'bags'
FIELD_LAYOUT = ROOT / 'config' / 'ct_gantry_field.yaml'
BUNDLED = [BAGS / 'field_baseline.mcap', BAGS / 'field_trial_I.mcap',
           BAGS / 'field_trial_II.mcap']
TRIALS = ['--trial', 'I:0.2@0,0.68', '--trial', 'II:0.2@0,0.68']


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def json_of(capsys, *args):
    code, out, err = run(capsys, *args, '--json')
    assert code == 0, err
    return json.loads(out), err


def layout_messages(bag):
    """[(log time s, layout text)] of a bag's /layout, by rosbags."""
    out = []
    with AnyReader([Path(bag)]) as reader:
        connections = [c for c in reader.connections if c.topic == '/layout']
        for connection, log_time, raw in reader.messages(connections=connections):
            out.append((log_time * 1e-9, reader.deserialize(raw, connection.msgtype).data))
    return out


def truth_grade(scenario_file, at):
    """Return the true rotor's equivalent grade at ``at`` s of a scenario (ISO 21940-2 by hand)."""
    scenario = load_scenario(scenario_file)
    truth = [m for t, m in scenario.truths if t <= at][-1]
    declared = [m for t, m in scenario.layouts if t <= at][-1]
    mass = sum(c['mass'] for c in truth['components'])
    z_i, z_ii = -0.12, 0.12                   # the demo gantry's planes: its supports
    planes = [0j, 0j]
    centre = sum(c['mass'] * c.get('z', 0.0) for c in truth['components']) / mass
    for c in truth['components']:
        u = c['mass'] * c['radius'] * complex(math.cos(math.radians(c.get('angle_deg', 0.0))),
                                              math.sin(math.radians(c.get('angle_deg', 0.0))))
        planes[0] += u * (z_ii - c.get('z', 0.0)) / (z_ii - z_i)
        planes[1] += u * (c.get('z', 0.0) - z_i) / (z_ii - z_i)
    shares = [min(max((z_ii - centre) / 0.24, 0.3), 0.7), min(max((centre - z_i) / 0.24, 0.3),
                                                              0.7)]
    speed = 23.27
    grade = max(abs(u) / s for u, s in zip(planes, shares)) * speed / mass * 1e3
    return grade, declared


def test_correct_reads_one_layout_segment_never_across_the_change(capsys):
    bag = BAGS / 'loose_bracket.mcap'
    messages = layout_messages(bag)
    assert len(messages) == 2
    change = messages[1][0]
    digests = [layout_from_text(text).digest() for _, text in messages]
    summary, _ = json_of(capsys, 'correct', bag)
    used = summary['run']
    # The longest steady stretch is after the tube swap, and does not reach back before it.
    assert used['segment'] == 2 and used['layout']['digest'] == digests[1]
    assert change <= used['window'][0] < used['window'][1]
    assert [s['layout']['digest'] for s in summary['segments']] == digests
    assert summary['segments'][0]['to'] < change <= summary['segments'][1]['from']
    first, _ = json_of(capsys, 'correct', bag, '--segment', '1')
    assert first['run']['segment'] == 1 and first['run']['layout']['digest'] == digests[0]
    assert first['run']['window'][1] <= change
    # Each segment's grade is its own rotor's: the truth of the scenario, segment by segment.
    for segment in summary['segments']:
        expected, _ = truth_grade(BAGS / 'loose_bracket.yaml', segment['from'] - 1.0 + 0.5)
        assert segment['grade']['equivalent_grade'] == pytest.approx(expected, rel=0.03)
    assert summary['grade']['before']['equivalent_grade'] == \
        summary['segments'][1]['grade']['equivalent_grade']
    # And people read which one was used.
    code, out, _ = run(capsys, 'correct', bag)
    lines = out.splitlines()
    assert re.match(r"\* segment 2 \(8\.0\d\d-15\.\d+ s, layout 'ct_gantry_demo' \("
                    + digests[1] + r"\)\): steady 8\.0\d\d-12\.\d+ s at 23\.27 rad/s, 18 "
                    r'revolutions; cells: G 15\.\d \(read\)$', lines[2]), lines[2]
    assert lines[3] == '  (read segment 2 of 2: --segment N to choose; never across a layout ' \
        'change)'
    code, _, err = run(capsys, 'correct', bag, '--segment', '3')
    assert code == 2 and '--segment 3: the run has 2 layout segments' in err


def test_calibrate_reads_each_run_in_one_segment(tmp_path, capsys):
    spec = yaml.safe_load((BAGS / 'field_baseline.yaml').read_text())
    spec.update(layout=str(FIELD_LAYOUT), seed=5)
    # The declared layout changes 2 s into the steady stretch: the drum on the axis said
    # heavier (a new digest; the trial runs' rotor stays the same).
    spec['events'] = [{'at': 5.0, 'set': {'component': 'rotating_frame', 'mass': 420.5}}]
    (tmp_path / 'baseline.yaml').write_text(yaml.safe_dump(spec))
    baseline = tmp_path / 'baseline.mcap'
    write_bag(load_scenario(tmp_path / 'baseline.yaml'), baseline)
    change = layout_messages(baseline)[1][0]
    record, _ = json_of(capsys, 'calibrate', baseline, *BUNDLED[1:], *TRIALS)
    first = record['runs'][0]
    assert first['segments'] == 2 and first['segment']['number'] == 2
    assert change <= first['segment']['steady']['window'][0]
    assert all(r['segment']['number'] == 1 and r['segments'] == 1 for r in record['runs'][1:])
    record, _ = json_of(capsys, 'calibrate', baseline, *BUNDLED[1:], *TRIALS,
                        '--segment', '1', '1', '1')
    assert record['runs'][0]['segment']['steady']['window'][1] <= change
    code, out, err = run(capsys, 'calibrate', baseline, *BUNDLED[1:], *TRIALS)
    assert code == 0
    assert re.search(r'^  read in segment 2 \(6\.\d+-12\.\d+ s, layout .*\): steady 6\.\d+-'
                     r'9\.\d+ s at 23\.27 rad/s, \d+ revolutions \(of 2; --segment to choose\)$',
                     out, re.M), out
    code, _, err = run(capsys, 'calibrate', baseline, *BUNDLED[1:], *TRIALS, '--segment',
                       '1', '1')
    assert code == 2 and 'one number for every run or one per run (3), got 2' in err


@pytest.fixture(scope='module')
def mirrored(tmp_path_factory):
    """Coefficients whose plane II trial was typed at 180 deg; it was at 0 (accepted)."""
    record = tmp_path_factory.mktemp('mirrored') / 'c.yaml'
    assert main(['calibrate', *map(str, BUNDLED), '--trial', 'I:0.2@0,0.68', '--trial',
                 'II:0.2@180,0.68', '--accept-mismatch', '-o', str(record)]) == 0
    return record


def test_no_plan_is_recommended_that_leaves_the_rotor_worse(mirrored, capsys, tmp_path):
    code, out, err = run(capsys, 'correct', BUNDLED[0], '--coefficients', mirrored, '--json')
    assert code == 2 and 'trial 2 (plane II' in err and 'another angle than typed' in err
    summary, err = json_of(capsys, 'correct', BUNDLED[0], '--coefficients', mirrored,
                           '--accept-mismatch')
    before = summary['grade']['before']['equivalent_grade']
    assert before == pytest.approx(9.17, abs=0.01)
    for plan in summary['plans']:
        worse = plan['after']['equivalent_grade'] > before or \
            plan['residual']['rms'] > summary['before']['residual']['rms']
        assert plan['worse'] == worse, plan['name']
    continuous = summary['plans'][0]
    # Bolted on the rotor the cells measured, the continuous "correction" doubles plane II.
    assert continuous['after']['equivalent_grade'] == pytest.approx(18.4, abs=0.1)
    assert all(p['worse'] for p in summary['plans'])
    assert summary['recommended'] is None
    said = [w for w in summary['warnings'] if w.startswith('no plan is recommended')]
    assert said == ['no plan is recommended: each would leave the rotor worse than it is (the '
                    'continuous correction: G 18.4 predicted after, against G 9.17 now by the '
                    'load cells); check the coefficients and the trial runs']
    assert 'cvc-balance: warning: ' + said[0] in err
    out = tmp_path / 'report'
    code, text, _ = run(capsys, 'report', BUNDLED[0], '--coefficients', mirrored,
                        '--accept-mismatch', '-o', out)
    assert code == 0 and 'no plan recommended' in text

    class Page(HTMLParser):
        def __init__(self):
            super().__init__()
            self.ids, self.text = [], []

        def handle_starttag(self, tag, attrs):
            self.ids += [v for k, v in attrs if k == 'id']

        def handle_data(self, data):
            self.text.append(data)

    page = Page()
    page.feed((out / 'report.html').read_text())
    assert 'no-plan' in page.ids and 'physics' in page.ids and 'segments' in page.ids
    assert 'Nothing: no plan is recommended.' in page.text


def test_the_correct_procedure_still_recommends(capsys, tmp_path):
    assert run(capsys, 'calibrate', *BUNDLED, *TRIALS, '-o', tmp_path / 'c.yaml')[0] == 0
    summary, _ = json_of(capsys, 'correct', BUNDLED[0], '--coefficients', tmp_path / 'c.yaml')
    assert summary['recommended'] == 'optimal'
    assert [p['worse'] for p in summary['plans']] == [False, False, False]
    assert summary['model_check']['agrees'] is True


def coefficient_record(capsys, tmp_path):
    path = tmp_path / 'c.yaml'
    assert run(capsys, 'calibrate', *BUNDLED, *TRIALS, '-o', path)[0] == 0
    return yaml.safe_load(path.read_text())


def test_singular_and_rank_deficient_coefficients_are_refused(capsys, tmp_path):
    record = coefficient_record(capsys, tmp_path)
    alike = dict(record, coefficients=[[row[0], dict(row[0])] for row in record['coefficients']])
    one_sensor = dict(record, sensors=record['sensors'][:1], ci95=None,
                      coefficients=record['coefficients'][:1],
                      reading_units=record['reading_units'][:1])
    for name, bad, needle in (('alike', alike, 'are singular (condition number'),
                              ('one', one_sensor, '1 sensor for 2 planes: rank-deficient')):
        path = tmp_path / f'{name}.yaml'
        path.write_text(yaml.safe_dump(bad))
        code, out, err = run(capsys, 'correct', BUNDLED[0], '--coefficients', path)
        assert code == 2 and out == '' and len(err.splitlines()) == 1, err
        assert needle in err, err


def test_a_plane_the_layout_lacks_is_refused(capsys):
    code, out, err = run(capsys, 'calibrate', *BUNDLED, '--trial', 'III:0.2@0,0.68',
                         '--trial', 'II:0.2@0,0.68')
    assert code == 2 and out == ''
    assert err == "cvc-balance: error: --trial: plane III: the layout 'ct_gantry_field' has " \
        'correction planes I (z -0.15 m), II (z 0.15 m)\n'


def test_a_site_radius_too_small_for_any_correction_is_refused(capsys, tmp_path):
    layout = yaml.safe_load(FIELD_LAYOUT.read_text())
    layout['balancing']['sites']['I']['radius'] = 1e-6
    path = tmp_path / 'tiny.yaml'
    path.write_text(yaml.safe_dump(layout))
    code, out, err = run(capsys, 'correct', BUNDLED[0], '--layout-file', path)
    assert code == 2 and out == ''
    assert re.fullmatch(r'cvc-balance: error: plane I: the correction needs 1\.17e\+05 kg at r '
                        r'1e-06 m \(balancing\.sites\.I\.radius\), more than the whole rotor\'s '
                        r'925\.5 kg: that radius cannot be right\n', err), err


# -- trial weights before the trial runs -----------------------------------------------

def cell_standard_errors(bag, window):
    """Each cell force's 1x standard error over the window, by least squares here."""
    from cvc_balance.bag.mcap_reader import wrench_samples
    from cvc_balance.bag.replay import read_inputs
    from cvc_balance.bag.rosbag2 import open_bag

    opened = open_bag(bag)
    motion, _ = read_inputs(opened, 'gantry_joint')
    t, q = motion.stamp * 1e-9, np.unwrap(motion.angle)
    out = {}
    for support in ('front', 'rear'):
        stamps, force, _ = wrench_samples(
            opened, opened.channel(f'/supports/{support}/measured_load',
                                   'geometry_msgs/msg/WrenchStamped'))
        time = stamps * 1e-9
        inside = (time >= window[0]) & (time < window[1])
        angle = np.interp(time[inside], t, q)
        design = np.column_stack([np.ones(inside.sum()), np.cos(angle), np.sin(angle)])
        for axis, values in zip('xy', force[inside, :2].T):
            fit, residual, *_ = np.linalg.lstsq(design, values, rcond=None)
            variance = residual[0] / (len(values) - 3)
            covariance = np.linalg.inv(design.T @ design) * variance
            out[f'{support}/force_{axis}'] = math.sqrt(0.5 * (covariance[1, 1]
                                                              + covariance[2, 2]))
    return out


def test_trial_weight_from_a_baseline_by_hand(capsys):
    advice, _ = json_of(capsys, 'trial-weight', BUNDLED[0])
    window = advice['run']['window']
    sigma = cell_standard_errors(BUNDLED[0], window)
    omega = advice['speed']
    layout = parse_layout(yaml.safe_load(FIELD_LAYOUT.read_text()))
    mass = sum(c.mass for c in layout.components)
    centre = sum(c.mass * c.z for c in layout.components) / mass
    weight = {'front': mass * 9.80665 * (0.12 - centre) / 0.24,
              'rear': mass * 9.80665 * (centre + 0.12) / 0.24}
    for plane, z in zip(advice['planes'], (-0.15, 0.15)):
        # Hand statics: a kg m at z loads front and rear with omega^2 (z_b - z) / L, ...
        per = {'front': omega ** 2 * (0.12 - z) / 0.24, 'rear': omega ** 2 * (z + 0.12) / 0.24}
        seen = max(abs(per[name.split('/')[0]]) / (math.sqrt(2) * s) for name, s in
                   sigma.items())
        wanted = 20.0 / seen
        assert plane['wanted_g_mm'] == pytest.approx(wanted * 1e6, rel=1e-6)
        assert plane['unbalance_g_mm'] == pytest.approx(wanted * 1e6, rel=1e-6)
        assert plane['mass'] == pytest.approx(wanted / 0.68, rel=1e-6)
        assert plane['standard_errors'] == pytest.approx(20.0)
        bearing = min(0.1 * weight[s] / abs(per[s]) for s in per)
        assert plane['bearing_cap_g_mm'] == pytest.approx(bearing * 1e6, rel=1e-9)
        share = min(max((0.15 - centre) / 0.3 if z < 0 else (centre + 0.15) / 0.3, 0.3), 0.7)
        assert plane['grade_cap_g_mm'] == pytest.approx(
            6.3e-3 * mass / 23.27 * share * 1e6, rel=1e-9)
        assert plane['kit']['masses'] == [0.05]          # the kit's smallest plate above
    code, out, _ = run(capsys, 'trial-weight', BUNDLED[0])
    assert re.search(r'^  plane I \(z -0\.150 m\): 4\d\.\d g at r 0\.680 m \(\d+ g mm\), moves '
                     r'the readings 20 standard errors$', out, re.M), out
    assert re.search(r'^    from the kit: 50 g \(2\d\.\d standard errors\)$', out, re.M), out


def test_the_advised_trial_is_seen_as_advised(capsys, tmp_path):
    """Bolt the advised mass on a simulated trial run: calibrate sees it about 20 times."""
    advice, _ = json_of(capsys, 'trial-weight', BUNDLED[0])
    plane = advice['planes'][0]
    spec = yaml.safe_load((BAGS / 'field_trial_I.yaml').read_text())
    spec.update(layout=str(FIELD_LAYOUT), seed=77)
    spec['hidden'][-1]['add'].update(mass=plane['mass'])
    (tmp_path / 'trial.yaml').write_text(yaml.safe_dump(spec))
    write_bag(load_scenario(tmp_path / 'trial.yaml'), tmp_path / 'trial.mcap')
    record, _ = json_of(capsys, 'calibrate', BUNDLED[0], tmp_path / 'trial.mcap',
                        '--trial', f"I:{plane['mass']}@0,0.68")
    snr = record['trials'][0]['snr']
    assert 14.0 < snr < 26.0, snr                     # 20, give or take the noise


def test_trial_weight_from_the_layout_alone(capsys):
    advice, _ = json_of(capsys, 'trial-weight', '--layout-file', FIELD_LAYOUT)
    for plane in advice['planes']:
        # No noise known: the starting rule, 10 % of a bearing's load, within the grade's cap.
        assert plane['standard_errors'] is None and plane['wanted_g_mm'] is None
        expected = min(plane['grade_cap_g_mm'], plane['bearing_cap_g_mm'])
        assert plane['unbalance_g_mm'] == pytest.approx(expected)
        assert plane['capped_by'] == 'grade'
        assert sum(plane['kit']['masses']) * 0.68e6 <= plane['grade_cap_g_mm']
    assert [p['kit']['masses'] for p in advice['planes']] == [[0.1, 0.05], [0.2]]
    advice, _ = json_of(capsys, 'trial-weight', '--layout-file', FIELD_LAYOUT, '--sigma',
                        '0.6')
    assert all(p['standard_errors'] == pytest.approx(20.0) for p in advice['planes'])
    code, _, err = run(capsys, 'trial-weight')
    assert code == 2 and 'give a baseline run, or the layout with --layout-file' in err
