"""
Mistakes in wiring sensors to the monitor, each caught with its named cause; none invented.

Issue 23, point 4, live: a JointState position in degrees or a velocity in rpm used to be
accepted without a word, and so were load cells with a reversed sign, a wrong scale, kN
for N or on the wrong support. The checks (cvc_balance/identify/mistakes.py) are fed
streams made here: motions by hand, cell readings by Pinocchio's RNEA split over the
supports by statics (test/independent.py), not by the project's engine; the fit of the
cells' static loads is the project's batch fit. A catalogue of mistakes, each named; 200
correct motion streams and 200 correct cell setups drawn at random (seeded), no alarm.
"""

import math
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
import yaml

from cvc_balance.identify.batch import CellReadings, fit, Motion
from cvc_balance.identify.mistakes import cell_mistakes, motion_units, static_loads
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout_file import layout_from_text
from independent import PinocchioRotor, tilted

G = 9.80665


def model_of(layout):
    return RotorModel.from_layout(layout_from_text(yaml.safe_dump(layout)))


# -- the layout's weight share of each support ------------------------------------------

def test_static_shares_are_the_lever_rule_by_hand():
    """
    The weight shares of a layout by the lever rule.

    Two masses, 30 kg at z 0.1 m and 10 kg at z -0.3 m (off the axis, any angle):
    centre of mass at z 0; supports at -0.2 and 0.5 m carry 0.5/0.7 and 0.2/0.7 of
    40 kg x 9.80665 m/s^2, downwards (-y); one support carries it all.
    """
    layout = {'name': 'lever', 'gravity': [0.0, -G, 0.0],
              'components': [{'name': 'a', 'mass': 30.0, 'radius': 0.4, 'angle_deg': 10.0,
                              'z': 0.1},
                             {'name': 'b', 'mass': 10.0, 'radius': 0.2, 'angle_deg': 250.0,
                              'z': -0.3}],
              'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.5,
                                                          'axial': True}]}
    shares = static_loads(model_of(layout))
    weight = 40.0 * G
    assert shares['front'] == pytest.approx(-1j * weight * 0.5 / 0.7, abs=1e-9)
    assert shares['rear'] == pytest.approx(-1j * weight * 0.2 / 0.7, abs=1e-9)
    single = dict(layout, supports=[{'name': 'slewing', 'z': 0.0, 'axial': True}])
    assert static_loads(model_of(single)) == {'slewing': pytest.approx(-1j * weight,
                                                                       abs=1e-9)}


# -- position against velocity ----------------------------------------------------------

def joint_stream(rate=1000.0, seconds=2.0, omega0=8.0, alpha=6.0, noise=1e-3, seed=0):
    """Return a true motion by hand: stamps s, angle rad (unbounded), omega rad/s; noisy."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(rate * seconds)) / rate
    q = 0.3 + omega0 * t + 0.5 * alpha * t * t
    w = omega0 + alpha * t
    return t, q + rng.normal(0.0, noise, len(t)), w * (1 + rng.normal(0.0, 1e-3, len(t)))


def wrapped(q, period=2 * math.pi, start=-math.pi):
    return np.remainder(q - start, period) + start


MOTION_MISTAKES = {
    # name: (position as sent, velocity as sent, cause, message)
    'position in degrees, 0..360': (
        lambda q: np.degrees(wrapped(q, start=0.0)), lambda w: w, 'degrees',
        'joint position looks like degrees: its rate is 57.3 x the velocity, and it wraps '
        'at 360'),
    'position in degrees, -180..180': (
        lambda q: np.degrees(wrapped(q)), lambda w: w, 'degrees',
        'joint position looks like degrees: its rate is 57.3 x the velocity, and it wraps '
        'at 360'),
    'position in degrees, sense reversed': (
        lambda q: np.degrees(wrapped(q)), lambda w: -w, 'degrees',
        'joint position looks like degrees: its rate is 57.3 x the velocity, and it wraps '
        "at 360; and its sign is opposite to the velocity's"),
    'velocity in rpm': (
        wrapped, lambda w: w * 30.0 / math.pi, 'rpm',
        "joint velocity looks like rpm: it is 9.55 x the position's rate"),
    'velocity in degrees/s': (
        wrapped, np.degrees, 'deg/s',
        "joint velocity looks like degrees/s: it is 57.3 x the position's rate"),
    'degrees and rpm': (
        lambda q: np.degrees(wrapped(q, start=0.0)), lambda w: w * 30.0 / math.pi,
        'degrees and rpm', "joint position looks like degrees and velocity like rpm: the "
        "position's rate is 6.00 x the velocity, and it wraps at 360"),
    'both in degrees (wraps at 360)': (
        lambda q: np.degrees(wrapped(q, start=0.0)), np.degrees, 'wraps at 360',
        'joint position wraps at 360 and its rate equals the velocity: both look like '
        'degrees (deg, deg/s), not rad and rad/s'),
    'velocity sense reversed': (
        wrapped, lambda w: -w, 'reversed',
        "joint velocity has the opposite sign of the position's rate: the senses disagree "
        '(ratio -1)'),
    'encoder counts (4096 a turn)': (
        lambda q: wrapped(q, start=0.0) * 4096 / (2 * math.pi), lambda w: w, 'ratio',
        "joint position's rate is 652 x the velocity (units, a gear ratio or another "
        'joint?), and it wraps at 4096'),
    'motor side of a 3:1 gear': (
        lambda q: wrapped(3.0 * q), lambda w: w, 'ratio',
        "joint position's rate is 3 x the velocity (units, a gear ratio or another joint?)"),
}


@pytest.mark.parametrize('name', MOTION_MISTAKES)
def test_each_motion_mistake_is_named(name):
    position, velocity, cause, message = MOTION_MISTAKES[name]
    t, q, w = joint_stream()
    check = motion_units(t, position(q), velocity(w))
    assert check is not None and check.finding is not None, name
    assert (check.finding.cause, check.finding.message) == (cause, message)


def test_motion_that_cannot_tell_says_nothing():
    """Standing still, under 1 rad turned, or samples too sparse for the speed: None."""
    t, q, w = joint_stream()
    assert motion_units(t, q * 0.0, w * 0.0) is None
    assert motion_units(t[:100], q[:100], w[:100]) is None            # 0.85 rad turned
    sparse = np.arange(0.0, 2.0, 0.05)                             # 20 Hz at 30 rad/s
    assert motion_units(sparse, wrapped(30.0 * sparse), 30.0 + 0 * sparse) is None
    assert motion_units(t[:15], q[:15], w[:15]) is None


def test_200_correct_motion_streams_raise_no_alarm():
    """
    Correct joint streams drawn at random: no finding.

    Random rates (50-5000 Hz), speeds (0.2-300 rad/s, either sense, ramps, spin-ups from
    rest at 2-50 rad/s^2), encoder
    noise (0-3 mrad), speed noise (0-1 %), stamp jitter, pauses, and positions wrapped
    at +-pi, 0..2 pi or not at all: no finding; and most streams are judged (ratio 1).
    """
    rng = np.random.default_rng(23)
    judged = 0
    for k in range(200):
        rate = float(np.exp(rng.uniform(np.log(50.0), np.log(5000.0))))
        n = int(rng.integers(100, 3000))
        t = np.cumsum(rng.uniform(0.7, 1.3, n) / rate)
        if rng.random() < 0.3:                                      # a pause
            t[n // 2:] += rng.uniform(0.1, 5.0)
        omega0 = float(np.exp(rng.uniform(np.log(0.2), np.log(300.0)))) * rng.choice([-1, 1])
        alpha = rng.uniform(-1.0, 1.0) * abs(omega0) / max(t[-1], 1e-3) * 0.5
        if k % 4 == 3:                                              # a spin-up from rest
            omega0, alpha = 0.0, float(rng.uniform(2.0, 50.0) * rng.choice([-1, 1]))
        q = rng.uniform(-3, 3) + omega0 * t + 0.5 * alpha * t * t
        w = (omega0 + alpha * t) * (1 + rng.normal(0, rng.uniform(0, 0.01), n))
        q = q + rng.normal(0, rng.uniform(0, 3e-3), n)
        style = k % 3
        q = wrapped(q) if style == 0 else wrapped(q, start=0.0) if style == 1 else q
        check = motion_units(t, q, w)
        assert check is None or check.finding is None, (k, check)
        if check is not None:
            judged += 1
            assert check.ratio == pytest.approx(1.0, abs=0.05)
    assert judged >= 120, judged


# -- the cells' static loads against the weight shares ---------------------------------

ASYMMETRIC = {
    'name': 'asymmetric', 'gravity': tilted(8.0),
    'components': [
        {'name': 'drum', 'mass': 300.0, 'radius': 0.0, 'angle': 0.0, 'z': 0.0,
         'shape': {'type': 'tube', 'inner_radius': 0.6, 'outer_radius': 0.7, 'length': 0.4}},
        {'name': 'tube', 'mass': 40.0, 'radius': 0.55, 'angle_deg': 20.0, 'z': 0.08},
        {'name': 'lump', 'mass': 2.0, 'radius': 0.6, 'angle_deg': 200.0, 'z': -0.1}],
    'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.5, 'axial': True}]}


def cell_run(layout, rate=400.0, revolutions=6, omega=20.0, noise=20.0, zero=None, seed=1):
    """
    Motion (exact, steady) and each support's cell readings by Pinocchio and statics.

    ``zero``: {support: (x, y)} N of each cell's zero offset. Readings at ``rate`` per
    cell, from the first sample to the last of ``revolutions`` whole turns.
    """
    rng = np.random.default_rng(seed)
    rotor = PinocchioRotor(layout)
    seconds = revolutions * 2 * math.pi / omega
    t = np.arange(0.0, seconds, 1e-3)
    motion = Motion(t, wrapped(omega * t), omega + 0 * t, 0 * t)
    cells = {}
    for k, support in enumerate(layout['supports']):
        times = np.arange((k + 1) / (3 * rate), t[-1], 1.0 / rate)
        force = np.array([rotor.loads(omega * s, omega, 0.0)['supports'][support['name']][0]
                          for s in times])
        force[:, :2] += (zero or {}).get(support['name'], (0.0, 0.0))
        force += rng.normal(0.0, noise, force.shape)
        cells[support['name']] = CellReadings(support['name'], times, force,
                                              np.zeros_like(force))
    return motion, cells


def static_of(layout, motion, cells):
    """Return the cells' static loads as the fit finds them (its biases): {name: complex}."""
    estimate, _ = fit(model_of(layout), motion, cells)
    assert estimate.identifiable
    return {s['name']: estimate.biases[k] for k, s in enumerate(layout['supports'])}


def mistaken(cells, name, change):
    """Return ``cells`` with the readings of ``name`` changed: force -> change(force)."""
    out = dict(cells)
    cell = cells[name]
    out[name] = CellReadings(name, cell.time, change(cell.force.copy()), cell.torque)
    return out


def turn_90(force):
    force[:, :2] = np.stack([-force[:, 1], force[:, 0]], axis=1)
    return force


CELL_MISTAKES = {
    # name: (cells -> cells, cause, message: {front}, {rear} the static loads read, N;
    # {front_share}, {rear_share} the supports' shares by hand, N)
    'front sign reversed': (
        lambda c: mistaken(c, 'front', lambda f: -f), 'sign',
        "cell front reads its support's static load with the sign reversed ({front:.4g} N "
        'where its support carries {front_share:.4g} N)'),
    'rear at half scale': (
        lambda c: mistaken(c, 'rear', lambda f: 0.5 * f), 'scale',
        "cell rear's scale looks off: it reads {rear_ratio:.3g} x its support's static load "
        '({rear:.4g} N where its support carries {rear_share:.4g} N)'),
    'front in kN': (
        lambda c: mistaken(c, 'front', lambda f: f / 1000.0), 'kN',
        "cell front reads 1/1000 of its support's static load: kN for N? ({front:.4g} N "
        'where its support carries {front_share:.4g} N)'),
    'rear in kgf': (
        lambda c: mistaken(c, 'rear', lambda f: f / G), 'kgf',
        "cell rear reads 1/9.81 of its support's static load: kgf for N? ({rear:.4g} N "
        'where its support carries {rear_share:.4g} N)'),
    'front axes turned 90 deg': (
        lambda c: mistaken(c, 'front', turn_90), 'axes',
        "cell front's axes look turned by {front_turn:.0f} deg: its static load points "
        "elsewhere than its support's ({front:.4g} N where its support carries "
        '{front_share:.4g} N)'),
    'front and rear swapped': (
        lambda c: {'front': c['rear'], 'rear': c['front']}, 'swapped',
        "cells front and rear look swapped: front reads the rear support's static load "
        "({front:.0f} N where front carries {front_share:.0f} N) and rear reads front's"),
    'both topics carry the front cell': (
        lambda c: {'front': c['front'], 'rear': c['front']}, 'wrong support',
        "cell rear reads the front support's static load ({rear:.0f} N where rear carries "
        '{rear_share:.0f} N): on the wrong support?'),
}


@pytest.fixture(scope='module')
def asymmetric_run():
    zero = {'front': (120.0, -340.0), 'rear': (-80.0, 55.0)}     # the bundled bags' zeros
    return cell_run(ASYMMETRIC, zero=zero)


def shares_by_hand():
    """Return the lever rule's shares: 342 kg, centre of mass at z 0.00877 m, tilt 8 deg."""
    mass = 342.0
    z_c = (40.0 * 0.08 - 2.0 * 0.1) / mass
    radial = mass * G * math.cos(math.radians(8.0))
    return {'front': radial * (0.5 - z_c) / 0.7, 'rear': radial * (z_c + 0.2) / 0.7}


def test_correct_cells_match_their_shares(asymmetric_run):
    motion, cells = asymmetric_run
    expected = static_loads(model_of(ASYMMETRIC))
    by_hand = shares_by_hand()
    for name in ('front', 'rear'):
        assert abs(expected[name]) == pytest.approx(by_hand[name], rel=1e-12)
    assert cell_mistakes(expected, static_of(ASYMMETRIC, motion, cells)) == []


@pytest.mark.parametrize('name', CELL_MISTAKES)
def test_each_cell_mistake_is_named(name, asymmetric_run):
    motion, cells = asymmetric_run
    change, cause, message = CELL_MISTAKES[name]
    expected = static_loads(model_of(ASYMMETRIC))
    measured = static_of(ASYMMETRIC, motion, change(cells))
    found = cell_mistakes(expected, measured)
    figures = {name: abs(value) for name, value in measured.items()}
    figures.update({f'{name}_share': value for name, value in shares_by_hand().items()})
    figures.update({f'{name}_ratio': abs(measured[name] / expected[name])
                    for name in measured})
    figures.update({f'{name}_turn': math.degrees(np.angle(measured[name] / expected[name]))
                    for name in measured})
    assert [(f.cause, f.message) for f in found] == [(cause, message.format(**figures))]
    if cause == 'axes':
        assert figures['front_turn'] == pytest.approx(90.0, abs=10.0)
    if cause in ('scale', 'kN', 'kgf'):
        scale = {'scale': 0.5, 'kN': 1e-3, 'kgf': 1 / G}[cause]
        assert max(figures['front_ratio'], figures['rear_ratio']) / scale == \
            pytest.approx(1.0, abs=0.15) or min(figures['front_ratio'],
                                                figures['rear_ratio']) / scale == \
            pytest.approx(1.0, abs=0.15)


def test_200_correct_cell_setups_raise_no_alarm():
    """
    Correct cell setups drawn at random: no finding.

    Random layouts (2-5 components, 5-400 kg, radii to 0.7 m, z within the supports),
    supports (one or two, spans 0.15-1 m), tilts (0-30 deg), speeds (3-30 rad/s), zero
    offsets up to 4 % of the weight, noise 0-2 % of it: the fitted static loads match
    the layout's shares, no finding; most setups judged (a share of 20 % of the weight).
    """
    rng = np.random.default_rng(24)
    judged = 0
    for k in range(200):
        a, b = sorted(rng.uniform(-0.6, 0.6, 2))
        b = max(b, a + 0.15)
        supports = [{'name': 'front', 'z': float(a)}, {'name': 'rear', 'z': float(b),
                                                       'axial': True}]
        if k % 10 == 0:
            supports = [{'name': 'slewing', 'z': float(a), 'axial': True}]
        components = [{'name': f'c{i}', 'mass': float(rng.uniform(5, 400)),
                       'radius': float(rng.uniform(0, 0.7)),
                       'angle': float(rng.uniform(0, 2 * math.pi)),
                       'z': float(rng.uniform(a, b))} for i in range(rng.integers(2, 6))]
        layout = {'name': f'random_{k}', 'gravity': tilted(float(rng.uniform(0, 30))),
                  'components': components, 'supports': supports}
        weight = sum(c['mass'] for c in components) * G
        zero = {s['name']: tuple(rng.uniform(-0.028, 0.028, 2) * weight) for s in supports}
        motion, cells = cell_run(layout, rate=120.0, revolutions=3,
                                 omega=float(rng.uniform(3, 30)),
                                 noise=float(rng.uniform(0, 0.02)) * weight, zero=zero, seed=k)
        expected = static_loads(model_of(layout))
        found = cell_mistakes(expected, static_of(layout, motion, cells))
        assert found == [], (k, found)
        judged += sum(abs(v) >= 0.2 * abs(sum(expected.values())) for v in expected.values())
    assert judged >= 250, judged


# -- live: the node names the mistake in /diagnostics and its log, once --------------------

def input_status(probe):
    """Return the node's last 'input checks' status: (level, message, values) or None."""
    for array in reversed(probe.received['/diagnostics']):
        for status in array.status:
            if status.name.endswith('input checks'):
                return status.level, status.message, {kv.key: kv.value for kv in status.values}
    return None


def stream_live(probe, seconds, joints=None, cells=None, rate=500.0):
    """
    Publish for ``seconds`` at ``rate``, stamped on the wall clock's line.

    ``joints(t)`` gives a JointState, ``cells(t)`` [(publisher, WrenchStamped)]; t s from
    the start, each stamped at the start's wall time plus t.
    """
    import time
    start, k, wall = time.monotonic(), 0, time.time_ns()
    while time.monotonic() - start < seconds:
        t = k / rate
        stamp = wall + round(t * 1e9)         # the time the position and readings are of
        for publisher, msg in ([(probe.joints, joints(t))] if joints else []) + \
                (cells(t) if cells else []):
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            publisher.publish(msg)
        k += 1
        probe.spin_for(max(0.0, start + k / rate - time.monotonic()))


def joint_msg(position, velocity):
    from sensor_msgs.msg import JointState
    return JointState(name=['spin'], position=[position], velocity=[velocity])


def live_node(tmp_path, layout):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from ros_harness import Probe
    from test_balance_monitor import start_node, wait_until_connected
    node = start_node(tmp_path, layout)
    probe = Probe('mistakes_probe')
    probe.record(DiagnosticArray, '/diagnostics')
    probe.joints = probe.publisher(JointState, 'joint_states', sensor=True)
    return node, probe, wait_until_connected


def test_live_position_in_degrees_is_named_once(tmp_path):
    """A JointState position in degrees (velocity in rad/s), 1.2 s at 500 Hz."""
    import signal
    node, probe, wait_until_connected = live_node(tmp_path, ASYMMETRIC)
    message = ('joint position looks like degrees: its rate is 57.3 x the velocity, and it '
               'wraps at 360')
    try:
        wait_until_connected(probe, node, 'joint_states')
        stream_live(probe, 1.2, joints=lambda t: joint_msg(
            math.degrees(wrapped(20.0 * t, start=0.0)), 20.0))
        assert probe.spin_until(lambda: (input_status(probe) or (0,))[0] ==
                                DiagnosticStatus.WARN, 5.0), \
            (input_status(probe), node.log()[-2000:])
        level, said, values = input_status(probe)
        assert said == message
        assert float(values['joint position rate / velocity']) == pytest.approx(57.2958,
                                                                                rel=1e-3)
        assert values['joint position wraps at'] == '360'
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
    assert node.log().count(f'input mistake? {message}') == 1, node.log()


def test_live_swapped_cells_are_named(tmp_path):
    """
    Two cells on each other's topics, named live.

    The two cells' topics swapped (readings by Pinocchio and statics), 2 s: the node's fit
    finds each cell's static load at the other support's share and names the swap.
    """
    import signal
    from geometry_msgs.msg import WrenchStamped
    rotor = PinocchioRotor(ASYMMETRIC)
    node, probe, wait_until_connected = live_node(tmp_path, ASYMMETRIC)
    cell_pubs = {name: probe.publisher(WrenchStamped, f'supports/{name}/measured_load',
                                       sensor=True) for name in ('front', 'rear')}
    omega = 20.0

    def cells(t):
        out = []
        loads = rotor.loads(omega * t, omega, 0.0)['supports']
        for name, topic in (('front', 'rear'), ('rear', 'front')):      # swapped
            msg = WrenchStamped()
            (msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z) = \
                (float(v) for v in loads[name][0])
            out.append((cell_pubs[topic], msg))
        return out

    try:
        wait_until_connected(probe, node, 'joint_states', 'supports/front/measured_load',
                             'supports/rear/measured_load')
        stream_live(probe, 2.0, joints=lambda t: joint_msg(wrapped(omega * t), omega),
                    cells=cells)
        assert probe.spin_until(lambda: (input_status(probe) or (0,))[0] ==
                                DiagnosticStatus.WARN, 5.0), \
            (input_status(probe), node.log()[-2000:])
        level, said, values = input_status(probe)
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
    shares = shares_by_hand()
    assert said == (f"cells front and rear look swapped: front reads the rear support's "
                    f"static load ({float(values['cell front static load [N]']):.0f} N where "
                    f"front carries {shares['front']:.0f} N) and rear reads front's")
    assert float(values['cell front static load [N]']) == pytest.approx(shares['rear'],
                                                                        rel=0.02)
    assert float(values['cell rear static load [N]']) == pytest.approx(shares['front'],
                                                                       rel=0.02)
    assert f'input mistake? {said}' in node.log()


BAGS = Path(__file__).resolve().parents[1] / 'bags'


@pytest.mark.parametrize('name', ['field_baseline', 'field_trial_I', 'loose_bracket',
                                  'spin_up_tube_swap', 'tilted_shift'])
def test_the_bundled_bags_raise_no_alarm(name):
    """
    The simulator's bags, read offline as the node reads them live: no mistake.

    Their encoders in rad and rad/s with noise; their cells (where they have some) with
    zero offsets of up to 340 N on shares of 4.5 kN. Every window of 2000 motion samples
    (as the node's) that can tell says ratio 1; every layout segment's fitted static
    loads match the shares.
    """
    from cvc_balance.bag.identify_run import identify_bag
    from cvc_balance.bag.replay import read_inputs
    from cvc_balance.bag.rosbag2 import open_bag
    motion, _ = read_inputs(open_bag(BAGS / f'{name}.mcap'), 'gantry_joint')
    told = 0
    for start in range(0, len(motion.stamp) - 100, 1000):
        window = slice(start, start + 2000)
        check = motion_units(motion.stamp[window] * 1e-9, motion.angle[window],
                             motion.omega[window])
        if check is not None:
            told += 1
            assert check.finding is None and check.ratio == pytest.approx(1.0, abs=0.01)
    assert told >= 3
    if name.startswith('field') or name == 'loose_bracket':
        segments, _ = identify_bag(BAGS / f'{name}.mcap')
        for segment in segments:
            model = RotorModel.from_layout(segment.layout)
            assert segment.estimate.identifiable
            measured = {s.name: segment.estimate.biases[k]
                        for k, s in enumerate(model.supports)}
            assert cell_mistakes(static_loads(model), measured) == []
