"""
The node ``BalanceMonitor`` with its options on, in this process: what each option adds.

One node on its own rclpy context (as test_independent_ros_balance_monitor.py makes it:
``publish`` kept, the monotonic clock the test's, nothing spins) with a layout_file, a
recording (record_path, labelled a trial run, machine M8), the bearings' life (the layout's
supports describe their bearings), load cells (each support's cell reads what Pinocchio
gives for the TRUE rotor: the layout's balanced drum and a 0.5 kg mass it misses), a
keyphasor topic and a rerun view (its logger a stand-in that keeps what it is handed).
The recording is read back with the ``mcap`` library; the identified unbalance is the
missed mass's by hand (m r omega^2), the bearings' life ISO 281's (P / C)^p per
revolution under the constant loads of a balanced drum (each support half its weight);
the log lines are the words people read.
"""

from functools import partial
import json
import math
import os
import struct
import threading
import time
from unittest import mock

from mcap.reader import make_reader
import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message, serialize_message
from rcl_interfaces.msg import ParameterType
import yaml

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from cvc_balance.ros import balance_monitor
from cvc_balance.ros.balance_monitor import BalanceMonitor
from cvc_balance.physics import layout_file
from cvc_balance.view import rerun_log
from independent import PinocchioRotor
from test_independent_ros_balance_monitor import Clock, Logger
from test_independent_ros_load_cells import wrench

G = 9.80665
DRUM = {'name': 'balanced drum', 'gravity': [0.0, -G, 0.0],
        'components': [{'name': 'drum', 'mass': 400.0, 'radius': 0.0, 'angle_deg': 0.0,
                        'shape': {'type': 'tube', 'inner_radius': 0.7, 'outer_radius': 0.8,
                                  'length': 0.3}}],
        'supports': [{'name': 'front', 'z': -0.5,
                      'bearing': {'C': 20000.0, 'type': 'ball', 'limit_speed': 15.0}},
                     {'name': 'rear', 'z': 0.5, 'axial': True,
                      'bearing': {'C': 40000.0, 'type': 'roller', 'a1': 0.5}}],
        'balancing': {'grade': 6.3}}
MISSED = {'name': 'missed', 'mass': 0.5, 'radius': 0.6, 'angle_deg': 30.0, 'z': 0.1}
OMEGA, RATE = 20.0, 500.0
LINE_NS = 900 * 10**9           # the stamps' line: 900 s behind the receive clock


class Rerun:
    """rerun_log's open_recording and RunLogger: what the node hands them, kept."""

    def __init__(self):
        self.calls = []

    def open_recording(self, mode, target='', name='cvc_balance'):
        self.calls.append(('open_recording', mode, target, name))
        return 'the recording'

    def RunLogger(self, recording, every=1):      # noqa: N802 (the class it stands for)
        self.calls.append(('RunLogger', recording, every))
        return self

    def layout(self, time_ns, model):
        self.calls.append(('layout', time_ns, model))

    def sample(self, stamp_ns, angle, omega, alpha, result):
        self.calls.append(('sample', stamp_ns, angle, omega, alpha, result))

    def evidence(self, time_ns, of_record):
        self.calls.append(('evidence', time_ns, of_record))

    def finish(self):
        self.calls.append(('finish',))


@pytest.fixture(scope='module')
def node(tmp_path_factory):
    folder = tmp_path_factory.mktemp('options')
    layout_file = folder / 'drum.yaml'
    layout_file.write_text(yaml.safe_dump(DRUM))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + (os.getpid() + 40) % 80)
    published, clock, logger, rerun = [], Clock(), Logger(), Rerun()
    with mock.patch.object(Publisher, 'publish',
                           lambda self, msg: published.append((self.topic_name, msg))), \
            mock.patch.object(balance_monitor, 'monotonic', clock), \
            mock.patch.object(BalanceMonitor, 'get_logger', lambda self: logger), \
            mock.patch.object(rerun_log, 'open_recording', rerun.open_recording), \
            mock.patch.object(rerun_log, 'RunLogger', rerun.RunLogger):
        monitor = BalanceMonitor(context=context, parameter_overrides=[
            Parameter('joint_name', value='spin'), Parameter('machine_id', value='M8'),
            Parameter('layout_file', value=str(layout_file)),
            Parameter('record_path', value=str(folder / 'run.mcap')),
            Parameter('record_run', value='trial'),
            Parameter('record_trial', value='I:0.2@0,0.68'),
            Parameter('identify_window_revs', value=2),
            Parameter('keyphasor_topic', value='tach'),
            Parameter('keyphasor_edge', value='falling'),
            Parameter('keyphasor_threshold', value=0.5),
            Parameter('rerun', value='save'), Parameter('rerun_target', value='run.rrd'),
            Parameter('rerun_every', value=3)])
        monitor.published, monitor.clock, monitor.logger, monitor.rerun = \
            published, clock, logger, rerun
        monitor.folder, monitor.layout_file = folder, layout_file
        monitor.destroyed = False
        yield monitor
        if not monitor.destroyed:
            try:
                monitor.destroy_node()
            except Exception:       # a mutant's broken state (mutants_in_process): go on
                Node.destroy_node(monitor)
    rclpy.try_shutdown(context=context)


def joint_states(stamp_ns, angle, omega):
    msg = JointState(name=['spin'], position=[angle], velocity=[omega])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return serialize_message(msg)


def diagnostics(node):
    """Publish the diagnostics now; return the statuses by name's tail, values as dicts."""
    node.published.clear()
    node._publish_diagnostics()
    (array,) = [msg for topic, msg in node.published if topic == '/diagnostics']
    node.published.clear()
    assert isinstance(array, DiagnosticArray)
    assert array.header.stamp.sec > 1_600_000_000      # the ROS clock's now: system time
    return {s.name.split(': ', 1)[1]: (s, {kv.key: kv.value for kv in s.values})
            for s in array.status}


def test_the_layout_file_is_in_force_from_the_start_and_said(node):
    """Put the layout_file in force at start, say it, hand it to rerun; open the view."""
    active = node._active
    assert active.layout.name == 'balanced drum' and active.source == str(node.layout_file)
    assert node.logger.lines[0] == (
        'info', f"layout 'balanced drum' ({active.digest}) from {node.layout_file}: "
        '1 components, 400.000 kg')
    assert node.rerun.calls == [('open_recording', 'save', 'run.rrd', '/balance_monitor'),
                                ('RunLogger', 'the recording', 3),
                                ('layout', None, active.model)]
    assert active.model.mass == 400.0
    assert node._layout_error == ''
    assert node._recorder.counts['/layout'] == 1
    recorder = node._recorder          # the inputs and diagnostics from the graph, not outputs
    assert all(recorder.subscription(name) is not None for name in (
        '/joint_states', '/speed', '/layout', '/diagnostics'))
    assert recorder.subscription('/bearing_load') is None


def test_the_tach_is_awaited_on_its_topic_with_its_edge_and_threshold(node):
    """Say the keyphasor's topic awaited in the values and where samples are awaited."""
    keyphasor = node._keyphasor
    assert (keyphasor.topic, keyphasor.threshold, keyphasor.qos.depth) == ('/tach', 0.5, 1000)
    assert (keyphasor.signal.sign, keyphasor.signal.given) == (-1.0, 0.5)      # falling
    _, values = diagnostics(node)['rotor balance']
    assert values['keyphasor'] == '/tach (waiting for a publisher)'
    assert node._motion_topics() == (
        '/joint_states, /speed or the keyphasor /tach, where nothing publishes')


def test_before_any_sample_nothing_is_judged_and_stale_comes_after_stale_after(node):
    """Leave the achieved grade and the last sample empty; STALE only past stale_after."""
    status, values = diagnostics(node)['rotor balance']
    assert (values['last motion sample [s ago]'], values['achieved grade [mm/s]']) == ('', '')
    assert status.level == DiagnosticStatus.OK
    started = node._started
    node.clock.ns += 2 * 10**9                  # stale_after (2 s) exactly: not yet
    assert node.clock() - started == 2.0
    status, _ = diagnostics(node)['rotor balance']
    assert status.level == DiagnosticStatus.OK
    node.clock.ns += 1
    status, _ = diagnostics(node)['rotor balance']
    assert status.level == DiagnosticStatus.STALE
    assert status.message.startswith(
        'no motion sample yet on /joint_states, /speed or the keyphasor /tach, where nothing '
        'publishes (stale after 2 s); balance grade not judged: ')


def test_the_parameters_are_declared_read_only_with_their_ranges_and_words(node):
    """Describe each parameter as --help does: read only, typed, its range."""
    (depth, speed, target, edge) = node.describe_parameters(
        ['input_depth', 'max_speed', 'rerun_target', 'keyphasor_edge'])
    assert all(d.read_only for d in (depth, speed, target, edge))
    assert depth.type == ParameterType.PARAMETER_INTEGER
    assert [(r.from_value, r.to_value, r.step) for r in depth.integer_range] == [(1, 10000, 1)]
    assert depth.description == ('history depth of the best-effort joint_states, speed and '
                                 'load cell subscriptions')
    assert speed.type == ParameterType.PARAMETER_DOUBLE
    assert [(r.from_value, r.to_value) for r in speed.floating_point_range] == [(1e-3, 1e5)]
    assert target.description == '.rrd path (save) or viewer URL (connect)'
    assert edge.type == ParameterType.PARAMETER_STRING and not edge.floating_point_range


@pytest.mark.parametrize('name, value, said', [
    ('keyphasor_edge', 'sideways',
     "parameter keyphasor_edge must be rising or falling, got 'sideways'"),
    ('joint_name', ' ', "parameter joint_name must be a non-empty string, got ' '"),
    ('stator_frame', '', "parameter stator_frame must be a non-empty string, got ''"),
    ('rotor_frame', '\t', "parameter rotor_frame must be a non-empty string, got '\\t'"),
    ('balance_grade', 0.05, 'parameter balance_grade must be from 0.1 to 4000 mm/s (ISO '
     '21940-11 grades run from G 0.4 to G 4000), got 0.05 mm/s'),
    ('record_run', 'baseline', 'record_run and record_trial label a recording: set '
     'record_path')])
def test_a_parameter_that_cannot_be_is_refused_in_words(node, name, value, said):
    """Refuse the node: a tach edge, an empty name or frame, a grade out of ISO's range."""
    with pytest.raises(ValueError) as refused:
        BalanceMonitor(context=node.context, parameter_overrides=[Parameter(name, value=value)])
    assert str(refused.value) == said
    BalanceMonitor(context=node.context,
                   parameter_overrides=[Parameter('balance_grade', value=4000.0)]).destroy_node()


def cell_callbacks(node):
    """Return the load cells' callbacks by topic (the recorder may subscribe there too)."""
    return {s.topic_name: s.callback for s in node.subscriptions
            if s.topic_name.endswith('/measured_load') and isinstance(s.callback, partial)}


@pytest.fixture(scope='module')
def turned(node):
    """
    Turn at OMEGA for 2.2 revolutions, 500 samples a second; each cell reads each sample.

    The cells read the true rotor's support forces (the drum and MISSED) by Pinocchio.
    Returns the samples' stamps (ns) and what was published, by topic.
    """
    true = PinocchioRotor(dict(DRUM, components=DRUM['components'] + [MISSED]))
    cells = cell_callbacks(node)
    assert sorted(cells) == ['/supports/front/measured_load', '/supports/rear/measured_load']
    node.published.clear()
    node.logger.lines.clear()
    del node.rerun.calls[:]
    steps = int(2.2 * 2 * math.pi / OMEGA * RATE)
    stamps = []
    for j in range(steps + 1):
        node.clock.ns += 2_000_000
        stamp = node.clock.ns - LINE_NS
        stamps.append(stamp)
        angle = OMEGA * j / RATE
        node._on_joint_states(joint_states(stamp, math.remainder(angle, 2 * math.pi), OMEGA))
        for name, (force, _) in true.loads(angle, OMEGA, 0.0)['supports'].items():
            cells[f'/supports/{name}/measured_load'](wrench(*divmod(stamp, 10**9), force))
    out = {}
    for topic, msg in node.published:
        out.setdefault(topic, []).append(msg)
    return stamps, out


def test_the_cells_identify_the_missed_mass_at_each_revolution_in_the_rotor_frame(
        node, turned):
    """Publish the missed mass's m r omega^2 and couple m r z omega^2 at revolutions 1, 2."""
    stamps, out = turned
    assert node._counts['accepted'] == len(stamps)
    assert node._active.cells.readings == {'front': len(stamps), 'rear': len(stamps)}
    force = MISSED['mass'] * MISSED['radius'] * OMEGA ** 2          # 36 N
    couple = force * MISSED['z']
    angle = math.radians(MISSED['angle_deg'])
    want = ([force * math.cos(angle), force * math.sin(angle), 0.0],
            [-couple * math.sin(angle), couple * math.cos(angle), 0.0])
    for topic in ('/identified_unbalance', '/unbalance_residual'):   # the layout's is 0
        assert len(out[topic]) == 2, topic
        for revolution, data in zip((1, 2), out[topic]):
            msg = deserialize_message(data, WrenchStamped)
            # The sample that completed the revolution: the first past 2 pi k rad.
            j = math.ceil(revolution * 2 * math.pi / OMEGA * RATE)
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(stamps[j], 10**9)
            assert msg.header.frame_id == 'rotor'
            got = msg.wrench.force, msg.wrench.torque
            np.testing.assert_allclose([[v.x, v.y, v.z] for v in got], want, atol=1e-6)
    assert node._recorder.counts['/identified_unbalance'] == 2
    assert node._recorder.counts['/unbalance_residual'] == 2


def test_each_sample_is_handed_to_rerun_and_recorded_as_published(node, turned):
    """Hand rerun each sample's stamp, angle, speed, zero slope; record every output."""
    stamps, out = turned
    samples = [call for call in node.rerun.calls if call[0] == 'sample']
    assert len(samples) == len(stamps)
    for j, (_, stamp_ns, angle, omega, alpha, result) in enumerate(samples):
        assert stamp_ns == stamps[j]
        assert angle == math.remainder(OMEGA * j / RATE, 2 * math.pi) and omega == OMEGA
        assert abs(alpha) < 1e-9
    weight = 400.0 * G
    np.testing.assert_allclose(samples[-1][5].force_stator, [0.0, -weight, 0.0], atol=1e-9)
    for topic in ('/bearing_load', '/supports/front/load', '/supports/rear/load',
                  '/unbalance', '/drive_torque'):
        assert len(out[topic]) == len(stamps), topic
        assert node._recorder.counts[topic] == len(stamps), topic
    front = deserialize_message(out['/supports/front/load'][-1], WrenchStamped)
    assert [front.wrench.force.x, front.wrench.force.y] == pytest.approx(
        [0.0, -weight / 2], abs=1e-9)


def test_the_bearings_life_is_iso_281s_under_half_the_weight_each(node, turned):
    """
    Count (P / C)^p a revolution, P half the drum's weight; WARN over front's limit speed.

    Front: a ball bearing (p 3) of C 20 kN, limit 15 rad/s; rear: a roller bearing
    (p 10/3) of C 40 kN, a1 0.5. The state file beside the recording, read back.
    """
    stamps, _ = turned
    statuses = diagnostics(node)
    status, values = statuses['bearing life']
    assert status.name == '/balance_monitor: bearing life' and status.hardware_id == 'M8'
    seconds = (len(stamps) - 1) / RATE
    revolutions = OMEGA * seconds / (2 * math.pi)
    load = 400.0 * G / 2
    used = {'front': revolutions * (load / 20000.0) ** 3 / 1e6,
            'rear': revolutions * (load / 40000.0) ** (10 / 3) / 1e6 / 0.5}
    hours = seconds / 3600
    parts = [f'{name} {used[name]:.3g} used since start ({used[name] / hours:.3g}/h: rating '
             f'life {hours / used[name]:.4g} h at this duty), {used[name]:.3g} in all'
             for name in ('front', 'rear')]
    assert status.level == DiagnosticStatus.WARN
    assert status.message == ('bearing life: front: speed 20 rad/s over its limiting speed '
                              '15 rad/s; ' + '; '.join(parts))
    path = node.folder / 'bearing_life_M8.json'
    assert values['state file'] == str(path)
    for name in ('front', 'rear'):
        assert float(values[f'{name} life used since start']) == pytest.approx(
            used[name], rel=1e-5)
        assert float(values[f'{name} revolutions since start']) == pytest.approx(
            revolutions, rel=1e-5)
        assert float(values[f'{name} mean equivalent load since start [N]']) == \
            pytest.approx(load, rel=1e-5)
    status, values = statuses['input checks']
    assert (status.name, status.hardware_id, status.level) == (
        '/balance_monitor: input checks', 'M8', DiagnosticStatus.OK)
    assert status.message == ('inputs agree: joint position and velocity (rad, rad/s) and '
                              "the cells and their supports' shares")
    assert float(values['joint position rate / velocity']) == 1.0
    assert float(values['joint position wraps at']) == pytest.approx(2 * math.pi, rel=1e-5)
    for name in ('front', 'rear'):
        assert float(values[f'cell {name} share of the weight [N]']) == pytest.approx(
            load, rel=1e-5)
    saved = json.loads(path.read_text())
    blocker = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    blocker.mkdir()                     # where it is written first: the save fails, said
    node.logger.lines.clear()
    try:
        diagnostics(node)
    finally:
        blocker.rmdir()
    assert node.logger.lines == [
        ('error', f'bearing life: state file not written: Is a directory: {path}')]
    assert saved['kind'] == 'cvc_balance bearing life'
    for name in ('front', 'rear'):
        assert saved['supports'][name]['revolutions'] == pytest.approx(revolutions, rel=1e-9)
        assert saved['supports'][name]['life_used'] == pytest.approx(used[name], rel=1e-9)


def test_the_cells_verdict_is_of_record_said_once_and_handed_to_rerun(node, turned):
    """
    Judge the measured rotor: plane shares of 0.3 kg m at z 0.1 by the lever rule.

    Planes I and II at the supports (z -0.5, 0.5): 0.12 and 0.18 kg m; each plane may
    have half of G 6.3's U = G m / omega = 6.3e-3 * 400 / 20 kg m (levers 0.5 about the
    centre of mass); the grade achieved 6.3 * 0.18 / 0.063.
    """
    stamps, _ = turned
    node.logger.lines.clear()
    node._reported_measured = node._reported_level = None
    del node.rerun.calls[:]
    allowed = 6.3e-3 * 400.0 / OMEGA / 2 * 1e6                     # g mm a plane
    planes = [MISSED['mass'] * MISSED['radius'] * share * 1e6 for share in (0.4, 0.6)]
    grade = 6.3 * planes[1] / allowed
    assert f'{grade:.3g}' == '18'
    verdict = f'G {grade:.3g} at the top speed seen 20 rad/s: OUT OF G 6.3'
    said = [f'plane {label} +{amount:.0f} g mm at 30.0 deg' for label, amount in
            zip(('I', 'II'), planes)]
    detail = [f'{s} (95 % radius 0 g mm; {amount / allowed:.2f} of its permissible '
              f'{allowed:.0f} g mm)' for s, amount in zip(said, planes)]
    explain = (f"as if an unlisted {0.3 / 0.8 * 1e3:.0f} g at the correction radius 0.8 m "
               'were at 30 deg, z 0.100 m (or a part there heavier than the layout says)')
    statuses = diagnostics(node)
    status, values = statuses['measured unbalance']
    measured = (f'measured: {verdict}; the rotor is not what its layout says: '
                f'{", ".join(detail)}; {explain}')
    assert (status.name, status.hardware_id) == ('/balance_monitor: measured unbalance', 'M8')
    assert (status.level, status.message) == (DiagnosticStatus.ERROR, measured)
    assert values['cell front readings'] == values['cell rear readings'] == str(len(stamps))
    assert values['measured verdict'] == verdict
    assert float(values['measured static [g mm]']) == pytest.approx(3e5, rel=1e-6)
    assert float(values['measured static angle [deg]']) == pytest.approx(30.0)
    for label, amount in zip(('I', 'II'), planes):
        residual = float(values[f'residual plane {label} [g mm]'])
        assert residual == pytest.approx(amount, rel=1e-6)
    status, values = statuses['rotor balance']
    headline = (f'{verdict} (measured by the load cells); the rotor is not what its layout '
                f'says: {", ".join(said)}; the layout expects OK: G 0 at the top speed seen '
                '20 rad/s: WITHIN G 6.3')
    assert (status.level, status.message) == (DiagnosticStatus.ERROR, headline)
    assert node.logger.lines == [('error', f'load cells ERROR: {measured}'),
                                 ('error', f'balance ERROR: {headline}')]
    ((what, time_ns, of_record),) = node.rerun.calls
    assert (what, time_ns, of_record.source, of_record.level) == (
        'evidence', stamps[-1], 'measured', 'ERROR')
    diagnostics(node)
    assert len(node.logger.lines) == 2          # said once


def test_a_residual_over_residual_warn_within_the_grade_is_a_warn_said_as_a_warning(
        node, turned, monkeypatch):
    """
    Judge at balance_grade G 40 with residual_warn 0.3: within it, but not as laid out.

    Each plane may have half of U = 40e-3 * 400 / 20 kg m: 0.4 kg m; the residuals 0.12
    and 0.18 kg m are 0.3 and 0.45 of it: plane II over 0.3.
    """
    monkeypatch.setitem(node.params, 'balance_grade', 40.0)
    monkeypatch.setitem(node.params, 'residual_warn', 0.35)
    node.logger.lines.clear()
    node._reported_measured = node._reported_level = None
    allowed = 40e-3 * 400.0 / OMEGA / 2 * 1e6                      # g mm a plane
    residual = MISSED['mass'] * MISSED['radius'] * 0.6 * 1e6        # plane II's share
    verdict = f'G {40.0 * residual / allowed:.3g} at the top speed seen 20 rad/s: WITHIN G 40'
    plane = f'plane II +{residual:.0f} g mm at 30.0 deg'
    measured = (f'measured: {verdict}; the rotor is not what its layout says: {plane} (95 % '
                f'radius 0 g mm; {residual / allowed:.2f} of its permissible {allowed:.0f} g '
                'mm); as if an unlisted 375 g at the correction radius 0.8 m were at 30 deg, '
                'z 0.100 m (or a part there heavier than the layout says)')
    headline = (f'{verdict} (measured by the load cells); the rotor is not what its layout '
                f'says: {plane}; the layout expects OK: G 0 at the top speed seen 20 rad/s: '
                'WITHIN G 40')
    statuses = diagnostics(node)
    status, _ = statuses['measured unbalance']
    assert (status.level, status.message) == (DiagnosticStatus.WARN, measured)
    status, _ = statuses['rotor balance']
    assert (status.level, status.message) == (DiagnosticStatus.WARN, headline)
    assert node.logger.lines == [('warning', f'load cells WARN: {measured}'),
                                 ('warning', f'balance WARN: {headline}')]


def test_a_layout_file_refused_is_said_and_the_one_in_force_kept(node, turned):
    """Say a missing or bad file in the words people read; keep the layout in force."""
    stamps, _ = turned
    node.logger.lines.clear()
    missing = node.folder / 'none.yaml'
    node._apply_layout_file(missing)
    said = f'{missing}: cannot read layout file: No such file or directory'
    bad = node.folder / 'bad.yaml'
    bad.write_text(yaml.safe_dump(dict(DRUM, supports=[])))
    node._apply_layout_file(bad)
    wrong = f'{bad}: layout: field supports: needs 1 or 2 supports, got 0'
    assert node.logger.lines == [
        ('error', f"layout rejected ('balanced drum' stays in force): {said}"),
        ('error', f"layout rejected ('balanced drum' stays in force): {wrong}")]
    assert node._layout_error == wrong and node._active.layout.name == 'balanced drum'
    assert node._recorder.counts['/layout'] == 1
    status, values = diagnostics(node)['rotor balance']
    assert values['last rejected layout'] == wrong
    assert status.message.endswith(f'; last layout rejected: {wrong}')
    far = node.folder / ('n' * 150 + '.yaml')
    node._apply_layout_file(far)
    said = f'{far}: cannot read layout file: No such file or directory'
    status, _ = diagnostics(node)['rotor balance']
    assert status.message.endswith(
        f'; last layout rejected: {said[:150]}... ({len(said)} characters)')
    with mock.patch.object(node, '_active', None):
        node._refuse_layout('why')
    assert node.logger.lines[-1] == ('error', 'layout rejected (no layout in force): why')


def test_a_new_layout_file_after_samples_is_recorded_and_handed_to_rerun_then(node, turned):
    """Record the layout put in force; hand rerun the new model at the last sample's time."""
    stamps, _ = turned
    again = node.folder / 'again.yaml'
    again.write_text(yaml.safe_dump(dict(DRUM, name='drum again')))
    old = node._active
    del node.rerun.calls[:]
    node.logger.lines.clear()
    node.published.clear()
    node._apply_layout_file(again)
    active = node._active
    assert active is not old and active.layout.name == 'drum again'
    assert node._layout_error == '' and node._top_speed == 0.0
    assert node._recorder.counts['/layout'] == 2
    assert node.rerun.calls[0] == ('layout', stamps[-1], active.model)
    assert [call[0] for call in node.rerun.calls] == ['layout', 'evidence']
    assert node.logger.lines[0] == (
        'info', f"layout 'drum again' ({active.digest}) from {again}: 1 components, "
        '400.000 kg')
    assert [topic for topic, _ in node.published] == ['/diagnostics']   # the verdict at once
    assert node._life_counting is node._life.counting is not None
    assert set(node._life_counting.counters) == {'front', 'rear'}


def test_layouts_that_come_meanwhile_are_said_waiting_or_dropped(node):
    """Say each layout received, whether it waits, and the one dropped unparsed."""
    node.logger.lines.clear()
    texts = [json.dumps(dict(DRUM, name=name)) for name in ('one', 'two', 'three', 'four')]
    for text in texts:
        node._on_layout(String(data=text))
    assert node.logger.lines == [
        ('info', f'layout received on the layout topic ({len(texts[0])} characters): parsing'),
        ('info', f'layout received on the layout topic ({len(texts[1])} characters): waits '
                 'for the one being parsed'),
        ('info', f'layout received on the layout topic ({len(texts[2])} characters): waits '
                 'for the one being parsed'),
        ('warning', f'layout dropped unparsed ({len(texts[1])} characters from the layout '
                    'topic): a newer one came while another was being parsed; the newest '
                    'wins'),
        ('info', f'layout received on the layout topic ({len(texts[3])} characters): waits '
                 'for the one being parsed'),
        ('warning', f'layout dropped unparsed ({len(texts[2])} characters from the layout '
                    'topic): a newer one came while another was being parsed; the newest '
                    'wins')]
    for _ in range(2):
        node._preparing.result()
        node._take_prepared()
    assert node._active.layout.name == 'four' and node._layouts_dropped == 2


def test_samples_without_a_layout_and_on_a_new_time_line_are_said(node):
    """Say dropped samples once a second; say a new time line confirmed by two samples."""
    node.logger.lines.clear()
    checked = len(node._checks._recent)
    with mock.patch.object(node, '_active', None):
        for _ in range(2):
            node.clock.ns += 2_000_000
            node._on_joint_states(joint_states(node.clock.ns - LINE_NS, 0.0, OMEGA))
    node._on_joint_states(joint_states(node.clock.ns - LINE_NS + 10**12, 0.0, OMEGA))
    assert node._last_rejection.startswith('motion sample: stamp ')
    assert len(node._checks._recent) == checked     # neither checked as an input
    node.logger.lines[1:] = []
    assert node.logger.lines == [('warning', 'no layout yet: motion samples dropped')]
    node.logger.lines.clear()
    node.clock.ns += 10**9                       # a second without samples, then 50 s later
    for _ in range(2):
        node.clock.ns += 2_000_000
        stamp = node.clock.ns - LINE_NS + 50 * 10**9
        node._on_joint_states(joint_states(stamp, 0.0, OMEGA))
    assert node._last_time == pytest.approx(stamp / 1e9, abs=1e-9)
    sec, nanosec = divmod(stamp, 10**9)
    assert node.logger.lines[-1] == (
        'warning', f'motion samples moved to a new time line at {sec}.{nanosec:09d} s '
        '(confirmed by two samples)')


def test_a_message_rclpy_could_not_hand_over_is_counted_and_said(node):
    """Count it as an internal error; say it cut to 200 characters, once a second."""
    node.logger.lines.clear()
    errors = node._internal_errors
    node.clock.ns += 2 * 10**9
    node.lost_message(ValueError('bad\n' + 'x' * 300))
    node.lost_message(ValueError('again'))
    said = 'a message rclpy could not convert: bad ' + 'x' * 196 + '... (304 characters)'
    assert node._internal_errors == errors + 2
    assert node.logger.lines == [('error', said)]
    assert node._last_rejection == 'a message rclpy could not convert: again'


def test_a_failure_in_a_callback_is_counted_said_as_an_error_and_cut(node):
    """Count each failure; say it at error level, its text cut to 200 characters."""
    def boom():
        raise ValueError('y' * 300)
    node.logger.lines.clear()
    node.clock.ns += 2 * 10**9
    errors = node._internal_errors
    node._guarded(boom)()
    assert node._internal_errors == errors + 1 > 1
    said = 'internal error in boom: ValueError: ' + 'y' * 200 + '... (300 characters)'
    assert node._last_rejection == said
    assert node.logger.lines == [('error', said)]


def test_a_rejection_is_cut_to_150_characters_in_the_headline_and_said_in_full(node):
    """Keep a reason of 150 characters; cut a longer one; log each once a second, in full."""
    node.logger.lines.clear()
    node.clock.ns += 2 * 10**9
    node._reject('z' * 150)
    assert node._last_rejection == 'z' * 150
    node.clock.ns += 10**9                      # THROTTLE_S exactly: said again
    node._reject('z' * 151)
    assert node._last_rejection == 'z' * 150 + '... (151 characters)'
    assert node.logger.lines == [('warning', 'rejected ' + 'z' * 150),
                                 ('warning', 'rejected ' + 'z' * 151)]


def test_a_joint_state_without_the_joint_names_what_it_has_cut_or_none(node):
    """Name the joints it has, cut to 60 characters, or 'no joint'."""
    names = ['a' * 40, 'b' * 40]
    for given, shown in ((names, "'" + 'a' * 40 + "', '" + 'b' * 15 + '... (86 characters)'),
                         ([], 'no joint')):
        msg = JointState(name=given, position=[0.0] * len(given),
                         velocity=[0.0] * len(given))
        node._on_joint_states(serialize_message(msg))
        assert node._last_rejection == (f"/joint_states without joint 'spin' (it names "
                                        f'{shown}): set joint_name')
    try:                                            # what Python says, cut at 100
        struct.unpack_from('<I', bytes(5), 12)
    except struct.error as error:
        said = str(error)
    assert len(said) > 100
    reason = f'joint_states message not readable as JointState: {said[:100]}... ' \
        f'({len(said)} characters)'
    node._on_joint_states(b'\x00\x01\x00\x00\x00')
    assert node._last_rejection == reason[:150] + f'... ({len(reason)} characters)'


def test_a_layout_waits_for_the_poll_timer_when_no_sample_comes(node):
    """Poll every 10 ms; the timer's callback puts the layout in force, then goes."""
    node._take_prepared()                        # nothing prepared: nothing happens
    assert node._layout_poll is None
    node._on_layout(String(data=json.dumps(dict(DRUM, name='polled'))))
    poll = node._layout_poll
    assert poll.timer_period_ns == 10_000_000
    node._preparing.result()
    poll.callback()
    assert node._active.layout.name == 'polled'
    assert node._layout_poll is None and poll not in node.timers


def test_a_plane_without_a_correction_radius_says_so(node):
    """Say 'none (no correction radius)' for a rotor of point masses on its axis."""
    layout = dict(DRUM, name='points', balancing={'grade': 6.3, 'service_speed': 10.0})
    layout['components'] = [{'name': 'hub', 'mass': 10.0, 'radius': 0.0, 'angle_deg': 0.0}]
    node._on_layout(String(data=json.dumps(layout)))
    node._preparing.result()
    node._take_prepared()
    _, values = diagnostics(node)['rotor balance']
    assert values['plane I correction mass [g]'] == values['plane II correction mass [g]'] == \
        'none (no correction radius)'


def graph_shows(node, check):
    """Wait (up to 2 s) until the ROS graph, seen from ``node``, passes ``check``."""
    for _ in range(200):
        if check():
            return
        time.sleep(0.01)
    raise AssertionError('the graph did not change in 2 s')


def test_where_samples_are_awaited_names_the_publishers_seen(node):
    """Name where JointState is published instead (three, the first to remap to)."""
    other = Node('elsewhere', context=node.context)
    try:
        for name in ('/d/joints', '/a/joints', '/c/joints', '/b/joints'):
            other.create_publisher(JointState, name, 1)
        graph_shows(node, lambda: len([n for n, types in node.get_topic_names_and_types()
                                       if n.endswith('/joints')]) == 4)
        assert node._motion_topics() == (
            '/joint_states, /speed or the keyphasor /tach, where nothing publishes; '
            'JointState is published on /a/joints, /b/joints, /c/joints: remap with '
            '-r joint_states:=/a/joints')
        tach = other.create_publisher(Float64, '/tach', 1)
        graph_shows(node, lambda: node.count_publishers('/tach') == 1)
        assert node._motion_topics() == '/joint_states, /speed or the keyphasor /tach'
        other.destroy_publisher(tach)
        other.create_publisher(WrenchStamped, '/supports/front/measured_load', 1)
        other.create_publisher(Float64, '/speed', 1)
        graph_shows(node, lambda: node.count_publishers('/tach') == 0 and
                    node.count_publishers('/speed') == 1)
        assert node._motion_topics() == '/joint_states, /speed or the keyphasor /tach'
        assert node._recorder.subscription('/supports/front/measured_load') is None
        node._recorder.discover()                    # its timer's work: the cells recorded
        assert node._recorder.subscription('/supports/front/measured_load') is not None
    finally:
        other.destroy_node()


def test_a_position_in_degrees_is_said_as_an_input_mistake(node):
    """Say a joint position 57.3 times its velocity's rate once, as a warning."""
    node.logger.lines.clear()
    node._checks.restart()
    for j in range(1, 401):             # 2.5 turns: it wraps at 360
        node.clock.ns += 2_000_000
        stamp = node.clock.ns - LINE_NS + 50 * 10**9      # the line moved to above
        node._on_joint_states(joint_states(stamp, math.degrees(OMEGA * j / RATE) % 360.0,
                                           OMEGA))
    node._reported_level = node._reported_measured = None
    status, values = diagnostics(node)['input checks']
    assert status.level == DiagnosticStatus.WARN
    assert float(values['joint position rate / velocity']) == pytest.approx(
        180 / math.pi, rel=1e-6)
    warned = [line for line in node.logger.lines if 'input mistake?' in line[1]]
    assert warned == [('warning', f'input mistake? {status.message}')]
    diagnostics(node)
    assert len([line for line in node.logger.lines if 'input mistake?' in line[1]]) == 1


def test_a_node_that_does_not_record_counts_life_since_start_and_judges_at_its_grade(
        node, tmp_path):
    """
    Judge at balance_grade; count the bearings' life since start only; a tach's threshold.

    The diagnostics timer's callback publishes; a layout put in force later restarts the
    wait for samples; one rclpy cannot subscribe for is refused; a byte not UTF-8 in a
    comment is no matter; the implausible said.
    """
    layout = dict(DRUM, name='served', balancing={'grade': 6.3, 'service_speed': 10.0})
    path = tmp_path / 'served.yaml'
    path.write_text(yaml.safe_dump(layout))
    other = BalanceMonitor(context=node.context, parameter_overrides=[
        Parameter('layout_file', value=str(path)), Parameter('balance_grade', value=16.0),
        Parameter('keyphasor_topic', value='tach'), Parameter('diagnostics_period', value=0.5)])
    other.published = node.published
    try:
        assert other._keyphasor.threshold is None
        statuses = diagnostics(other)
        status, _ = statuses['rotor balance']
        assert status.message == ('G 0 at the service speed 10 rad/s: WITHIN G 16 (from the '
                                  'layout: no load cells)')
        assert statuses['bearing life'][1]['state file'] == \
            'none (the node does not record: counted since start)'
        (timer,) = [t for t in other.timers if t.timer_period_ns == 500_000_000]
        node.published.clear()
        timer.callback()
        assert [topic for topic, _ in node.published] == ['/diagnostics']
        assert other._internal_errors == 0
        node.clock.ns += 5 * 10**9                   # no sample yet: the wait starts again
        odd = dict(layout, name='odd', components=[
            dict(DRUM['components'][0]),
            {'name': 'lump', 'mass': 1.0, 'radius': 0.5, 'angle': 10.0}])
        path.write_bytes(b'# caf\xe9\n' + yaml.safe_dump(odd).encode())
        node.logger.lines.clear()
        other._apply_layout_file(path)
        assert other._active.layout.name == 'odd'
        assert node.logger.lines[1] == (
            'warning', "layout 'odd': implausible? component 'lump': angle 10 rad (572.958 "
            'deg) is more than a full turn: degrees in the radians field? (angle_deg takes '
            'degrees)')
        status, _ = diagnostics(other)['rotor balance']
        assert status.level == DiagnosticStatus.WARN            # not STALE
        with mock.patch.object(balance_monitor, 'LoadCells', side_effect=RuntimeError('no')):
            other._apply_layout_file(path)
        assert other._layout_error == f'{path}: RuntimeError: no'
        assert other._active.layout.name == 'odd'
    finally:
        gate = threading.Event()                     # a parse under way: not waited for
        other._layout_worker.submit(gate.wait, 1.0)
        started = time.monotonic()
        other.destroy_node()
        took = time.monotonic() - started
        gate.set()
    assert took < 0.5


def test_a_layout_file_over_the_limit_is_refused_by_its_size(node, monkeypatch):
    """
    Read one byte past the limit, so that the parser can say the file is over it.

    The limit (256 MiB) scaled down to 2000 bytes, in the node and in the parser; the
    file 2500 bytes of JSON.
    """
    monkeypatch.setattr(balance_monitor, 'MAX_TEXT_BYTES', 2000)
    monkeypatch.setattr(layout_file, 'MAX_TEXT_BYTES', 2000)
    big = node.folder / 'big.json'
    big.write_text(json.dumps(DRUM).ljust(2500))
    node._apply_layout_file(big)
    assert node._layout_error == (f'{big}: layout text of 2001 bytes is over the limit of '
                                  '2000 bytes')


def test_a_stamp_with_nanoseconds_over_a_second_is_rejected_in_words(node):
    """Reject a stamp whose nanosec is 10^9 or more, though its time would be on the line."""
    rejected = node._counts['rejected']
    node.clock.ns += 2_000_000
    sec = (node.clock.ns - LINE_NS + 50 * 10**9) // 10**9 - 1
    msg = JointState(name=['spin'], position=[0.0], velocity=[OMEGA])
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, 1_000_000_000
    node._on_joint_states(serialize_message(msg))
    assert node._counts['rejected'] == rejected + 1
    assert node._last_rejection == (f'motion sample: stamp nanosec 1000000000 not below '
                                    f'10^9 (sec {sec})')


class Stream:
    """The standard output in the test: what is written and when it is flushed."""

    def __init__(self):
        self.calls = []

    def write(self, text):
        self.calls.append(('write', text))

    def flush(self):
        self.calls.append(('flush', ''))


def test_the_end_says_the_counts_and_finishes_the_recording_the_life_and_the_view(
        node, turned):
    """
    Print the counts; close the bag (read back by the mcap library); save; finish rerun.

    The bag: labelled and named for its machine, the layouts put in force from files as
    the files say them, each output as published.
    """
    stamps, out = turned
    cells = cell_callbacks(node)
    for k in range(3):
        node.clock.ns += 2_000_000
        stamp = node.clock.ns - LINE_NS + 50 * 10**9      # the line the last test moved to
        node._on_joint_states(joint_states(stamp, 0.04 * k, OMEGA))
        cells['/supports/rear/measured_load'](wrench(*divmod(stamp, 10**9), (0.0, -2e3, 0.0)))
    cells['/supports/front/measured_load'](b'\x00\x01\x00\x00' + bytes(8))
    counts = dict(node._counts)
    stream = Stream()
    node.destroyed = True
    with mock.patch('sys.stdout', stream):
        node.destroy_node()
    printed = ''.join(text for _, text in stream.calls).splitlines()
    assert stream.calls == [call for line in printed for call in (
        ('write', line), ('write', '\n'), ('flush', ''))]      # each line flushed at once
    assert printed == [
        'balance_monitor: motion samples: ' + ', '.join(
            f'{counts[name]} {name}' for name in ('accepted', 'rejected', 'dropped')),
        'balance_monitor: keyphasor /tach: 0 marks, 0 missed (put back), 0 doubled '
        '(dropped), 0 irregular periods (no angle there), 0 revolutions',
        'balance_monitor: load cell readings (layout in force): 0 front, 3 rear, 1 dropped']
    assert node.rerun.calls[-1] == ('finish',) and node._rerun is None
    assert node._recorder is None and node._layout_worker._shutdown
    with open(node.folder / 'run.mcap', 'rb') as stream:
        reader = make_reader(stream)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = {}
        for _, channel, message in reader.iter_messages():
            messages.setdefault(channel.topic, []).append(message.data)
    assert metadata['cvc_balance'] == {'machine_id': 'M8', 'run': 'trial',
                                       'trial': 'I:0.2@0.0,0.68'}
    layouts = [deserialize_message(data, String).data for data in messages['/layout']]
    assert layouts == [node.layout_file.read_text(),
                       (node.folder / 'again.yaml').read_text()]
    for topic in ('/bearing_load', '/supports/front/load', '/supports/rear/load',
                  '/unbalance', '/drive_torque', '/identified_unbalance',
                  '/unbalance_residual'):
        assert messages[topic][:len(out[topic])] == [bytes(d) for d in out[topic]], topic
    assert len(messages['/bearing_load']) == counts['accepted'] == len(stamps) + 404
    assert json.loads((node.folder / 'bearing_life_M8.json').read_text())['supports'][
        'front']['revolutions'] > 2.0
