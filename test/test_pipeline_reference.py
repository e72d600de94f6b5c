"""
Whole pipelines against Pinocchio: offline replay, the rerun view and the live node.

The input is an exact motion, a spin-up ramp omega = omega_0 + alpha t (the alpha
estimator fits a line: exact from the second sample), with the layout changed twice
mid-run (a heavier tube, then a 20 deg tilt). Every output is compared with Pinocchio's
RNEA of the layout in force at the ramp's (q, omega, alpha), the support loads with its
load split by hand, the unbalance with Pinocchio's mass properties, the unbalance per
correction plane with ISO 21940-2's per-component formula. None of the expected values
comes from cvc_balance's physics.
"""

import copy
import math
from pathlib import Path
import signal
import subprocess
import sys

import numpy as np
import pytest
import yaml

from cvc_balance.bag.replay import replay
from independent import PinocchioRotor, ramp, read_outputs, tilted, write_input_bag

ROOT = Path(__file__).resolve().parents[1]
ALPHA = 3.0
BASE = {
    'name': 'pipeline_gantry', 'gravity': [0.0, -9.80665, 0.0],
    'components': [
        {'name': 'drum', 'mass': 250.0, 'radius': 0.0, 'angle': 0.0,
         'shape': {'type': 'tube', 'inner_radius': 0.62, 'outer_radius': 0.7, 'length': 0.4}},
        {'name': 'tube', 'mass': 60.0, 'radius': 0.55, 'angle_deg': 15.0, 'z': 0.06,
         'shape': {'type': 'cylinder', 'radius': 0.09, 'length': 0.35, 'axis': 'tangential'}},
        {'name': 'detector', 'mass': 90.0, 'radius': 0.5, 'angle_deg': 190.0, 'z': -0.04,
         'shape': {'type': 'box', 'size': [0.12, 0.8, 0.16]}},
        {'name': 'counterweight', 'mass': 20.0, 'radius': 0.6, 'angle_deg': 280.0, 'z': 0.1},
        {'name': 'product', 'mass': 5.0, 'radius': 0.4, 'angle_deg': 100.0,
         'inertia': {'ixx': 0.02, 'iyy': 0.03, 'izz': 0.025, 'ixy': 0.001, 'ixz': 0.004,
                     'iyz': -0.003}}],
    'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.35, 'axial': True}],
    'balancing': {'planes': [-0.2, 0.25], 'correction_radius': 0.65, 'grade': 6.3,
                  'service_speed': 23.27}}


def layouts():
    """Return the three layouts of the run and when (s from the start) each takes over."""
    heavier = copy.deepcopy(BASE)
    heavier['components'][1]['mass'] = 63.0
    tilted_run = copy.deepcopy(heavier)
    tilted_run['gravity'] = tilted(20.0)
    return [(0.0, BASE), (2.5, heavier), (5.0, tilted_run)]


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    """Make the input bag (an exact ramp, 8 s at 200 Hz); give per sample layout and motion."""
    folder = tmp_path_factory.mktemp('pipeline')
    stamps, angle, omega = ramp(0.5, ALPHA, rate=200.0, seconds=8.0)
    start = int(stamps[0])
    changes = [(start + int(at * 1e9) - 2_500_000, layout) for at, layout in layouts()]
    bag = write_input_bag(folder / 'in.mcap', stamps, angle, omega,
                          [(t, yaml.safe_dump(layout)) for t, layout in changes])
    rotors = [(t, PinocchioRotor(layout)) for t, layout in changes]
    alpha = np.full(len(stamps), ALPHA)
    alpha[0] = 0.0                           # the estimator's first sample: no slope yet
    in_force = [[r for t, r in rotors if t <= ns][-1] for ns in stamps.tolist()]
    return {'bag': bag, 'folder': folder, 'stamps': stamps, 'angle': angle, 'omega': omega,
            'alpha': alpha, 'rotor': in_force}


def expected_topics(rotor, q, omega, alpha):
    """{topic: [fx, fy, fz, tx, ty, tz]} of one sample, from Pinocchio and statics."""
    ref = rotor.loads(q, omega, alpha)
    out = {'/bearing_load': [*ref['force'], *ref['moment']],
           '/drive_torque': [0.0, 0.0, 0.0, 0.0, 0.0, ref['drive_torque']],
           '/unbalance': [*np.concatenate(rotor.unbalance(omega))]}
    for name, (force, moment) in ref['supports'].items():
        out[f'/supports/{name}/load'] = [*force, *moment]
    return out


def deviations(got, run):
    """Per topic: largest |got - Pinocchio| over the run / the topic's peak, and the count."""
    expected = {}
    for k, ns in enumerate(run['stamps'].tolist()):
        for topic, values in expected_topics(run['rotor'][k], run['angle'][k],
                                             run['omega'][k], run['alpha'][k]).items():
            expected.setdefault(topic, {})[ns] = values
    out = {}
    for topic, reference in expected.items():
        stamps = sorted(got.get(topic, {}))
        assert stamps == sorted(reference), topic        # every sample, nothing more
        mine = np.array([got[topic][ns] for ns in stamps])
        theirs = np.array([reference[ns] for ns in stamps])
        out[topic] = float(np.abs(mine - theirs).max() / np.abs(theirs).max())
    return out


def test_offline_replay_equals_pinocchio(run, tmp_path):
    """
    Every output of every sample, read back with rosbags.

    Measured, of each topic's peak: bearing load 1.6e-15, supports 1.4e-15 and 2.0e-15,
    unbalance 1.2e-15 (Pinocchio's rounding of a 425 kg rotor's sums), drive torque
    3.0e-13 (alpha estimated from the stamps: the estimator's rounding, 1e-13 of alpha).
    """
    summary = replay(run['bag'], tmp_path / 'out.mcap')
    assert summary.accepted == len(run['stamps']) and summary.rejected == 0
    assert len(summary.segments) == 3
    error = deviations(read_outputs(tmp_path / 'out.mcap'), run)
    assert set(error) == {'/bearing_load', '/drive_torque', '/unbalance',
                          '/supports/front/load', '/supports/rear/load'}
    for topic, bound in (('/bearing_load', 1e-14), ('/supports/front/load', 1e-14),
                         ('/supports/rear/load', 1e-14), ('/unbalance', 1e-14),
                         ('/drive_torque', 2e-12)):
        assert error[topic] <= bound, (topic, error[topic])


def per_component_planes(layout, z_i, z_ii):
    """ISO 21940-2's two-plane split summed per component (no own products here), kg m."""
    plane_1 = plane_2 = 0j
    for c in layout['components']:
        theta = c['angle'] if 'angle' in c else math.radians(c['angle_deg'])
        u = c['mass'] * c['radius'] * complex(math.cos(theta), math.sin(theta))
        z = c.get('z', 0.0)
        if 'inertia' in c:      # a given tensor's own xz, yz products: its couple
            u_couple = complex(-c['inertia']['ixz'], -c['inertia']['iyz']) * complex(
                math.cos(theta), math.sin(theta))
            plane_1 -= u_couple / (z_ii - z_i)
            plane_2 += u_couple / (z_ii - z_i)
        plane_1 += u * (z_ii - z) / (z_ii - z_i)
        plane_2 += u * (z - z_i) / (z_ii - z_i)
    return plane_1, plane_2


def read_rrd_scalars(path):
    """{entity path: {time ns: value}} of the scalar plots, by rerun's own reader."""
    from rerun.chunk import RrdReader
    out = {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        if 'time' not in batch.schema.names or 'Scalars:scalars' not in batch.schema.names:
            continue
        times = batch.column('time').cast('int64').to_numpy()
        values = [v[0] if v else math.nan for v in batch.column('Scalars:scalars').to_pylist()]
        out.setdefault(str(chunk.entity_path), {}).update(zip(times.tolist(), values))
    return out


def plane_fractions(layout):
    """
    Each correction plane's |U_i| / its permissible share, by hand (ISO 21940-11).

    U_per = G m / Omega at the layout's service speed; each plane's share is the lever of
    the other plane about the centre of mass, kept within 0.3-0.7 (the rule of
    shared/domain/FACTS.md).
    """
    z_i, z_ii = layout['balancing']['planes']
    mass = sum(c['mass'] for c in layout['components'])
    z_com = sum(c['mass'] * c.get('z', 0.0) for c in layout['components']) / mass
    u_per = layout['balancing']['grade'] * 1e-3 * mass / layout['balancing']['service_speed']
    shares = [min(max(lever, 0.3), 0.7)
              for lever in ((z_ii - z_com) / (z_ii - z_i), (z_com - z_i) / (z_ii - z_i))]
    return [abs(u) / (u_per * share)
            for u, share in zip(per_component_planes(layout, z_i, z_ii), shares)]


def test_rerun_view_plots_pinocchio_values(run, tmp_path):
    """
    ``cvc-balance view`` plots Pinocchio's values, every sample.

    Omega, alpha, drive torque, each support's static weight (Pinocchio's load at rest)
    and rotating amplitude (Pinocchio's load without gravity), and each correction
    plane's unbalance over its permissible share (ISO 21940-2 per component, ISO 21940-11
    by hand).

    Measured, of each plot's peak: omega 0, alpha 3.8e-13 (the estimator on a ramp),
    drive torque 3.0e-13, static weights 6.1e-16 and 5.7e-16, rotating amplitudes
    7.7e-16, plane fractions 7.0e-16 and 3.4e-16.
    """
    out = tmp_path / 'run.rrd'
    done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'view', str(run['bag']),
                           '-o', str(out)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    scalars = read_rrd_scalars(out)
    stamps = run['stamps'].tolist()
    expected = {'/plots/speed/omega': run['omega'], '/plots/speed/alpha': run['alpha']}
    rotors, angle = run['rotor'], run['angle']
    refs = [rotors[k].loads(angle[k], run['omega'][k], run['alpha'][k])
            for k in range(len(stamps))]
    at_rest = [rotors[k].loads(angle[k], 0.0, 0.0) for k in range(len(stamps))]
    no_gravity = [rotors[k].loads(angle[k], run['omega'][k], run['alpha'][k],
                                  gravity=[0.0, 0.0, 0.0]) for k in range(len(stamps))]
    expected['/plots/drive_torque'] = np.array([r['drive_torque'] for r in refs])
    for name in ('front', 'rear'):
        expected[f'/plots/load_static/{name}'] = np.array(
            [np.linalg.norm(r['supports'][name][0]) for r in at_rest])
        expected[f'/plots/load_rotating/{name}'] = np.array(
            [np.linalg.norm(r['supports'][name][0]) for r in no_gravity])
    fractions = np.array([plane_fractions(r.layout) for r in rotors])
    expected['/plots/unbalance/plane_I'] = fractions[:, 0]
    expected['/plots/unbalance/plane_II'] = fractions[:, 1]
    bounds = {'/plots/speed/omega': 0.0, '/plots/speed/alpha': 4e-12,
              '/plots/drive_torque': 2e-12}
    for path, values in expected.items():
        got = np.array([scalars[path][ns] for ns in stamps])
        error = np.abs(got - values).max() / max(np.abs(values).max(), 1e-300)
        assert error <= bounds.get(path, 1e-14), (path, error)


def test_live_node_outputs_equal_pinocchio(tmp_path):
    """
    The node as its own process fed the ramp (500 Hz, 1.2 s) with the tilted layout.

    Measured, of each topic's peak: loads 9e-16 to 2.0e-15, unbalance 1.2e-15, drive
    torque 1.1e-13.
    """
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from ros_harness import NodeProcess, Probe

    layout = layouts()[-1][1]
    layout_path = tmp_path / 'layout.yaml'
    layout_path.write_text(yaml.safe_dump(layout))
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', f'layout_file:={layout_path}', '-p', 'joint_name:=spin'],
                       tmp_path / 'node.log')
    probe = Probe('pipeline_probe')
    topics = ('bearing_load', 'unbalance', 'drive_torque', 'supports/front/load',
              'supports/rear/load')
    for topic in topics:
        probe.record(WrenchStamped, topic)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    try:
        assert probe.spin_until(lambda: joints.get_subscription_count() > 0
                                and probe.node.count_publishers('bearing_load') > 0,
                                timeout=20), node.log()
        probe.spin_for(1.5)          # DDS matching is one-sided: let the node's side match
        stamps, angle, omega = ramp(2.0, ALPHA, rate=500.0, seconds=1.2)
        for ns, q, w in zip(stamps.tolist(), angle, omega):
            msg = JointState(name=['spin'], position=[float(q)], velocity=[float(w)])
            msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
            joints.publish(msg)
            probe.spin_for(0.002)
        assert probe.spin_until(
            lambda: all(len(probe.received[t]) == len(stamps) for t in topics)), node.log()
    finally:
        probe.close()
        assert node.stop(signal.SIGINT) == 0
    got = {}
    for topic in topics:
        for msg in probe.received[topic]:
            w = msg.wrench
            got.setdefault(f'/{topic}', {})[msg.header.stamp.sec * 10**9
                                            + msg.header.stamp.nanosec] = [
                w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]
    alpha = np.full(len(stamps), ALPHA)
    alpha[0] = 0.0
    rotor = PinocchioRotor(layout)
    error = deviations(got, {'stamps': stamps, 'angle': angle, 'omega': omega,
                             'alpha': alpha, 'rotor': [rotor] * len(stamps)})
    for topic, value in error.items():
        assert value <= (2e-12 if topic == '/drive_torque' else 1e-14), (topic, value)
