"""
The balance_monitor node as its own process, driven by a probe node.

Every output topic is checked against Pinocchio's RNEA and mass properties, the
support loads against its load split by statics (test/independent.py; to 5e-11
relative), across a layout change mid-run, a rejected layout and bad messages
interleaved; the diagnostics go from OK to ERROR and back; a noisy encoder does not make
drive-torque spikes; SIGINT and SIGTERM end the node cleanly.
"""

import math
import random
import signal
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
import yaml

from cvc_balance.physics.layout_file import layout_from_text
from independent import PinocchioRotor
from reference import relative_error
from ros_harness import NodeProcess, Probe

TOLERANCE = 5e-11
"""Relative error of each output against Pinocchio: measured 2.7e-11 at most (the drive
torque, alpha estimated by the node on a ramp against the ramp's exact alpha); the loads
1.1e-14, the unbalance 2.2e-16."""
LAYOUT_A = {
    'name': 'layout_a', 'gravity': [0.0, -9.80665 * math.cos(0.3), 9.80665 * math.sin(0.3)],
    'components': [
        {'name': 'tube', 'mass': 60.0, 'radius': 0.62, 'angle_deg': 0.0, 'z': 0.05,
         'shape': {'type': 'cylinder', 'radius': 0.09, 'length': 0.35, 'axis': 'tangential'}},
        {'name': 'detector', 'mass': 110.0, 'radius': 0.58, 'angle_deg': 170.0, 'z': -0.04,
         'shape': {'type': 'box', 'size': [0.12, 0.9, 0.16]}},
        {'name': 'generator', 'mass': 120.0, 'radius': 0.55, 'angle_deg': 95.0, 'z': 0.1}],
    'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.25, 'axial': True}],
    'balancing': {'grade': 6.3}}
LAYOUT_B = {
    'name': 'layout_b', 'gravity': [0.0, -9.80665, 0.0],
    'components': [
        {'name': 'drum', 'mass': 400.0, 'radius': 0.0, 'angle': 0.0,
         'shape': {'type': 'tube', 'inner_radius': 0.7, 'outer_radius': 0.8, 'length': 0.3}},
        {'name': 'lump', 'mass': 5.0, 'radius': 0.7, 'angle': 2.0, 'z': 0.12}],
    'supports': [{'name': 'slewing', 'z': 0.03}]}
OUTPUTS = ('bearing_load', 'unbalance', 'drive_torque', 'supports/front/load',
           'supports/rear/load', 'supports/slewing/load')


def stamp_of(ns):
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def ns_of(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def joint_state(ns, angle, omega, joint='spin'):
    msg = JointState(name=['other', joint], position=[0.0, angle], velocity=[0.0, omega])
    msg.header.stamp = stamp_of(ns)
    return msg


def diagnostic_values(probe):
    arrays = probe.received['/diagnostics']
    if not arrays:
        return None, {}
    status = arrays[-1].status[0]
    return status, {kv.key: kv.value for kv in status.values}


def wait_for_diagnostics(probe, predicate, timeout=10.0):
    def seen():
        status, values = diagnostic_values(probe)
        return status is not None and predicate(status, values)
    return probe.spin_until(seen, timeout)


def expected_outputs(rotor, angle, omega, alpha):
    """Each output topic's (force, torque) for one sample, from Pinocchio (a PinocchioRotor)."""
    ref = rotor.loads(angle, omega, alpha)
    outputs = {'bearing_load': (ref['force'], ref['moment']),
               'unbalance': rotor.unbalance(omega),
               'drive_torque': ((0.0, 0.0, 0.0), (0.0, 0.0, ref['drive_torque']))}
    for name, load in ref['supports'].items():
        outputs[f'supports/{name}/load'] = load
    return outputs


def vector(v):
    return [v.x, v.y, v.z]


@pytest.fixture
def probe():
    probe = Probe()
    for topic in OUTPUTS:
        probe.record(WrenchStamped, topic)
    probe.record(DiagnosticArray, '/diagnostics')
    yield probe
    probe.close()


def start_node(tmp_path, layout, *extra, params=None):
    layout_path = tmp_path / 'layout.yaml'
    layout_path.write_text(yaml.safe_dump(layout))
    params_path = tmp_path / 'params.yaml'
    params_path.write_text(yaml.safe_dump({'balance_monitor': {'ros__parameters': {
        'joint_name': 'spin', 'stator_frame': 'gantry_base', 'diagnostics_period': 0.2,
        'layout_file': str(layout_path), **(params or {})}}}))
    return NodeProcess('cvc_balance.ros.balance_monitor',
                       ['--params-file', str(params_path), '-p', 'rotor_frame:=gantry_rotor',
                        *extra], tmp_path / 'node.log')


def wait_until_connected(probe, node, *topics):
    connected = probe.spin_until(
        lambda: all(probe.node.count_subscribers(t) >= 1 for t in topics)
        and probe.node.count_publishers('bearing_load') >= 1, timeout=20.0)
    assert connected, node.log()
    # DDS matching is one-sided: the node's reader may match the probe's writer later
    # than the probe sees the node (up to ~0.7 s seen here).
    probe.spin_for(1.5)


def test_outputs_match_the_engine_through_layout_change_and_bad_input(probe, tmp_path):
    node = start_node(tmp_path, LAYOUT_A)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    layouts = probe.publisher(String, 'layout', latched=True)
    wait_until_connected(probe, node, 'joint_states', 'layout')
    model_a, model_b = PinocchioRotor(LAYOUT_A), PinocchioRotor(LAYOUT_B)
    digest_b = layout_from_text(yaml.safe_dump(LAYOUT_B)).digest()
    alpha = 0.75
    start_ns, step_ns = 10_000_000_000, 2_000_000
    good = {}          # stamp ns -> (model, angle, omega, alpha)
    bad = 0
    last_good_ns = None

    def send(k, model, first=False):
        nonlocal last_good_ns
        ns = start_ns + k * step_ns
        omega = 20.0 + alpha * (k * step_ns * 1e-9)
        angle = math.remainder(0.37 + 20.0 * k * step_ns * 1e-9, 2 * math.pi)
        joints.publish(joint_state(ns, angle, omega))
        good[ns] = (model, angle, omega, 0.0 if first else alpha)
        last_good_ns = ns
        probe.spin_for(0.002)

    def send_bad(msg):
        nonlocal bad
        joints.publish(msg)
        bad += 1
        probe.spin_for(0.002)

    for k in range(150):
        send(k, model_a, first=(k == 0))
        if k == 20:
            send_bad(joint_state(start_ns + k * step_ns + 1, 0.0, math.nan))
        if k == 40:
            send_bad(joint_state(start_ns + k * step_ns + 1, 0.0, 3.0, joint='elsewhere'))
        if k == 60:
            empty = JointState(name=['spin'])
            empty.header.stamp = stamp_of(start_ns + k * step_ns + 1)
            send_bad(empty)
        if k == 80:
            send_bad(joint_state(last_good_ns - step_ns, 0.0, 20.0))     # backwards
        if k == 100:
            send_bad(joint_state(start_ns + k * step_ns + 1, 0.0, 1e5))   # absurd speed
        if k == 120:
            send_bad(joint_state(start_ns + k * step_ns + 1, math.inf, 20.0))
    assert probe.spin_until(lambda: len(probe.received['bearing_load']) == len(good)), \
        node.log()

    # A new layout, then one that must be rejected: B stays in force.
    layouts.publish(String(data=yaml.safe_dump(LAYOUT_B)))
    assert wait_for_diagnostics(probe, lambda s, v: v.get('layout digest') == digest_b), \
        node.log()
    broken = dict(LAYOUT_B, components=[dict(LAYOUT_B['components'][1], mass=-5.0)])
    layouts.publish(String(data=yaml.safe_dump(broken)))
    assert wait_for_diagnostics(probe, lambda s, v: "'lump'" in v.get('last rejected layout', '')
                                and 'mass' in v['last rejected layout']), node.log()
    for k in range(150, 300):
        send(k, model_b)
    assert probe.spin_until(lambda: len(probe.received['bearing_load']) == len(good)), \
        node.log()
    probe.spin_for(0.3)

    checked = 0
    for topic in OUTPUTS:
        for msg in probe.received[topic]:
            model, angle, omega, alpha_used = good[ns_of(msg.header.stamp)]
            expected = expected_outputs(model, angle, omega, alpha_used)[topic]
            got = (vector(msg.wrench.force), vector(msg.wrench.torque))
            assert relative_error(got, expected) < TOLERANCE, (topic, got, expected)
            frame = 'gantry_rotor' if topic in ('unbalance', 'drive_torque') else 'gantry_base'
            assert msg.header.frame_id == frame
            checked += 1
    counts = {topic: len(probe.received[topic]) for topic in OUTPUTS}
    assert counts == {'bearing_load': 300, 'unbalance': 300, 'drive_torque': 300,
                      'supports/front/load': 150, 'supports/rear/load': 150,
                      'supports/slewing/load': 150}
    assert checked == sum(counts.values())
    assert wait_for_diagnostics(probe, lambda s, v: v.get('accepted') == '300'
                                and v.get('rejected') == str(bad))
    assert node.stop(signal.SIGINT) == 0


HEAVY = {'name': 'heavy_lump', 'mass': 8.0, 'radius': 0.65, 'angle_deg': 40.0, 'z': 0.1}


def test_diagnostics_go_from_ok_to_error_and_back(probe, tmp_path):
    gantry = yaml.safe_load(open('config/ct_gantry.yaml'))
    node = start_node(tmp_path, gantry)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    layouts = probe.publisher(String, 'layout', latched=True)
    wait_until_connected(probe, node, 'joint_states', 'layout')
    clock = iter(range(1, 10**9))

    def stream(seconds, omega=23.27):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            joints.publish(joint_state(next(clock) * 5_000_000, 0.0, omega))
            probe.spin_for(0.005)

    def level_is(level):
        return lambda s, v: s.level == level and v.get('speed [rad/s]') == '23.27'

    stream(0.6)
    assert wait_for_diagnostics(probe, level_is(DiagnosticStatus.OK), timeout=2.0), node.log()
    layouts.publish(String(data=yaml.safe_dump(
        dict(gantry, components=gantry['components'] + [HEAVY]))))
    stream(0.8)
    assert wait_for_diagnostics(probe, level_is(DiagnosticStatus.ERROR), timeout=2.0)
    status, values = diagnostic_values(probe)
    assert float(values['achieved grade [mm/s]']) > 6.3
    assert 'OUT OF G 6.3' in status.message
    layouts.publish(String(data=yaml.safe_dump(gantry)))
    stream(0.8)
    assert wait_for_diagnostics(probe, level_is(DiagnosticStatus.OK), timeout=2.0)
    assert node.stop(signal.SIGTERM) == 0


def test_noisy_encoder_makes_no_drive_torque_spikes(probe, tmp_path):
    """Speed noise 0.01 rad/s at 500 Hz: raw differences would swing I_zz * 7 rad/s^2."""
    layout = dict(LAYOUT_A, gravity=[0.0, 0.0, 0.0])
    node = start_node(tmp_path, layout)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    wait_until_connected(probe, node, 'joint_states')
    rng = random.Random(2)
    sigma, dt = 0.01, 0.002
    for k in range(1000):
        joints.publish(joint_state(10**9 + k * 2_000_000, 0.0, 23.0 + rng.gauss(0.0, sigma)))
        probe.spin_for(0.002)
    assert probe.spin_until(lambda: len(probe.received['drive_torque']) >= 990), node.log()
    torque = np.array([m.wrench.torque.z for m in probe.received['drive_torque']])
    mass, com, inertia = PinocchioRotor(layout).mass_properties()
    i_zz = inertia[2, 2] + mass * (com[0] ** 2 + com[1] ** 2)      # about the axis
    raw_rms = i_zz * sigma * math.sqrt(2.0) / dt
    settled = torque[200:]          # past four time constants of 0.1 s
    assert np.sqrt(np.mean(settled**2)) < 0.01 * raw_rms
    assert np.abs(settled).max() < 0.05 * raw_rms
    assert node.stop(signal.SIGINT) == 0


def test_speed_only_input(probe, tmp_path):
    """Float64 speed: rotor-frame unbalance and the size of the bearing load, exactly."""
    layout = dict(LAYOUT_A, gravity=[0.0, 0.0, 0.0])
    node = start_node(tmp_path, layout)
    speeds = probe.publisher(Float64, 'speed', sensor=True)
    wait_until_connected(probe, node, 'speed')
    for k in range(50):
        speeds.publish(Float64(data=15.0))
        probe.spin_for(0.004)
    assert probe.spin_until(lambda: len(probe.received['unbalance']) == 50), node.log()
    expected = expected_outputs(PinocchioRotor(layout), 0.0, 15.0, 0.0)
    for msg in probe.received['unbalance']:
        got = (vector(msg.wrench.force), vector(msg.wrench.torque))
        assert relative_error(got, expected['unbalance']) < TOLERANCE
    size = np.linalg.norm(expected['bearing_load'][0])
    for msg in probe.received['bearing_load']:
        assert abs(np.linalg.norm(vector(msg.wrench.force)) - size) < TOLERANCE * size
    speeds.publish(Float64(data=math.nan))
    assert wait_for_diagnostics(probe, lambda s, v: v.get('rejected') == '1'
                                and 'speed' in v.get('last rejected input', ''))
    assert node.stop(signal.SIGTERM) == 0


def test_bad_layout_file_at_start_keeps_the_node_up(probe, tmp_path):
    broken = dict(LAYOUT_A, supports=[])
    node = start_node(tmp_path, broken)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    wait_until_connected(probe, node, 'joint_states')
    for k in range(5):
        joints.publish(joint_state(10**9 + k * 1_000_000, 0.0, 5.0))
        probe.spin_for(0.01)
    assert wait_for_diagnostics(probe, lambda s, v: s.message.startswith('no layout')
                                and v.get('dropped') == '5' and 'supports' in s.message)
    assert probe.received['bearing_load'] == []
    assert 'layout rejected' in node.log()
    assert node.stop(signal.SIGINT) == 0


@pytest.mark.parametrize('setting, word', [('alpha_time_constant:=-1.0', 'out of range'),
                                           ('max_speed:=fast', 'DOUBLE')])
def test_bad_parameter_gets_one_line_and_exit_code_2(setting, word, tmp_path):
    node = NodeProcess('cvc_balance.ros.balance_monitor', ['-p', setting], tmp_path / 'node.log')
    assert node.process.wait(30) == 2
    lines = node.log().strip().splitlines()
    assert len(lines) == 1 and word in lines[0] and 'Traceback' not in lines[0]
