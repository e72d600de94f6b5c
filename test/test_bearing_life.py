"""
Bearing life (ISO 281 basic rating life) against independent references.

* A bearing maker's printed examples, to their printed digits: SKF's catalogue example
  (6309, C 55.3 kN, 10 kN radial at 3000 r/min: L10 169 million revolutions, 940 h) and its
  bearing calculator's report (6309, Fr 4 kN, Fa 0.5 kN at 1800 r/min: P 4 kN, C/P 13.8,
  L10h 24500 h).
* A constant load over a spin-up (closed form: (P/C)^p times the revolutions, which the
  motion gives by hand), and ISO 281's factors switching at Fa/Fr = e.
* A static plus a rotating load against mpmath's quadrature of |F(q)|^p over the angle the
  rotor turned.
* A ramp through the whole command (``cvc-balance life --json``), the loads from Pinocchio's
  RNEA split by statics by hand, the balanced rotor's by hand from Pinocchio's mass
  properties.
* Load cells (a simulated run, the cells' zeros off): measured and layout lives agree when
  the rotor is its layout, and the measured life is the true rotor's when it is not.
* A bag whose layouts describe no bearing: one line naming the field, no numbers, exit 1;
  a bearing field out of range: one line; a layout without bearings keeps its digest.
"""

import copy
import json
import math

import mpmath
import numpy as np
import pytest
import yaml

from cvc_balance.cli import main
from cvc_balance.physics.bearing_life import LifeCounters
from cvc_balance.physics.layout import Bearing, LayoutError
from cvc_balance.physics.layout_file import layout_from_text, load_layout
from independent import PinocchioRotor, ramp, write_input_bag

GANTRY = yaml.safe_load(open('config/ct_gantry.yaml'))
BEARINGS = yaml.safe_load(open('config/ct_gantry_bearings.yaml'))


class Support:
    """A support as the counters read it: a name and a bearing."""

    def __init__(self, name, bearing):
        self.name, self.bearing = name, bearing


def steady_run(rpm, seconds, rate=2000.0):
    """Return samples of a constant speed: time s, angle rad (wrapped), omega rad/s."""
    omega = rpm * 2.0 * math.pi / 60.0
    time = np.arange(int(seconds * rate) + 1) / rate
    return time, np.remainder(omega * time, 2.0 * math.pi), np.full(len(time), omega)


def counted(bearing, time, angle, omega, force):
    """Return the LifeUse of one bearing under ``force`` (n, 3) over the samples, by blocks."""
    counters = LifeCounters([Support('b', bearing)])
    for a in range(0, len(time), 1000):     # in blocks: the steps between them count too
        counters.add(time[a:a + 1000], angle[a:a + 1000], omega[a:a + 1000],
                     {'b': force[a:a + 1000]})
    return counters.uses()['b']


def test_skf_catalogue_example_to_its_printed_digits():
    # SKF, Rolling bearings (catalogue PUB BU/P1 10000/2 EN), "Calculation examples",
    # Example 1: SKF Explorer 6309 at 3 000 r/min under a constant radial load Fr = 10 kN;
    # C = 55,3 kN, P = Fr: L10 = (55,3/10)^3 = 169 million revolutions, L10h = 10^6 /
    # (60 x 3 000) x 169 = 940 operating hours.
    # https://www.yumpu.com/en/document/view/55668573/skf-rolling-bearings/92
    time, angle, omega = steady_run(3000.0, 2.0)
    force = np.zeros((len(time), 3))
    force[:, 0] = 10_000.0
    use = counted(Bearing(55_300.0, 'ball'), time, angle, omega, force)
    assert round(use.revolutions / use.life_used / 1e6) == 169      # L10, 10^6 revolutions
    assert round(use.rating_life_hours) == 940
    assert use.equivalent_load == pytest.approx(10_000.0, rel=1e-12)
    assert use.revolutions == pytest.approx(100.0, rel=1e-12)        # 3000 r/min, 2 s


def test_skf_calculator_report_with_an_axial_load_below_e():
    # SKF Bearing Calculator, calculation summary report, designation 6309 (C 55.3 kN,
    # C0 31.5 kN): radial load 4 kN, axial load 0.5 kN, inner ring at 1800 r/min; result:
    # equivalent dynamic bearing load P 4 kN, load ratio C/P 13.8, basic rating life
    # L10h 24500 hour. Fa/Fr = 0.125 is below e (SKF's table: e about 0.2 at
    # f0 Fa/C0 = 13.1 x 0.5 / 31.5 = 0.21), so P = Fr.
    # https://ja.scribd.com/document/254704766/SELECCION-RODAMIENTO1
    time, angle, omega = steady_run(1800.0, 2.0)
    force = np.zeros((len(time), 3))
    force[:, 1], force[:, 2] = -4_000.0, 500.0
    bearing = Bearing(55_300.0, 'ball', X=0.56, Y=2.2, e=0.2)
    use = counted(bearing, time, angle, omega, force)
    assert use.equivalent_load == pytest.approx(4_000.0, rel=1e-12)
    assert round(bearing.C / use.equivalent_load, 1) == 13.8
    assert f'{use.rating_life_hours:.3g}' == '2.45e+04'              # 24500 hour


def test_constant_load_over_a_spin_up_is_the_closed_form():
    # A roller bearing under a constant radial and axial load beyond e, over a spin-up from
    # rest and a steady part: P = X Fr + Y Fa by hand, and the revolutions by hand.
    alpha, top, rate = 4.0, 30.0, 1000.0
    ramp_time = top / alpha
    time = np.arange(int(12.0 * rate) + 1) / rate
    omega = np.minimum(alpha * time, top)
    turned = np.where(time <= ramp_time, 0.5 * alpha * time ** 2,
                      0.5 * alpha * ramp_time ** 2 + top * (time - ramp_time))
    bearing = Bearing(90_000.0, 'roller', X=0.4, Y=1.6, e=0.37, a1=0.21)
    force = np.tile([3_000.0, -4_000.0, 2_500.0], (len(time), 1))    # Fr 5 kN, Fa 2.5 kN
    load = 0.4 * 5_000.0 + 1.6 * 2_500.0                              # Fa/Fr 0.5 > e
    use = counted(bearing, time, np.remainder(turned, 2 * math.pi), omega, force)
    revolutions = turned[-1] / (2 * math.pi)
    assert use.revolutions == pytest.approx(revolutions, rel=1e-12)
    assert use.equivalent_load == pytest.approx(load, rel=1e-12)
    used = (load / 90_000.0) ** (10.0 / 3.0) * revolutions / 1e6 / 0.21
    assert use.life_used == pytest.approx(used, rel=1e-12)
    assert use.rating_life_hours == pytest.approx(12.0 / 3600.0 / used, rel=1e-12)
    # Below e, the same bearing takes the radial load alone.
    force[:, 2] = 1_000.0                                             # Fa/Fr 0.2 < e
    below = counted(bearing, time, np.remainder(turned, 2 * math.pi), omega, force)
    assert below.equivalent_load == pytest.approx(5_000.0, rel=1e-12)


def test_static_and_rotating_load_against_quadrature_over_the_angle():
    # A static load (the weight) and one turning with the rotor (an unbalance): the bearing's
    # damage is the integral of (|F(q)|/C)^p over the angle turned, by mpmath's quadrature.
    static = np.array([400.0, -5_200.0])
    rotating, phase = 3_100.0, 0.7
    rpm, seconds = 400.0, 3.37                   # 22.47 revolutions: not a whole number
    time, angle, omega = steady_run(rpm, seconds, rate=1000.0)
    turned = omega[0] * time
    force = np.zeros((len(time), 3))
    force[:, 0] = static[0] + rotating * np.cos(turned + phase)
    force[:, 1] = static[1] + rotating * np.sin(turned + phase)
    for kind, p in (('ball', 3), ('roller', mpmath.mpf(10) / 3)):
        bearing = Bearing(60_000.0, kind)
        use = counted(bearing, time, angle, omega, force)

        def rate(q):
            x = static[0] + rotating * mpmath.cos(q + phase)
            y = static[1] + rotating * mpmath.sin(q + phase)
            return (mpmath.sqrt(x * x + y * y) / 60_000) ** p
        end = mpmath.mpf(float(turned[-1]))
        whole = int(end // (2 * mpmath.pi))
        damage = whole * mpmath.quad(rate, [0, mpmath.pi, 2 * mpmath.pi]) / (2 * mpmath.pi) \
            + mpmath.quad(rate, [2 * mpmath.pi * whole, end]) / (2 * mpmath.pi)
        # The trapezoid over 0.042 rad steps: within h^2/12 |L'(end) - L'(0)| of the
        # integral over a part of a turn (measured 2.0e-6 of the damage, both kinds).
        assert use.damage == pytest.approx(float(damage), rel=1e-5), kind
        assert use.revolutions == pytest.approx(float(end / (2 * mpmath.pi)), rel=1e-12)


def bearings_layout():
    """Return the pipeline gantry of test_pipeline_reference, a large unbalance, bearings."""
    layout = {
        'name': 'life_gantry', 'gravity': [0.0, -9.80665, 0.0],
        'components': [
            {'name': 'drum', 'mass': 250.0, 'radius': 0.0, 'angle': 0.0,
             'shape': {'type': 'tube', 'inner_radius': 0.62, 'outer_radius': 0.7,
                       'length': 0.4}},
            {'name': 'tube', 'mass': 60.0, 'radius': 0.55, 'angle_deg': 15.0, 'z': 0.06,
             'shape': {'type': 'cylinder', 'radius': 0.09, 'length': 0.35,
                       'axis': 'tangential'}},
            {'name': 'detector', 'mass': 90.0, 'radius': 0.5, 'angle_deg': 190.0, 'z': -0.04,
             'shape': {'type': 'box', 'size': [0.12, 0.8, 0.16]}},
            {'name': 'lump', 'mass': 12.0, 'radius': 0.6, 'angle_deg': 280.0, 'z': 0.25}],
        'supports': [
            {'name': 'front', 'z': -0.3, 'bearing': {'C': 40_000.0, 'type': 'ball'}},
            {'name': 'rear', 'z': 0.35, 'axial': True,
             'bearing': {'C': 50_000.0, 'type': 'roller', 'a1': 0.62}}],
        'balancing': {'planes': [-0.2, 0.25], 'correction_radius': 0.65, 'grade': 6.3,
                      'service_speed': 23.27}}
    return layout


@pytest.fixture(scope='module')
def pinocchio_run(tmp_path_factory):
    """Write a spin-up bag of the bearings layout; return it and its motion."""
    folder = tmp_path_factory.mktemp('life')
    layout = bearings_layout()
    stamps, angle, omega = ramp(0.5, 3.0, rate=200.0, seconds=8.0)
    bag = write_input_bag(folder / 'in.mcap', stamps, angle, omega,
                          [(int(stamps[0]) - 1_000_000, yaml.safe_dump(layout))])
    return {'layout': layout, 'bag': bag, 'stamps': stamps, 'angle': angle, 'omega': omega}


def test_whole_command_against_pinocchio(pinocchio_run, capsys):
    run = pinocchio_run
    assert main(['life', str(run['bag']), '--json']) == 0
    found = json.loads(capsys.readouterr().out)
    assert list(found) == ['segments'] and len(found['segments']) == 1
    segment = found['segments'][0]
    assert segment['layout']['name'] == 'life_gantry'
    rotor = PinocchioRotor(run['layout'])
    stamps, omega = run['stamps'], run['omega']
    alpha = np.full(len(stamps), 3.0)
    alpha[0] = 0.0                        # the estimator's first sample: no slope yet
    forces = [rotor.loads(q, w, a)['supports'] for q, w, a in zip(run['angle'], omega, alpha)]
    seconds = (stamps - stamps[0]) * 1e-9
    steps = 0.5 * (omega[1:] + omega[:-1]) * np.diff(seconds) / (2 * math.pi)   # exact: ramp
    mass, com, _ = rotor.mass_properties()
    supports = {s['name']: s for s in run['layout']['supports']}
    z_a, z_b = supports['front']['z'], supports['rear']['z']
    weight = mass * 9.80665                     # the balanced rotor: its weight, by statics
    quiet = {'front': weight * (z_b - com[2]) / (z_b - z_a),
             'rear': weight * (com[2] - z_a) / (z_b - z_a)}
    assert [s['name'] for s in segment['supports']] == ['front', 'rear']
    for record in segment['supports']:
        name, spec = record['name'], supports[record['name']]['bearing']
        p = 3.0 if spec['type'] == 'ball' else 10.0 / 3.0
        a1 = spec.get('a1', 1.0)
        load = np.array([math.hypot(f[name][0][0], f[name][0][1]) for f in forces])
        rate = (load / spec['C']) ** p
        damage = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * steps))
        revolutions = float(steps.sum())
        quiet_damage = (quiet[name] / spec['C']) ** p * revolutions
        assert record['bearing'] == {'C': spec['C'], 'type': spec['type'], 'p': p, 'X': 1.0,
                                     'Y': 0.0, 'e': None, 'a1': a1, 'limit_speed': None}
        assert record['revolutions'] == pytest.approx(revolutions, rel=1e-9)
        got = record['layout']
        assert got['life_used'] == pytest.approx(damage / 1e6 / a1, rel=1e-9)
        assert got['equivalent_load_N'] == pytest.approx(
            spec['C'] * (damage / revolutions) ** (1 / p), rel=1e-9)
        assert got['l10_hours'] == pytest.approx(
            seconds[-1] / 3600.0 / (damage / 1e6 / a1), rel=1e-9)
        assert got['unbalance_share'] == pytest.approx(damage / quiet_damage - 1.0, rel=1e-8)
        assert got['unbalance_share'] > 0.01       # the lump's 7 kg m is felt
        assert record['measured'] is None           # no load cells in the bag


def test_text_says_each_bearing_and_what_the_unbalance_costs(pinocchio_run, capsys):
    assert main(['life', str(pinocchio_run['bag'])]) == 0
    text = capsys.readouterr().out
    assert main(['life', str(pinocchio_run['bag']), '--json']) == 0
    record = json.loads(capsys.readouterr().out)['segments'][0]['supports']
    lines = text.splitlines()
    assert lines[0].startswith(f"bag {pinocchio_run['bag']}: bearing life per layout segment")
    assert lines[1].startswith("layout 'life_gantry' (")
    front, rear = record
    layout = front['layout']
    hours = layout['l10_hours'] * layout['life_used']
    assert lines[2] == (f"  bearing front (ball, C 40000 N): {front['revolutions']:.1f} "
                        f'revolutions in {hours:.4g} h')
    assert lines[3] == (f"    layout:   P_m {layout['equivalent_load_N']:.6g} N, life used "
                        f"{layout['life_used']:.4g}, L10 {layout['l10_hours']:.4g} h at this "
                        f"duty; this unbalance uses {100 * layout['unbalance_share']:.3g} % "
                        'more of its life than the rotor balanced')
    assert lines[5].startswith(f"    layout:   P_m {rear['layout']['equivalent_load_N']:.6g} N")
    assert ', L (a1 0.62) ' in lines[5]             # not L10: the rear asks 95 % reliability


def test_without_bearing_data_one_line_and_no_numbers(tmp_path, capsys):
    stamps, angle, omega = ramp(1.0, 2.0, rate=100.0, seconds=2.0)
    bag = write_input_bag(tmp_path / 'plain.mcap', stamps, angle, omega,
                          [(int(stamps[0]) - 1, yaml.safe_dump(GANTRY))])
    assert main(['life', str(bag), '--json']) == 1
    out, err = capsys.readouterr()
    assert out == ''
    digest = load_layout('config/ct_gantry.yaml').digest()
    assert err == (f'cvc-balance: error: {bag}: no bearing data: give each support a field '
                   'bearing (supports[].bearing: C, the basic dynamic load rating in N, and '
                   'type ball or roller; optional X, Y, e, a1, limit_speed), in the bag\'s '
                   f"layout or with --layout-file; its layouts: 'ct_gantry_demo' ({digest})\n")


@pytest.mark.parametrize('bearing, said', [
    ({'C': 0.0}, 'field bearing.C must be from 1 to 1e+09 N (a newton or more: the loads are '
     "divided by it, and the largest slewing bearings' C is below 10^8 N), got 0 N"),
    ({'C': 1e5, 'X': -0.5}, "field bearing.X must be from 0 to 10 (ISO 281's factors are "
     "below 3, a thrust bearing's up to 10), got -0.5"),
    ({'C': 1e5, 'type': 'needle'}, "field bearing.type: unknown bearing type 'needle', "
     'expected one of ball, roller (life exponent 3 or 10/3)'),
    ({'C': 1e5, 'a1': 1.5}, 'field bearing.a1 must be from 0.05 to 1 (ISO 281 a1: 1 at 90 % '
     'reliability (L10), 0.05 beyond 99.95 %), got 1.5'),
    ({'C': 1e5, 'X': 0.0}, 'field bearing: X and Y are both 0: the equivalent load would be 0 '
     '(radial only: X 1, Y 0)'),
    ({'C': 1e5, 'e': -1}, "field bearing.e must be from 0.01 to 10 (the Fa / Fr at which ISO "
     "281's factors switch), got -1"),
    ({'C': 1e5, 'limit_speed': 0}, "field bearing.limit_speed must be from 0.1 to 100000 rad/s "
     "(a maker's limiting speed: 1 rpm to 955 000 rpm), got 0 rad/s"),
    ({'type': 'ball'}, 'field bearing: missing field C'),
    ({'C': 1e5, 'c': 3}, "field bearing: unknown field 'c' (known: C, type, X, Y, e, a1, "
     'limit_speed)'),
])
def test_a_bad_bearing_is_one_line_in_yaml_and_json(bearing, said):
    layout = copy.deepcopy(GANTRY)
    layout['supports'][0]['bearing'] = bearing
    for text in (yaml.safe_dump(layout), json.dumps(layout)):     # both readers
        with pytest.raises(LayoutError) as error:
            layout_from_text(text)
        assert str(error.value) == f"layout: support 'front': {said}"


def test_bearings_read_alike_from_yaml_and_json_and_old_digests_stay():
    # The digest every bundled bag and picture knows for the gantry without bearings.
    assert load_layout('config/ct_gantry.yaml').digest() == 'd3882a62afc9'
    with_bearings = load_layout('config/ct_gantry_bearings.yaml')
    from_json = layout_from_text(json.dumps(BEARINGS))
    assert from_json == with_bearings and from_json.digest() == with_bearings.digest()
    front, rear = with_bearings.supports
    assert front.bearing == Bearing(180_000.0, 'ball', limit_speed=60.0)
    assert rear.bearing == Bearing(180_000.0, 'ball', 0.35, 0.57, 1.14, 1.0, 60.0)
    plain = copy.deepcopy(BEARINGS)
    for support in plain['supports']:
        del support['bearing']
    assert layout_from_text(yaml.safe_dump(plain)).digest() != with_bearings.digest()


def test_load_cells_measure_the_true_rotors_life(tmp_path, capsys):
    # The real rotor's rear counterweight sits 8.3 deg from where its layout says; the cells
    # (their zeros off by up to 340 N) read the real rotor. Measured, the bearings' life is
    # the true layout's; the declared layout's misses what the moved counterweight costs.
    declared = copy.deepcopy(BEARINGS)
    true = copy.deepcopy(BEARINGS)
    moved = next(c for c in true['components'] if c['name'] == 'counterweight_rear')
    moved['angle_deg'] = 262.0
    (tmp_path / 'declared.yaml').write_text(yaml.safe_dump(declared))
    (tmp_path / 'true.yaml').write_text(yaml.safe_dump(true))
    (tmp_path / 'run.yaml').write_text(yaml.safe_dump({
        'name': 'cells', 'layout': 'declared.yaml', 'joint_name': 'gantry_joint', 'rate': 500,
        'seed': 3, 'noise': {'angle': 0.0, 'speed': 0.0},
        'profile': [{'type': 'spin_up', 'to': 23.27, 'alpha': 6.0},
                    {'type': 'steady', 'duration': 6.0}],
        'hidden': [{'at': 0.0, 'set': {'component': 'counterweight_rear', 'angle_deg': 262.0}}],
        'load_cells': {'rate': 500, 'noise': 0.0,
                       'bias': {'front': [120.0, -340.0, 5.0], 'rear': [-80.0, 55.0, -3.0]}}}))
    bag = str(tmp_path / 'run.mcap')
    assert main(['simulate', str(tmp_path / 'run.yaml'), '-o', bag]) == 0
    capsys.readouterr()
    lives = {}
    true_file = ['--layout-file', str(tmp_path / 'true.yaml')]
    for name, extra in (('declared', []), ('true', true_file)):
        assert main(['life', bag, '--json', *extra]) == 0
        lives[name] = {s['name']: s for s in
                       json.loads(capsys.readouterr().out)['segments'][0]['supports']}
    for support in ('front', 'rear'):
        measured = lives['declared'][support]['measured']
        truth = lives['true'][support]['layout']
        # Over the cells' readings (the samples' span less a reading): P_m and the rate.
        assert measured['equivalent_load_N'] == pytest.approx(truth['equivalent_load_N'],
                                                              rel=1e-4)
        assert measured['l10_hours'] == pytest.approx(truth['l10_hours'], rel=1e-4)
        assert measured['unbalance_share'] == pytest.approx(truth['unbalance_share'],
                                                            rel=1e-3, abs=1e-5)
    declared_rear = lives['declared']['rear']['layout']
    assert declared_rear['unbalance_share'] < 1e-3 < 0.3 < \
        lives['declared']['rear']['measured']['unbalance_share']


def node_life(probe):
    """Return the last 'bearing life' status the node sent and its values (None: none)."""
    for array in reversed(probe.received['/diagnostics']):
        for status in array.status:
            if status.name.endswith(': bearing life'):
                return status, {kv.key: kv.value for kv in status.values}
    return None, {}


def run_node(tmp_path, probe, record, first_k, count, omega=10.0):
    """Start the node recording to ``record``, send ``count`` samples from the k-th; stop it."""
    import signal
    from sensor_msgs.msg import JointState
    from ros_harness import NodeProcess
    layout = bearings_layout()
    layout['supports'][0]['bearing']['limit_speed'] = 5.0
    (tmp_path / 'layout.yaml').write_text(yaml.safe_dump(layout))
    (tmp_path / 'params.yaml').write_text(yaml.safe_dump({'balance_monitor': {
        'ros__parameters': {'joint_name': 'spin', 'diagnostics_period': 0.2,
                            'layout_file': str(tmp_path / 'layout.yaml'),
                            'record_path': str(tmp_path / record),
                            'machine_id': 'gantry7/B:1'}}}))
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['--params-file', str(tmp_path / 'params.yaml')], tmp_path / 'node.log')
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    assert probe.spin_until(lambda: probe.node.count_subscribers('joint_states') >= 1,
                            timeout=20.0), node.log()
    probe.spin_for(1.5)
    step = 0.005
    for k in range(first_k, first_k + count):
        msg = JointState(name=['spin'], position=[math.remainder(omega * k * step, 2 * math.pi)],
                         velocity=[omega])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(10**10 + k * 5_000_000,
                                                                10**9)
        joints.publish(msg)
        probe.spin_for(0.002)
    probe.received['/diagnostics'].clear()
    assert probe.spin_until(lambda: node_life(probe)[1].get('front revolutions since start')
                            and float(node_life(probe)[1]['front revolutions since start'])
                            >= 0.999 * omega * (count - 1) * step / (2 * math.pi),
                            timeout=10.0), node.log()
    status, values = node_life(probe)
    assert node.stop(signal.SIGINT) == 0
    return status, values, node


@pytest.fixture
def diagnostics_probe():
    from diagnostic_msgs.msg import DiagnosticArray
    from ros_harness import Probe
    probe = Probe()
    probe.record(DiagnosticArray, '/diagnostics')
    yield probe
    probe.close()


def test_node_counts_life_live_and_across_restarts(tmp_path, diagnostics_probe):
    # Pinocchio's loads at each sample's angle (constant speed, alpha 0), the trapezoid over
    # the angle turned by hand: the life used since start; a second run (a new recording in
    # the same folder) goes on from the state file the first left.
    from diagnostic_msgs.msg import DiagnosticStatus
    omega, step = 10.0, 0.005
    rotor = PinocchioRotor(bearings_layout())
    layout = bearings_layout()

    def expected(first_k, count):
        angles = omega * step * np.arange(first_k, first_k + count)
        turns = omega * step / (2 * math.pi) * (count - 1)
        out = {}
        for support in layout['supports']:
            name, spec = support['name'], support['bearing']
            p = 3.0 if spec['type'] == 'ball' else 10.0 / 3.0
            load = np.array([math.hypot(*rotor.loads(q, omega, 0.0)['supports'][name][0][:2])
                             for q in angles])
            rate = (load / spec['C']) ** p
            damage = float(np.sum(0.5 * (rate[1:] + rate[:-1]))) * omega * step / (2 * math.pi)
            out[name] = (damage / 1e6 / spec.get('a1', 1.0), turns)
        return out

    status, values, node = run_node(tmp_path, diagnostics_probe, 'run1.mcap', 0, 300)
    first = expected(0, 300)
    hours = 299 * step / 3600.0
    for name, (used, turns) in first.items():
        assert float(values[f'{name} revolutions since start']) == pytest.approx(turns,
                                                                                 rel=1e-5)
        assert float(values[f'{name} life used since start']) == pytest.approx(used, rel=1e-5)
        assert float(values[f'{name} life used in all']) == pytest.approx(used, rel=1e-5)
        assert float(values[f'{name} life used per hour of running']) == pytest.approx(
            used / hours, rel=1e-5)
        assert float(values[f'{name} life left at this duty [h]']) == pytest.approx(
            (1.0 - used) * hours / used, rel=1e-5)
    state = tmp_path / 'bearing_life_gantry7_B_1.json'
    assert values['state file'] == str(state)
    assert status.level == DiagnosticStatus.WARN        # front's limiting speed is 5 rad/s
    front = float(values['front life used since start'])
    rate = float(values['front life used per hour of running'])
    assert status.message.startswith(
        'bearing life: front: speed 10 rad/s over its limiting speed 5 rad/s; front '
        f'{front:.3g} used since start ({rate:.3g}/h: rating life {1 / rate:.4g} h at this '
        f'duty), {front:.3g} in all; rear ')
    saved = json.loads(state.read_text())
    assert saved['kind'] == 'cvc_balance bearing life'
    assert saved['supports']['front']['life_used'] == pytest.approx(first['front'][0],
                                                                    rel=1e-5)

    status, values, node = run_node(tmp_path, diagnostics_probe, 'run2.mcap', 1000, 200)
    second = expected(1000, 200)
    for name in first:
        assert float(values[f'{name} life used since start']) == pytest.approx(
            second[name][0], rel=1e-5)
        assert float(values[f'{name} life used in all']) == pytest.approx(
            first[name][0] + second[name][0], rel=1e-5)


def test_an_unreadable_state_file_is_kept_and_said(tmp_path):
    from cvc_balance.ros.bearing_life import BearingLife, state_path
    path = state_path(tmp_path / 'run.mcap', 'gantry7')
    path.write_text('{"kind": "cvc_balance bearing life", "supports": {"front": {"bearing": '
                    '{}, "revolutions": -3}}}')
    said = []
    life = BearingLife(path, lambda severity, text: said.append((severity, text)))
    supports = load_layout('config/ct_gantry_bearings.yaml').supports
    life.layout(supports)
    life.save()
    assert path.read_text().startswith('{"kind": "cvc_balance bearing life", "supports"')
    problem = (f"state file unreadable, not written over (counted from 0 since start): "
               f"{path}: support 'front': give bearing and revolutions, damage, seconds "
               '(finite, >= 0)')
    assert said == [('error', f'bearing life: {problem}')]
    level, message, values = life.status(0.0)
    assert values['state file'] == problem
    assert message == 'bearing life: front 0 used since start, 0 in all; rear 0 used since ' \
        'start, 0 in all'


def test_rerun_view_plots_each_bearings_life_used(pinocchio_run, tmp_path, capsys):
    from test_rerun_view import read_rrd
    rrd = tmp_path / 'run.rrd'
    assert main(['view', str(pinocchio_run['bag']), '-o', str(rrd)]) == 0
    capsys.readouterr()
    assert main(['life', str(pinocchio_run['bag']), '--json']) == 0
    record = json.loads(capsys.readouterr().out)['segments'][0]['supports']
    scalars, _, paths = read_rrd(rrd)
    assert {'/plots/life/front', '/plots/life/rear'} <= paths
    for support in record:
        times, used = scalars[f"/plots/life/{support['name']}"]
        assert len(times) == len(pinocchio_run['stamps'])
        assert np.all(np.diff(used) >= 0.0) and used[0] == 0.0
        assert used[-1] == pytest.approx(support['layout']['life_used'], rel=1e-12)


def test_fleet_sums_each_machines_bearing_life_and_ranks_by_hours_left(tmp_path, capsys):
    # A simulated fleet (load cells: measured where the cells can tell) analysed into the
    # table; per machine and bearing the life used is the sum of what `life` says of each
    # run (of record), the duty that of the latest layout's runs, the hours left by hand.
    from datetime import datetime
    fleet = tmp_path / 'fleet'
    assert main(['simulate-fleet', 'config/ct_gantry_bearings.yaml', '-o', str(fleet),
                 '--machines', '2', '--runs', '3', '--days', '20', '--rate', '50',
                 '--cell-rate', '50']) == 0
    results = tmp_path / 'fleet.parquet'
    assert main(['fleet', str(fleet), '--out', str(results), '--engine', 'local']) == 0
    capsys.readouterr()
    expected = {}
    for bag in sorted(fleet.glob('*/*')):
        if bag.suffix == '.yaml':
            continue
        assert main(['replay', str(bag), '--json']) == 0
        record = json.loads(capsys.readouterr().out)
        for segment in record['segments']:
            hours = (segment['last_sample'] - segment['first_sample']) / 3600.0
            source = 'measured' if segment['verdict']['source'] == 'measured' else 'layout'
            for support in segment['life']:
                use = support[source] or support['layout']
                runs = expected.setdefault((record['machine_id'], support['name']), [])
                runs.append((datetime.fromisoformat(segment['start_utc'].replace('Z', '')),
                             segment['layout']['digest'], use['life_used'], hours))
    assert main(['trends', str(results), '--rank', 'life', '--json']) == 0
    machines = json.loads(capsys.readouterr().out)['machines']
    left = []
    for machine in machines:
        worst = None
        for bearing in machine['bearings']:
            runs = sorted(expected[(machine['machine_id'], bearing['support'])])
            latest = [r for r in runs if r[1] == runs[-1][1]]
            used = sum(r[2] for r in runs)
            duty = sum(r[2] for r in latest) / sum(r[3] for r in latest)
            assert bearing['runs'] == len(runs)
            assert bearing['life_used'] == pytest.approx(used, rel=1e-12)
            assert bearing['running_hours'] == pytest.approx(sum(r[3] for r in runs),
                                                             rel=1e-9)
            assert bearing['life_per_running_hour'] == pytest.approx(duty, rel=1e-9)
            assert bearing['hours_left'] == pytest.approx((1 - used) / duty, rel=1e-9)
            worst = min(worst or math.inf, bearing['hours_left'])
        left.append(worst)
    assert len(machines) == 2 and left == sorted(left)
    assert [m['rank'] for m in machines] == [1, 2]
    assert main(['trends', str(results), '--rank', 'life']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ['rank', 'machine', 'bearing', 'life', 'used', 'per', 'running',
                                'hour', 'hours', 'left', 'rating', 'life', 'reached', 'runs',
                                'last', 'run']
    first = machines[0]
    worst = min(first['bearings'], key=lambda b: b['hours_left'])
    assert lines[1].split()[:6] == ['1', first['machine_id'], worst['support'],
                                    f"{worst['life_used']:.3g}",
                                    f"{worst['life_per_running_hour']:.3g}",
                                    f"{worst['hours_left']:.4g}"]


def pinocchio_life_hours(layout, omega, points=360):
    """Each bearing's rating life (h) at ``omega`` from Pinocchio's loads over a turn."""
    rotor = PinocchioRotor(layout)
    angles = np.arange(points) * 2 * math.pi / points
    forces = [rotor.loads(q, omega, 0.0)['supports'] for q in angles]
    hours = {}
    for support in layout['supports']:
        spec = support['bearing']
        p = 3.0 if spec.get('type', 'ball') == 'ball' else 10.0 / 3.0
        radial = np.array([math.hypot(*f[support['name']][0][:2]) for f in forces])
        axial = np.array([abs(f[support['name']][0][2]) for f in forces])
        load = radial
        if 'e' in spec:
            load = np.where(axial > spec['e'] * radial,
                            spec['X'] * radial + spec['Y'] * axial, radial)
        rate = np.mean((load / spec['C']) ** p)
        hours[support['name']] = spec.get('a1', 1.0) * 1e6 / (rate * omega * 3600 / (2 * math.pi))
    return hours


def test_sensitivity_gives_each_bearings_life_and_slopes_against_pinocchio(tmp_path, capsys):
    # The gantry tilted 15 deg (the rear row takes thrust beyond e): the rating life at the
    # service speed and its derivative by the counterweights' parameters, against central
    # differences of Pinocchio's loads over a turn.
    layout = copy.deepcopy(BEARINGS)
    tilt = math.radians(15.0)
    layout['gravity'] = [0.0, -9.80665 * math.cos(tilt), 9.80665 * math.sin(tilt)]
    layout['supports'][1]['bearing'].update(X=0.35, Y=0.57, e=0.1)
    target = tmp_path / 'tilted.yaml'
    target.write_text(yaml.safe_dump(layout))
    assert main(['sensitivity', str(target), '--json']) == 0
    found = json.loads(capsys.readouterr().out)
    assert main(['sensitivity', str(target)]) == 0
    text = capsys.readouterr().out
    omega = layout['balancing']['service_speed']
    nominal = pinocchio_life_hours(layout, omega)
    assert found['bearings']['omega'] == omega
    for name, hours in found['bearings']['l10_hours'].items():
        assert hours == pytest.approx(nominal[name], rel=1e-9)
    rows = {(r['component'], r['parameter']): r for r in found['parameters']}
    for component in ('counterweight_rear', 'counterweight_front'):
        index = next(k for k, c in enumerate(layout['components']) if c['name'] == component)
        for parameter, step in (('mass', 1e-3), ('radius', 1e-5), ('angle_deg', 1e-3),
                                ('z', 1e-5)):
            moved = []
            for sign in (1, -1):
                changed = copy.deepcopy(layout)
                changed['components'][index][parameter] += sign * step
                moved.append(pinocchio_life_hours(changed, omega))
            unit = math.radians(1.0) if parameter == 'angle_deg' else 1.0
            row = rows[(component, parameter.replace('_deg', ''))]
            for name in nominal:
                slope = (moved[0][name] - moved[1][name]) / (2 * step * unit)
                assert row['d_l10_hours'][name] == pytest.approx(slope, rel=1e-5, abs=1e-6 *
                                                                 nominal[name])
    hours = found['bearings']['l10_hours']
    assert (f"bearing rating life at {omega:.4g} rad/s (ISO 281, the layout as designed): "
            f"front {hours['front']:.4g} h, rear {hours['rear']:.4g} h") in text.splitlines()


def test_tolerance_gives_each_bearings_life_spread(capsys):
    assert main(['sensitivity', 'config/ct_gantry_bearings.yaml', '--tolerances',
                 'config/ct_gantry_tolerances.yaml', '--json']) == 0
    slopes = json.loads(capsys.readouterr().out)
    assert main(['tolerance', 'config/ct_gantry_bearings.yaml', '--tolerances',
                 'config/ct_gantry_tolerances.yaml', '--samples', '2000', '--json']) == 0
    stack = json.loads(capsys.readouterr().out)
    assert [b['support'] for b in stack['bearings']] == ['front', 'rear']
    for bearing in stack['bearings']:
        name = bearing['support']
        assert bearing['l10_hours'] == slopes['bearings']['l10_hours'][name]
        # The linear worst case: each parameter's slope times its tolerance, summed.
        assert bearing['worst_case_linear_hours'] == pytest.approx(
            sum(r['moves_l10_hours'][name] for r in slopes['parameters']), rel=1e-12)
        assert sum(c['share'] for c in bearing['contributions']) <= 1.0 + 1e-12
    assert main(['tolerance', 'config/ct_gantry_bearings.yaml', '--tolerances',
                 'config/ct_gantry_tolerances.yaml', '--samples', '2000']) == 0
    lines = capsys.readouterr().out.splitlines()
    front = stack['bearings'][0]
    most = front['contributions'][0]
    assert (f"bearing front: rating life {front['l10_hours']:.4g} h at 23.27 rad/s, +- "
            f"{front['rss_sigma_hours']:.3g} h (RSS sigma), worst case +- "
            f"{front['worst_case_linear_hours']:.3g} h; most from {most['component']}."
            f"{most['parameter']} ({most['share'] * 100:.0f} %)") in lines
