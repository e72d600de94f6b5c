"""
Bundled bags played live through the node give the offline replay's outputs, sample by sample.

The node runs as its own process; ``cvc-balance play`` publishes the bag's layouts and
joint states with their timing and records the node's outputs. Both bags are compared with
``cvc-balance replay`` of the same bag, to 4e-15 of each output's peak over the run
(measured 5.1e-16; unbalance: equal), 2e-12 for the drive torque (2.7e-13: its alpha goes
through two implementations of the estimator). The live outputs are also checked against
Pinocchio's RNEA of the layout in force (the bag's own /layout messages), at the alpha the
node's drive torque implies: replay and node could share a mistake, Pinocchio does not.
"""

import math
import re
from pathlib import Path
import signal
import subprocess
import sys

import numpy as np
import pytest

from rosbags.highlevel import AnyReader

from cvc_balance.bag.mcap_reader import Bag, wrench_samples
from cvc_balance.bag.replay import replay
from ros_harness import NodeProcess, ros_environment

ROOT = Path(__file__).resolve().parents[1]
WRENCH = 'geometry_msgs/msg/WrenchStamped'


def outputs(path):
    bag = Bag(path)
    result = {}
    for channel in bag.channels.values():
        if channel.msg_type == WRENCH:
            stamps, force, torque = wrench_samples(bag, channel)
            result[channel.topic] = (stamps, np.hstack([force, torque]))
    return result


def played(bag, tmp_path, extra=()):
    """Play ``bag`` into a node process (ROS arguments ``extra``); return (its log, live bag)."""
    node = NodeProcess('cvc_balance.ros.balance_monitor', list(extra), tmp_path / 'node.log')
    live = tmp_path / 'live.mcap'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play', str(bag), '-o',
                          str(live), '--wait', '60'], env=ros_environment(),
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    assert node.stop(signal.SIGINT) == 0
    return node.log(), live


def assert_rigid_body_outputs(bag, live):
    """
    Compare the live outputs with Pinocchio's RNEA of the layout in force (independent.py).

    The node estimates alpha from the encoder; the loads are linear in it. So per sample
    alpha is taken from the node's drive torque, tau = tau(q, omega, 0) + I alpha with
    tau(0) and I = tau(1) - tau(0) by Pinocchio; the bearing and support loads must then
    be Pinocchio's at that alpha, and the unbalance Pinocchio's at omega (alpha-free).
    Returns (each topic's largest deviation over its peak, alphas).
    """
    from independent import PinocchioRotor
    import yaml
    layouts, motion, got = [], {}, {}
    with AnyReader([bag]) as reader:
        for connection, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == '/layout':
                layouts.append((log_time, PinocchioRotor(yaml.safe_load(msg.data))))
            elif connection.topic == '/joint_states':
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                motion[stamp] = (log_time, float(msg.position[0]), float(msg.velocity[0]))
    with AnyReader([live]) as reader:
        for connection, _, raw in reader.messages():
            if connection.msgtype != WRENCH:
                continue
            msg = reader.deserialize(raw, connection.msgtype)
            w = msg.wrench
            got.setdefault(connection.topic, {})[
                msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = np.array(
                [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z])
    expected, alphas = {}, {}
    for stamp, torque in got['/drive_torque'].items():
        log_time, q, omega = motion[stamp]
        rotor = [r for t, r in layouts if t <= log_time][-1]
        at_rest, at_one = rotor.loads(q, omega, 0.0), rotor.loads(q, omega, 1.0)
        alpha = (torque[5] - at_rest['drive_torque']) \
            / (at_one['drive_torque'] - at_rest['drive_torque'])
        alphas[stamp] = alpha
        ref = {key: np.asarray(at_rest[key]) + alpha * (np.asarray(at_one[key])
                                                        - np.asarray(at_rest[key]))
               for key in ('force', 'moment')}
        expected.setdefault('/bearing_load', {})[stamp] = np.hstack([ref['force'],
                                                                     ref['moment']])
        for name in at_rest['supports']:
            load = [np.asarray(a) + alpha * (np.asarray(b) - np.asarray(a))
                    for a, b in zip(at_rest['supports'][name], at_one['supports'][name])]
            expected.setdefault(f'/supports/{name}/load', {})[stamp] = np.hstack(load)
        expected.setdefault('/unbalance', {})[stamp] = np.hstack(rotor.unbalance(omega))
    deviation = {}
    for topic, reference in expected.items():
        assert sorted(got[topic]) == sorted(reference), topic
        mine = np.array([got[topic][s] for s in sorted(reference)])
        theirs = np.array([reference[s] for s in sorted(reference)])
        deviation[topic] = float(np.abs(mine - theirs).max() / np.abs(theirs).max())
    return deviation, alphas


def assert_same_outputs(got, expected):
    """Every output once, equal to 4e-15 of its peak (the drive torque 2e-12)."""
    assert got.keys() == expected.keys()
    for topic, (stamps, values) in expected.items():
        live_stamps, live_values = got[topic]
        assert np.array_equal(np.sort(live_stamps), stamps), topic    # every sample, once
        order = np.argsort(live_stamps)
        scale = np.abs(values).max()
        bound = 2e-12 if topic == '/drive_torque' else 4e-15
        assert np.abs(live_values[order] - values).max() <= bound * scale, topic


@pytest.mark.parametrize('name, record', [('spin_up_tube_swap', False), ('tilted_shift', True)])
def test_live_and_offline_replay_agree(name, record, tmp_path):
    bag = ROOT / 'bags' / f'{name}.mcap'
    extra = ['-p', f'record_path:={tmp_path / "node.mcap"}'] if record else []
    log, live = played(bag, tmp_path, extra)
    offline = tmp_path / 'offline.mcap'
    summary = replay(bag, offline)
    assert f'{summary.accepted} accepted, 0 rejected, 0 dropped' in log, log
    assert not Bag(live).problems          # the recorder finalised the file on SIGINT
    by_rosbags = {}
    with AnyReader([live]) as reader:     # an independent reader, every message
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            by_rosbags.setdefault(connection.topic, []).append(
                msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
    assert by_rosbags.pop('/diagnostics')       # play -o records the node's verdicts too
    got, expected = outputs(live), outputs(offline)
    assert {t: sorted(s) for t, s in by_rosbags.items()} == \
        {t: sorted(s.tolist()) for t, (s, _) in got.items()}
    assert_same_outputs(got, expected)
    # And against Pinocchio (measured: loads 7.1e-15 of their peak, unbalance 7.3e-14).
    deviation, _ = assert_rigid_body_outputs(bag, live)
    for topic, value in deviation.items():
        assert value <= (2e-13 if topic == '/unbalance' else 2e-14), (topic, value)
    if record:
        recorded = Bag(tmp_path / 'node.mcap')
        assert not recorded.problems       # the node finalised its recording on SIGINT
        with AnyReader([tmp_path / 'node.mcap']) as reader:
            counts = {}
            for connection, _, raw in reader.messages():
                reader.deserialize(raw, connection.msgtype)
                counts[connection.topic] = counts.get(connection.topic, 0) + 1
        assert counts['/bearing_load'] == counts['/joint_states'] == summary.accepted
        topics = recorded.topics()
        for topic in ('/joint_states', '/layout', '/bearing_load', '/diagnostics',
                      '/supports/front/load'):
            assert topic in topics
        stamps, _ = outputs(tmp_path / 'node.mcap')['/bearing_load']
        assert len(stamps) == summary.accepted


DRUM = {'name': 'drum', 'gravity': [0.0, -9.80665, 0.0],
        'components': [{'name': 'drum', 'mass': 300.0, 'radius': 0.0, 'angle': 0.0},
                       {'name': 'lump', 'mass': 2.0, 'radius': 0.6, 'angle_deg': 200.0,
                        'z': 0.1}],
        'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.3, 'axial': True}]}


def hostile_time_line_bag(path):
    """
    Write a bag of 400 good samples at 500 Hz and 4 bad stamps; return the good stamps (ns).

    Stamps 1.7e9 s on, log times 3 s before them. First a sample stamped 0; after the
    100th good one a stamp of nanosec 4294967295 (sec 4 s early: as one number 0.095 s
    after the good one); after the 200th two samples stamped 11.6 days ahead, 1 ms
    apart (they agree); after the 300th a pause of 1.5 s (more than max_stamp_jump), the
    stamps advancing as the log times do.
    """
    import yaml
    from independent import TYPESTORE
    from cvc_balance.bag.mcap_writer import BagWriter
    joint_type, string_type = 'sensor_msgs/msg/JointState', 'std_msgs/msg/String'
    state, header = TYPESTORE.types[joint_type], TYPESTORE.types['std_msgs/msg/Header']
    stamp_type = TYPESTORE.types['builtin_interfaces/msg/Time']
    start, lead = 1_700_000_000 * 10**9, 3 * 10**9
    events, good = [], []         # (log ns, sec, nanosec, angle, omega)
    for k in range(400):
        ns = start + k * 2_000_000 + (1_500_000_000 if k >= 300 else 0)
        good.append(ns)
        omega = 20.0 + 0.5 * k * 0.002
        events.append((ns - lead, ns // 10**9, ns % 10**9, math.remainder(0.02 * k, 2 * math.pi),
                       omega))
        if k == 100:
            events.append((ns - lead + 500_000, ns // 10**9 - 4, 4294967295, 0.0, omega))
        if k == 200:
            far = ns + int(11.6 * 86400e9)
            events += [(ns - lead + 300_000, far // 10**9, far % 10**9, 0.0, omega),
                       (ns - lead + 600_000, far // 10**9, far % 10**9 + 1_000_000, 0.0, omega)]
    events.insert(0, (start - lead - 1_000_000, 0, 0, 0.0, 20.0))
    with BagWriter(path, chunk_bytes=8192) as writer:
        layout = writer.add_channel('/layout', string_type, latched=True)
        writer.write(layout, start - lead - 50_000_000, TYPESTORE.serialize_cdr(
            TYPESTORE.types[string_type](data=yaml.safe_dump(DRUM)), string_type).tobytes())
        joints = writer.add_channel('/joint_states', joint_type, best_effort=True)
        for log, sec, nanosec, q, w in events:
            msg = state(header=header(stamp=stamp_type(sec=sec, nanosec=nanosec), frame_id=''),
                        name=['gantry_joint'], position=np.array([q]), velocity=np.array([w]),
                        effort=np.array([], dtype=float))
            writer.write(joints, log, TYPESTORE.serialize_cdr(msg, joint_type).tobytes())
    return good


def test_bad_stamps_and_a_pause_are_judged_alike_live_and_offline(tmp_path):
    """
    Stamp 0, nanosec 4294967295, a far-future pair and a pause of 1.5 s, played live.

    The node answers exactly the 400 good samples, each once and stamped as sent (none
    stamped 0, 11.6 days ahead or with nanosec beyond 10^9; the sample after the pause
    kept), and refuses the 4 others; the offline replay of the bag (log times as the
    receive clock) decides the same, sample for sample, with the same outputs.
    """
    bag = tmp_path / 'hostile.mcap'
    good = hostile_time_line_bag(bag)
    log, live = played(bag, tmp_path)
    assert 'motion samples: 400 accepted, 4 rejected, 0 dropped' in log, log
    summary = replay(bag, tmp_path / 'offline.mcap')
    assert (summary.accepted, summary.rejected) == (400, 4)
    got, expected = outputs(live), outputs(tmp_path / 'offline.mcap')
    assert got.keys() == expected.keys() == {'/bearing_load', '/unbalance', '/drive_torque',
                                             '/supports/front/load', '/supports/rear/load'}
    for topic, (stamps, _) in expected.items():
        assert stamps.tolist() == good, topic
    assert_same_outputs(got, expected)


def slow_shift_bag(path, points=20_000):
    """
    Write tilted_shift with its last layout (the counterweight's slip) slow to parse.

    The layout gets ``points`` point masses of a gram more: about 1.5 s to parse here,
    three times the bag's 0.5 s left after it. Returns the path.
    """
    import yaml
    from cvc_balance.bag.mcap_writer import BagWriter
    from cvc_balance.messages.cdr import read_string_message, string_message
    from tach_bags import copy_channels
    source = ROOT / 'bags' / 'tilted_shift.mcap'
    bag = Bag(source)
    layouts = bag.messages(bag.channel('/layout', 'std_msgs/msg/String'))
    shifted = yaml.safe_load(read_string_message(layouts[-1][1]))
    shifted['components'] += [{'name': f'gram_{i}', 'mass': 1e-3, 'radius': 0.5,
                               'angle': (i * 2.399963) % 6.283, 'z': (i % 11 - 5) * 0.01}
                              for i in range(points)]
    layouts[-1] = (layouts[-1][0], string_message(yaml.safe_dump(shifted)))
    with BagWriter(path) as writer:
        copy_channels(writer, source, leave_out=('/layout',))
        channel = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        for log_time, data in layouts:
            writer.write(channel, log_time, data)
    return path


def test_a_slow_layout_and_a_stalled_player_change_no_output(tmp_path):
    """
    A layout slow to parse and a player stopped for 1.5 s: live still equals replay.

    play waits until the node has each layout in force (before: 50 ms, and the node
    computed the samples meanwhile with the old layout: 99.6 N apart on /bearing_load,
    seen under load). A player descheduled goes on from where it is (before: it sent the
    1500 late samples at once, more than the node's input queue of 1000 holds).
    """
    bag = slow_shift_bag(tmp_path / 'slow_shift.mcap')
    node = NodeProcess('cvc_balance.ros.balance_monitor', [], tmp_path / 'node.log')
    live = tmp_path / 'live.mcap'
    player = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'play', str(bag), '-o',
                               str(live), '--wait', '60'], env=ros_environment(),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    from geometry_msgs.msg import WrenchStamped
    from ros_harness import Probe
    probe = Probe('stall_probe')
    try:           # a second into the samples (the node answers them), stop the player
        answers = probe.record(WrenchStamped, 'bearing_load')
        assert probe.spin_until(lambda: len(answers) > 0, timeout=60.0), node.log()
        probe.spin_for(1.0)
        player.send_signal(signal.SIGSTOP)
        probe.spin_for(1.5)
        player.send_signal(signal.SIGCONT)
    finally:
        probe.close()
    said, err = player.communicate(timeout=180)
    assert player.returncode == 0, err
    assert node.stop(signal.SIGINT) == 0
    behind = re.search(r"^play: fell behind the bag's pace \d+ times? \(a busy machine\?\): "
                       r'paused (\d+\.\d+) s in all', said, re.M)
    assert behind and float(behind[1]) >= 1.4, said
    summary = replay(bag, tmp_path / 'offline.mcap')
    assert f'{summary.accepted} accepted, 0 rejected, 0 dropped' in node.log(), node.log()
    assert_same_outputs(outputs(live), outputs(tmp_path / 'offline.mcap'))
