"""
Bundled bags played live through the node give the offline replay's outputs, sample by sample.

The node runs as its own process; ``cvc-balance play`` publishes the bag's layouts and
joint states with their timing and records the node's outputs. Both bags are compared with
``cvc-balance replay`` of the same bag, to 4e-15 of each output's peak over the run
(measured 5.1e-16; unbalance: equal), 2e-12 for the drive torque (2.7e-13: its alpha goes
through two implementations of the estimator).
"""

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


@pytest.mark.parametrize('name, record', [('spin_up_tube_swap', False), ('tilted_shift', True)])
def test_live_and_offline_replay_agree(name, record, tmp_path):
    bag = ROOT / 'bags' / f'{name}.mcap'
    extra = ['-p', f'record_path:={tmp_path / "node.mcap"}'] if record else []
    node = NodeProcess('cvc_balance.ros.balance_monitor', extra, tmp_path / 'node.log')
    live = tmp_path / 'live.mcap'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play', str(bag), '-o',
                          str(live), '--wait', '60'], env=ros_environment(),
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    assert node.stop(signal.SIGINT) == 0
    log = node.log()
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
    assert got.keys() == expected.keys()
    for topic, (stamps, values) in expected.items():
        live_stamps, live_values = got[topic]
        assert np.array_equal(np.sort(live_stamps), stamps), topic    # every sample, once
        order = np.argsort(live_stamps)
        scale = np.abs(values).max()
        bound = 2e-12 if topic == '/drive_torque' else 4e-15
        assert np.abs(live_values[order] - values).max() <= bound * scale, topic
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
