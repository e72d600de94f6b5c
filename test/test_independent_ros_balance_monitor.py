"""
The node ``BalanceMonitor`` itself, in this process: its callbacks called with messages.

One node on its own rclpy context (a ROS_DOMAIN_ID from the process id), its publishers'
``publish`` kept by the test and its monotonic clock the test's, so nothing spins and no
other process runs. Each motion sample's outputs are read back with rclpy's own
deserialiser and compared with Pinocchio's RNEA and statics by hand
(:class:`independent.PinocchioRotor`); the verdict words, levels and counts in
``/diagnostics`` are worked out by hand (ISO 21940-11: the achieved grade e omega, e =
U / m, against the grade and 0.8 of it).
"""

import json
import math
import os
from unittest import mock

import numpy as np
import pytest
import rclpy
import rclpy.time
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message, serialize_message

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from cvc_balance.ros import balance_monitor
from cvc_balance.ros.balance_monitor import BalanceMonitor
from independent import PinocchioRotor

GRAVITY = [0.0, -9.80665 * math.cos(1.2), 9.80665 * math.sin(1.2)]   # the axial load peaks
TWO = {'name': 'two supports', 'gravity': GRAVITY,
       'components': [
           {'name': 'a', 'mass': 20.0, 'radius': 0.5, 'angle_deg': 30.0, 'z': -0.1,
            'shape': {'type': 'box', 'size': [0.1, 0.2, 0.3]}},
           {'name': 'b', 'mass': 12.0, 'radius': 0.4, 'angle_deg': 200.0, 'z': 0.2},
           {'name': 'c', 'mass': 7.0, 'radius': 0.3, 'angle_deg': 110.0, 'z': 0.05,
            'shape': {'type': 'cylinder', 'radius': 0.05, 'length': 0.2,
                      'axis': 'tangential'}}],
       'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.35, 'axial': True}]}


def one_support(grade):
    """Return a layout judged by its static unbalance: 5 kg at 0.7 m on a centred 400 kg drum."""
    return {'name': f'drum G{grade:g}', 'gravity': [0.0, -9.80665, 0.0],
            'components': [
                {'name': 'drum', 'mass': 400.0, 'radius': 0.0, 'angle_deg': 0.0,
                 'shape': {'type': 'tube', 'inner_radius': 0.7, 'outer_radius': 0.8,
                           'length': 0.3}},
                {'name': 'lump', 'mass': 5.0, 'radius': 0.7, 'angle_deg': 40.0, 'z': 0.1}],
            'supports': [{'name': 'slewing', 'z': 0.03}], 'balancing': {'grade': grade}}


class Clock:
    """The node's monotonic clock, set by the test (whole nanoseconds)."""

    def __init__(self):
        self.ns = 1000 * 10**9

    def __call__(self):
        return self.ns / 1e9

    def advance(self, seconds):
        self.ns += round(seconds * 1e9)


@pytest.fixture(scope='module')
def node():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + os.getpid() % 80)
    published = []
    clock = Clock()
    with mock.patch.object(Publisher, 'publish',
                           lambda self, msg: published.append((self.topic_name, msg))), \
            mock.patch.object(balance_monitor, 'monotonic', clock):
        monitor = BalanceMonitor(context=context, parameter_overrides=[
            Parameter('joint_name', value='spin'), Parameter('stator_frame', value='base'),
            Parameter('rotor_frame', value='drum'), Parameter('machine_id', value='M7'),
            Parameter('max_stamp_jump', value=0.5), Parameter('stale_after', value=3.0)])
        monitor.published, monitor.clock = published, clock
        yield monitor
        try:
            monitor.destroy_node()
        except Exception:       # a mutant's broken state (mutants_in_process): go on
            Node.destroy_node(monitor)
    rclpy.try_shutdown(context=context)


def put_layout(node, mapping):
    """Hand ``mapping`` to the layout callback and put it in force (or refuse it)."""
    node._on_layout(String(data=json.dumps(mapping)))
    node._preparing.result()
    node._take_prepared()


def joint_states(sec, nanosec, angle, omega, names=('other', 'spin')):
    """Return a JointState's CDR bytes: joint 'spin' at ``angle`` and ``omega``."""
    msg = JointState(name=list(names), position=[9.0, angle][-len(names):],
                     velocity=[-3.0, omega][-len(names):])
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return serialize_message(msg)


def sample(node, angle, omega, after=0.01, lead=0.0, names=('other', 'spin')):
    """
    Hand the node a JointState ``after`` s of its clock after the previous one.

    Stamped on the receive clock's line (900 s behind it) plus ``lead`` s; returns the
    stamp (sec, nanosec).
    """
    node.clock.advance(after)
    stamp = node.clock.ns - 900 * 10**9 + round(lead * 1e9)
    sec, nanosec = divmod(stamp, 10**9)
    node._on_joint_states(joint_states(sec, nanosec, angle, omega, names))
    return sec, nanosec


def wrenches(node):
    """Return and forget what was published: {topic: [WrenchStamped or DiagnosticArray]}."""
    out = {}
    for topic, msg in node.published:
        if isinstance(msg, bytes):
            msg = deserialize_message(msg, WrenchStamped)
        out.setdefault(topic, []).append(msg)
    node.published.clear()
    return out


def vector(v):
    return np.array([v.x, v.y, v.z])


def diagnostics(node):
    """Publish the diagnostics now; return the statuses by name's tail, values as dicts."""
    node.published.clear()
    node._publish_diagnostics()
    (array,) = wrenches(node)['/diagnostics']
    assert isinstance(array, DiagnosticArray)
    return {s.name.split(': ', 1)[1]: (s, {kv.key: kv.value for kv in s.values})
            for s in array.status}


def test_a_new_node_has_counted_nothing_and_waits_for_a_layout(node):
    """Say WARN, where the layout is awaited, and zero counts (first: the node is new)."""
    status, values = diagnostics(node)['rotor balance']
    assert (status.level, status.message) == (
        DiagnosticStatus.WARN, 'no layout (waiting for one on /layout, or set layout_file)')
    assert status.hardware_id == 'M7'
    assert values == {'accepted': '0', 'rejected': '0', 'dropped': '0', 'input rate [Hz]': '0',
                      'peak bearing load [N]': '0', 'rejected in the last period': '0',
                      'internal errors': '0', 'last rejected input': '',
                      'last rejected layout': ''}
    assert (node._top_speed, node._omega, node._last_time, node._layout_poll) == (
        0.0, 0.0, None, None)


def test_the_subscriptions_take_raw_bytes_through_the_guard(node):
    """Subscribe joint_states and speed raw, layout as messages; a failure is counted."""
    subscriptions = {s.topic_name: s for s in node.subscriptions}
    assert {name: (s.msg_type, s.raw) for name, s in subscriptions.items()} == {
        '/joint_states': (JointState, True), '/speed': (Float64, True),
        '/layout': (String, False)}
    dropped, errors = node._counts['dropped'], node._internal_errors
    subscriptions['/joint_states'].callback(joint_states(1, 0, 0.0, 1.0))
    subscriptions['/speed'].callback(serialize_message(Float64(data=1.0)))
    assert node._counts['dropped'] == dropped + 2        # no layout yet
    subscriptions['/joint_states'].callback(None)
    assert node._internal_errors == errors + 1
    assert node._last_rejection == ("internal error in _on_joint_states: TypeError: object of "
                                    "type 'NoneType' has no len()")
    node._internal_errors = errors      # the later tests count from 0
    subscriptions['/layout'].callback(String(data=json.dumps(TWO)))
    node._preparing.result()
    node._take_prepared()
    assert node._active.layout.name == 'two supports'


def test_each_motion_sample_gives_pinocchios_loads_in_their_frames_with_its_stamp(node):
    """Publish bearing, support, unbalance and drive torque wrenches as Pinocchio has them."""
    put_layout(node, TWO)
    assert node._layout_error == ''
    reference = PinocchioRotor(TWO)
    omega = 3.0
    start = node._counts['accepted']
    for i in range(4):          # constant speed: alpha is 0
        angle = 0.3 + omega * 0.01 * i
        wrenches(node)
        stamp = sample(node, angle, omega)
    out = wrenches(node)
    assert node._counts['accepted'] == start + 4
    expected = reference.loads(angle, omega, 0.0)
    assert sorted(out) == ['/bearing_load', '/drive_torque', '/supports/front/load',
                           '/supports/rear/load', '/unbalance']
    for topic, frame in (('/bearing_load', 'base'), ('/supports/front/load', 'base'),
                         ('/supports/rear/load', 'base'), ('/unbalance', 'drum'),
                         ('/drive_torque', 'drum')):
        (msg,) = out[topic]
        assert msg.header.frame_id == frame, topic
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == stamp, topic
    scale = 1e-9 * 40.0 * 9.81 * 10
    (bearing,) = out['/bearing_load']
    np.testing.assert_allclose(vector(bearing.wrench.force), expected['force'], atol=scale)
    np.testing.assert_allclose(vector(bearing.wrench.torque), expected['moment'], atol=scale)
    for name in ('front', 'rear'):
        (msg,) = out[f'/supports/{name}/load']
        force, moment = expected['supports'][name]
        np.testing.assert_allclose(vector(msg.wrench.force), force, atol=scale)
        np.testing.assert_allclose(vector(msg.wrench.torque), moment, atol=scale)
    (torque,) = out['/drive_torque']
    assert vector(torque.wrench.force).tolist() == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(vector(torque.wrench.torque), [0.0, 0.0, expected['drive_torque']],
                               atol=scale)
    (unbalance,) = out['/unbalance']
    force, moment = reference.unbalance(omega)
    np.testing.assert_allclose(vector(unbalance.wrench.force), force, atol=scale)
    np.testing.assert_allclose(vector(unbalance.wrench.torque), moment, atol=scale)
    # The diagnostics' counts and the peak support load, by hand from Pinocchio's split.
    _, values = diagnostics(node)['rotor balance']
    peak = max(np.linalg.norm(reference.loads(0.3 + omega * 0.01 * i, omega, 0.0)['supports']
                              [name][0]) for i in range(4) for name in ('front', 'rear'))
    assert float(values['peak bearing load [N]']) == pytest.approx(peak, rel=1e-5)
    assert max(np.linalg.norm(expected['supports'][name][0]) for name in ('front', 'rear')) \
        == pytest.approx(abs(expected['supports']['rear'][0][2]), rel=0.2)
    assert values['accepted'] == str(start + 4)
    assert float(values['input rate [Hz]']) == pytest.approx(4 / 0.04)
    assert float(values['speed [rad/s]']) == omega
    assert float(values['top speed seen [rad/s]']) == omega
    assert float(values['last motion sample [s ago]']) == 0.0


def test_samples_off_the_time_line_or_without_the_joint_are_rejected_in_words(node):
    """Count each rejection and say its reason; publish nothing for it; WARN for the period."""
    put_layout(node, one_support(200.0))
    accepted = node._counts['accepted']
    sample(node, 0.0, 2.0, after=1.0)
    assert node._counts['accepted'] == accepted + 1
    wrenches(node)
    rejected = node._counts['rejected']
    sample(node, 0.1, 2.0, lead=0.6)          # 0.6 s ahead of the line: max_stamp_jump 0.5
    assert node._last_rejection.startswith('motion sample: stamp ')
    sample(node, 0.1, 2.0, names=('spun',))
    assert node._last_rejection == "/joint_states without joint 'spin' (it names 'spun'): " \
        'set joint_name'
    msg = JointState(name=['spin'], position=[0.1])
    node._on_joint_states(serialize_message(msg))
    assert node._last_rejection == "/joint_states: joint 'spin' has no position or velocity"
    node._on_joint_states(b'\x00\x01\x00\x00\x00')
    assert node._last_rejection.startswith(
        'joint_states message not readable as JointState: ')
    node._on_speed(b'\x01\x00\x00\x00' + bytes(8))
    assert node._last_rejection == 'speed message not readable as Float64'
    node._on_speed(serialize_message(Float64(data=2e5)))
    assert node._last_rejection.startswith('speed: ')
    assert node._counts['rejected'] == rejected + 6
    assert wrenches(node) == {}
    status, values = diagnostics(node)['rotor balance']
    assert values['rejected'] == str(rejected + 6)
    assert values['rejected in the last period'] == '6'
    assert float(values['input rate [Hz]']) == pytest.approx(1 / 1.02)
    assert status.level == DiagnosticStatus.WARN
    assert status.message == (
        'G 17.3 at the top speed seen 2 rad/s: WITHIN G 200 (from the layout: no load cells); '
        f'6 motion samples rejected in the last 1 s (last: {node._last_rejection})')
    assert values['last rejected input'] == node._last_rejection
    _, values = diagnostics(node)['rotor balance']
    assert (values['rejected in the last period'], values['peak bearing load [N]']) == ('0', '0')


@pytest.mark.parametrize('grade, level, words', [
    (200.0, DiagnosticStatus.OK, 'G 86.4 at the top speed seen 10 rad/s: WITHIN G 200'),
    (150.0, DiagnosticStatus.OK, 'G 86.4 at the top speed seen 10 rad/s: WITHIN G 150'),
    (100.0, DiagnosticStatus.WARN,
     'G 86.4 at the top speed seen 10 rad/s: WITHIN G 100, NEAR ITS LIMIT'),
    (40.0, DiagnosticStatus.ERROR, 'G 86.4 at the top speed seen 10 rad/s: OUT OF G 40')])
def test_the_verdict_of_a_layout_is_its_static_grade_at_the_top_speed_seen(
        node, grade, level, words):
    """Judge 5 kg at 0.7 m on 405 kg at 10 rad/s: e omega = 3.5 / 405 * 10 m/s = 86.4 mm/s."""
    put_layout(node, one_support(grade))
    assert node._top_speed == 0.0
    accepted = node._counts['accepted']
    for omega in (4.0, -10.0, 6.0):
        sample(node, 0.0, omega)
    assert node._counts['accepted'] == accepted + 3
    wrenches(node)
    statuses = diagnostics(node)
    status, values = statuses['rotor balance']
    assert status.name == '/balance_monitor: rotor balance'
    assert status.hardware_id == 'M7'
    achieved = 5.0 * 0.7 / 405.0 * 10.0 * 1e3
    assert float(values['achieved grade [mm/s]']) == pytest.approx(achieved, rel=1e-5)
    static = 5.0 * 700.0 * 1e3         # g mm
    assert float(values['static unbalance [g mm]']) == pytest.approx(static, rel=1e-5)
    assert float(values['static unbalance angle [deg]']) == pytest.approx(40.0)
    permissible = grade * 405.0 / 10.0 * 1e3      # G m / omega, g mm
    assert float(values['permissible [g mm]']) == pytest.approx(permissible, rel=1e-5)
    assert float(values['top speed seen [rad/s]']) == 10.0
    assert float(values['speed [rad/s]']) == 6.0
    assert values['judged at'] == 'top speed seen'
    assert values['layout'] == f'drum G{grade:g}'
    assert values['verdict source'] == 'layout'
    assert status.level == level
    assert status.message == f'{words} (from the layout: no load cells)'
    assert values['layout warnings'] == ''
    couple = 5.0 * 0.7 * (0.1 - 5.0 * 0.1 / 405.0) * 1e9     # m r (z - z_c), g mm^2
    assert float(values['couple unbalance [g mm^2]']) == pytest.approx(couple, rel=1e-5)
    assert float(values['couple unbalance angle [deg]']) == pytest.approx(40.0)
    assert float(values['judged at [rad/s]']) == 10.0
    assert float(values['layout achieved grade [mm/s]']) == pytest.approx(achieved, rel=1e-5)
    assert float(values['grade [mm/s]']) == grade
    assert values['verdict level'] == values['layout verdict level'] == \
        {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
         DiagnosticStatus.ERROR: 'ERROR'}[level]
    assert values['verdict'] == status.message
    assert values['layout verdict'] == words
    assert values['what would explain it'] == ''
    assert list(values) == [
        'accepted', 'rejected', 'dropped', 'input rate [Hz]', 'peak bearing load [N]',
        'rejected in the last period', 'internal errors', 'last rejected input',
        'last rejected layout', 'layout', 'layout digest', 'speed [rad/s]',
        'top speed seen [rad/s]', 'grade [mm/s]', 'verdict level', 'verdict',
        'verdict source', 'what would explain it', 'achieved grade [mm/s]',
        'layout verdict level', 'layout verdict', 'judged at [rad/s]', 'judged at',
        'layout achieved grade [mm/s]', 'static unbalance [g mm]',
        'static unbalance angle [deg]', 'couple unbalance [g mm^2]',
        'couple unbalance angle [deg]', 'permissible [g mm]', 'layout warnings',
        'last motion sample [s ago]']
    assert values['internal errors'] == '0'


def test_two_supports_are_judged_in_planes_i_and_ii(node):
    """Name each plane's values after the plane, I before II (the statuses' words)."""
    put_layout(node, TWO)
    sample(node, 0.0, 3.0)
    _, values = diagnostics(node)['rotor balance']
    planes = [key for key in values if key.startswith('plane ')]
    assert planes == [f'plane {label} {what}' for label in ('I', 'II') for what in (
        'z [m]', 'unbalance [g mm]', 'angle [deg]', 'permissible [g mm]',
        'unbalance / permissible', 'correction mass [g]', 'correction angle [deg]')]
    assert (float(values['plane I z [m]']), float(values['plane II z [m]'])) == (-0.3, 0.35)


def test_no_layout_and_a_refused_one_are_said_in_the_headline(node, monkeypatch):
    """WARN without a layout; a refused layout keeps the one in force and is said after it."""
    monkeypatch.setattr(node, '_active', None)
    monkeypatch.setattr(node, '_layout_error', '')
    dropped = node._counts['dropped']
    sample(node, 0.0, 1.0)
    assert node._counts['dropped'] == dropped + 1
    status, values = diagnostics(node)['rotor balance']
    assert (status.level, status.message) == (
        DiagnosticStatus.WARN, 'no layout (waiting for one on /layout, or set layout_file)')
    assert values['dropped'] == str(dropped + 1)
    monkeypatch.undo()
    put_layout(node, one_support(200.0))
    bad = dict(one_support(200.0), supports=[])
    put_layout(node, bad)
    assert node._active.layout.name == 'drum G200'
    assert node._layout_error.startswith('layout topic: ')
    status, values = diagnostics(node)['rotor balance']
    assert values['last rejected layout'] == node._layout_error
    assert status.message == (
        'balance grade not judged: the layout names no service speed '
        '(balancing.service_speed) and the rotor has not turned (from the layout: no load '
        f'cells); last layout rejected: {node._layout_error}')
    put_layout(node, one_support(200.0))
    assert node._layout_error == ''


def test_no_motion_sample_for_stale_after_is_stale_naming_the_topics(node):
    """Say STALE, how long and where samples are awaited, before the verdict."""
    put_layout(node, one_support(200.0))
    sample(node, 0.0, 10.0)
    wrenches(node)
    node.clock.advance(3.3)
    status, values = diagnostics(node)['rotor balance']
    assert status.level == DiagnosticStatus.STALE
    assert float(values['last motion sample [s ago]']) == pytest.approx(3.3)
    assert status.message == (
        'no motion sample for 3.3 s on /joint_states or /speed, where nothing publishes '
        '(stale after 3 s); G 86.4 at the top speed seen 10 rad/s: WITHIN G 200 '
        '(from the layout: no load cells)')
    node.clock.advance(-0.5)
    status, _ = diagnostics(node)['rotor balance']
    assert status.level == DiagnosticStatus.OK


class RosClock:
    """The node's ROS clock, on the test's monotonic clock's line (900 s behind it)."""

    def __init__(self, clock):
        self.clock = clock

    def now(self):
        return rclpy.time.Time(nanoseconds=self.clock.ns - 900 * 10**9)


def test_speed_samples_are_stamped_now_and_their_angle_integrated(node, monkeypatch):
    """Integrate q = omega t over the receive times (from 0) and stamp each output then."""
    put_layout(node, TWO)
    monkeypatch.setattr(node, 'get_clock', lambda: RosClock(node.clock))
    monkeypatch.setattr(node, '_integrator', type(node._integrator)())    # q from 0
    reference = PinocchioRotor(TWO)
    accepted = node._counts['accepted']
    omega = 0.5
    for i in range(3):
        wrenches(node)
        node.clock.advance(0.02)
        node._on_speed(serialize_message(Float64(data=omega)))
    assert node._counts['accepted'] == accepted + 3
    out = wrenches(node)
    stamp = divmod(node.clock.ns - 900 * 10**9, 10**9)
    expected = reference.loads(2 * 0.02 * omega, omega, 0.0)
    (bearing,) = out['/bearing_load']
    assert (bearing.header.stamp.sec, bearing.header.stamp.nanosec) == stamp
    scale = 1e-9 * 40.0 * 9.81 * 10
    np.testing.assert_allclose(vector(bearing.wrench.force), expected['force'], atol=scale)
    np.testing.assert_allclose(vector(bearing.wrench.torque), expected['moment'], atol=scale)
    (unbalance,) = out['/unbalance']
    assert (unbalance.header.stamp.sec, unbalance.header.stamp.nanosec) == stamp
    np.testing.assert_allclose(vector(unbalance.wrench.force), reference.unbalance(omega)[0],
                               atol=scale)
    _, values = diagnostics(node)['rotor balance']
    assert float(values['top speed seen [rad/s]']) == omega


def test_of_layouts_that_come_meanwhile_the_newest_waits_and_the_others_are_dropped(node):
    """Parse one layout at a time; the newest waits for it, and is put in force after it."""
    dropped = node._layouts_dropped
    node._on_layout(String(data=json.dumps(one_support(10.0))))
    assert node._layout_poll is not None
    node._on_layout(String(data=json.dumps(one_support(20.0))))
    node._on_layout(String(data=json.dumps(dict(one_support(30.0), supports=[]))))
    assert node._layouts_dropped == dropped + 1
    node._preparing.result()
    node._take_prepared()
    assert node._active.layout.name == 'drum G10'
    assert node._layout_poll is not None and node._waiting is None
    node._preparing.result()
    node._take_prepared()
    assert node._active.layout.name == 'drum G10'
    assert node._layout_error.startswith('layout topic: ')
    assert (node._preparing, node._waiting, node._layout_poll) == (None, None, None)
    status, values = diagnostics(node)['input checks']
    assert values['layouts dropped unparsed'] == str(dropped + 1)
    put_layout(node, one_support(20.0))
    assert node._layout_poll is None


class Logger:
    """The node's logger in the test: (severity, text) of each line."""

    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def warning(self, text):
        self.lines.append(('warning', text))

    def error(self, text):
        self.lines.append(('error', text))


def test_level_changes_refusals_and_rejections_are_logged_once_at_their_severity(
        node, monkeypatch):
    """Log a change of level once; a refused layout as an error; rejections once a second."""
    logger = Logger()
    monkeypatch.setattr(node, 'get_logger', lambda: logger)
    put_layout(node, one_support(200.0))
    sample(node, 0.0, 10.0)
    diagnostics(node)
    ok = 'G 86.4 at the top speed seen 10 rad/s: WITHIN G 200 (from the layout: no load cells)'
    node._reported_level = None
    logger.lines.clear()
    diagnostics(node)
    diagnostics(node)
    assert logger.lines == [('info', f'balance OK: {ok}')]
    logger.lines.clear()
    put_layout(node, one_support(40.0))         # the new verdict at once
    sample(node, 0.0, 10.0)
    diagnostics(node)
    assert logger.lines[0] == ('info', 'layout received on the layout topic '
                               f'({len(json.dumps(one_support(40.0)))} characters): parsing')
    assert logger.lines[-1] == ('error', 'balance ERROR: G 86.4 at the top speed seen 10 '
                                'rad/s: OUT OF G 40 (from the layout: no load cells)')
    logger.lines.clear()
    put_layout(node, dict(one_support(40.0), supports=[]))
    assert logger.lines[-1] == (
        'error', f"layout rejected ('drum G40' stays in force): {node._layout_error}")
    logger.lines.clear()
    node.clock.advance(1.0)
    sample(node, 0.0, 10.0, names=('spun',))
    sample(node, 0.0, 10.0, names=('spun',))
    assert logger.lines == [('warning', "rejected /joint_states without joint 'spin' (it "
                             "names 'spun'): set joint_name")]
    node.clock.advance(3.5)
    diagnostics(node)
    assert logger.lines[-1][0] == 'warning'
    assert logger.lines[-1][1].startswith('balance STALE: no motion sample for 4.5 s on ')
    put_layout(node, one_support(200.0))


def test_a_speed_ramp_gives_pinocchios_drive_torque_and_loads_at_its_slope(node, monkeypatch):
    """Estimate alpha as the ramp's slope; a layout parsed meanwhile takes the next sample."""
    node._on_layout(String(data=json.dumps(TWO)))
    node._preparing.result()
    monkeypatch.setattr(node, '_alpha', type(node._alpha)(0.1))   # no earlier samples
    reference = PinocchioRotor(TWO)
    node.clock.advance(1.0)
    for i in range(6):          # omega = 2 + 3 t, q = 2 t + 1.5 t^2
        t = 0.01 * i
        wrenches(node)
        sample(node, 2 * t + 1.5 * t * t, 2 + 3 * t, after=0.0 if i == 0 else 0.01)
        assert node._active.layout.name == 'two supports'
    out = wrenches(node)
    expected = reference.loads(2 * t + 1.5 * t * t, 2 + 3 * t, 3.0)
    scale = 1e-6 * 40.0 * 9.81
    (torque,) = out['/drive_torque']
    assert torque.wrench.torque.z == pytest.approx(expected['drive_torque'], abs=scale)
    assert abs(expected['drive_torque'] - reference.loads(2 * t + 1.5 * t * t, 2 + 3 * t,
                                                          0.0)['drive_torque']) > 0.1
    (bearing,) = out['/bearing_load']
    np.testing.assert_allclose(vector(bearing.wrench.force), expected['force'], atol=scale)


def test_an_implausible_layout_is_a_warn_with_its_first_warning_in_the_headline(node):
    """Say how many warnings and the first; list them all, ' | ' between, in the values."""
    layout = one_support(200.0)
    angles = (10.0, 10.0 + math.pi / 2)       # radians, more than a full turn
    layout['components'][1:] = [
        {'name': name, 'mass': 5.0, 'radius': 0.7, 'angle': angle, 'z': 0.1}
        for name, angle in zip(('lump', 'lump2'), angles)]
    put_layout(node, layout)
    sample(node, 0.0, 10.0)
    status, values = diagnostics(node)['rotor balance']
    said = [f"component '{name}': angle {angle:.6g} rad ({math.degrees(angle):.6g} deg) is "
            'more than a full turn: degrees in the radians field? (angle_deg takes degrees)'
            for name, angle in zip(('lump', 'lump2'), angles)]
    assert values['layout warnings'] == ' | '.join(said)
    achieved = math.hypot(3.5, 3.5) / 410.0 * 10.0 * 1e3        # 0.60 of G 200: OK
    assert status.level == DiagnosticStatus.WARN
    assert status.message == (
        f'G {achieved:.3g} at the top speed seen 10 rad/s: WITHIN G 200 (from the layout: no '
        f'load cells); layout implausible? 2 warning(s): {said[0]}')
    put_layout(node, one_support(200.0))


def test_each_planes_unbalance_and_correction_mass_by_the_lever_rule(node):
    """Split 5 kg at 0.7 m, z 0.1 over planes at z -0.2 and 0.3; correct at 0.5 m opposite."""
    layout = dict(one_support(200.0), supports=[{'name': 'front', 'z': -0.2},
                                                {'name': 'rear', 'z': 0.3, 'axial': True}])
    layout['balancing'] = {'grade': 200.0, 'correction_radius': 0.5}
    put_layout(node, layout)
    sample(node, 0.0, 10.0)
    _, values = diagnostics(node)['rotor balance']
    for label, share in (('I', (0.3 - 0.1) / 0.5), ('II', (0.1 + 0.2) / 0.5)):
        amount = 3.5 * share                                        # kg m
        unbalance = float(values[f'plane {label} unbalance [g mm]'])
        assert unbalance == pytest.approx(amount * 1e6, rel=1e-5)
        assert float(values[f'plane {label} angle [deg]']) == pytest.approx(40.0)
        assert float(values[f'plane {label} correction mass [g]']) == pytest.approx(
            amount / 0.5 * 1e3, rel=1e-5)
        assert float(values[f'plane {label} correction angle [deg]']) == pytest.approx(220.0)
    put_layout(node, one_support(200.0))
