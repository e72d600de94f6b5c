"""
Foreign bags and rosbag2 directories live: play through the node, record to a directory.

A run split over three MCAP files by rosbags' rosbag2 writer, under the namespace /gantry, is
played (``--joint-states``, ``--layout``) into the node running as its own process, and the
node's outputs are recorded to a rosbag2 directory; every output message, by stamp, must equal
the offline replay of the same directory, read back by the mcap library's reader (CRCs
validated) and rosbags' rosbag2 reader.
"""

from pathlib import Path
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
import numpy as np
from rosbags.rosbag2 import Reader as Rosbag2Reader

from cvc_balance.bag.mcap_reader import joint_samples
from cvc_balance.bag.replay import replay
from cvc_balance.bag.rosbag2 import open_bag
from ros_harness import NodeProcess, Probe, ros_environment
from test_foreign_bags import make_run, read_outputs, write_split

CLI = [sys.executable, '-m', 'cvc_balance.cli']


def test_play_a_split_namespaced_directory_through_the_node(tmp_path):
    run = make_run(prefix='/gantry')
    bag = tmp_path / 'split'
    write_split(bag, run)
    own = tmp_path / 'node_run'                   # the node's own recording, a directory too
    node = NodeProcess('cvc_balance.ros.balance_monitor', ['-p', f'record_path:={own}'],
                       tmp_path / 'node.log')
    live = tmp_path / 'live'                      # recorded as a rosbag2 directory
    played = subprocess.run(CLI + ['play', str(bag), '--joint-states', '/gantry/joint_states',
                                   '--layout-topic', '/gantry/layout', '-o', str(live)],
                            env=ros_environment(), capture_output=True, text=True, timeout=120)
    assert played.returncode == 0, played.stderr
    assert node.stop(signal.SIGINT) == 0
    summary = replay(bag, tmp_path / 'offline.mcap', names=None)
    assert f'{summary.accepted} accepted, 0 rejected, 0 dropped' in node.log(), node.log()
    assert (live / 'metadata.yaml').is_file()
    with Rosbag2Reader(live) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    got, expected = read_outputs(live), read_outputs(tmp_path / 'offline.mcap')
    assert got.keys() == expected.keys()
    for topic, (stamps, values) in expected.items():
        assert counts[topic] == len(stamps) == summary.accepted
        assert np.array_equal(got[topic][0], stamps), topic       # every sample, once
        scale = np.abs(values).max()
        # Measured 2.3e-13 (drive torque: alpha by two estimator implementations).
        assert np.abs(got[topic][1] - values).max() <= 1e-12 * scale, topic
    recorded = read_outputs(own)                  # the mcap library's reader, CRCs validated
    with Rosbag2Reader(own) as reader:
        assert reader.message_count == sum(
            1 for _ in reader.messages())
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/joint_states'] == counts['/bearing_load'] == summary.accepted
    assert np.array_equal(recorded['/bearing_load'][0], expected['/bearing_load'][0])


def test_record_to_a_rosbag2_directory(tmp_path):
    """cvc-balance record -o DIR: metadata.yaml and DIR_0.mcap, read by three readers."""
    from sensor_msgs.msg import JointState
    out = tmp_path / 'recorded'
    recorder = subprocess.Popen(CLI + ['record', '-o', str(out), 'joint_states'],
                                env=ros_environment(), stdout=subprocess.PIPE, text=True)
    probe = Probe('record_probe')
    publisher = probe.publisher(JointState, 'joint_states', sensor=True)
    assert probe.spin_until(lambda: publisher.get_subscription_count() > 0, timeout=20)
    probe.spin_for(1.5)      # the recorder's side of the match may come later
    for i in range(500):
        msg = JointState(name=['gantry_joint'], position=[0.001 * i], velocity=[3.0])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 5, i * 1000
        publisher.publish(msg)
        time.sleep(0.002)
    probe.spin_for(0.5)
    recorder.send_signal(signal.SIGINT)
    report = recorder.communicate(timeout=30)[0]
    probe.close()
    assert recorder.returncode == 0, report
    assert sorted(p.name for p in out.iterdir()) == ['metadata.yaml', 'recorded_0.mcap']
    with open(out / 'recorded_0.mcap', 'rb') as stream:
        stamps = [message.log_time for _, _, message in
                  make_reader(stream, validate_crcs=True).iter_messages()]
    with Rosbag2Reader(out) as reader:
        assert reader.message_count == len(stamps) > 400   # best effort: a few may be lost
    bag = open_bag(out)
    motion = joint_samples(bag, bag.channel('joint_states', 'sensor_msgs/msg/JointState'),
                           'gantry_joint')
    assert len(motion.stamp) == len(stamps) and not bag.problems
    assert np.array_equal(motion.angle, 0.001 * ((motion.stamp - 5_000_000_000) // 1000))
    assert Path(out / 'metadata.yaml').read_text().count('name: /joint_states') == 1
