"""
Bags, written by the project and read back by two independent readers.

Offline replay against Pinocchio (scenario_reference) and the scenarios' known
unbalance; damaged bags; a recorder killed with SIGKILL; rerun opening a bag.
"""

import dataclasses
import math
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader as make_mcap_reader
from mcap.stream_reader import StreamReader
from mcap_ros2.reader import read_ros2_messages
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.mcap_reader import Bag, BagError, joint_samples
from cvc_balance.bag.replay import replay
from cvc_balance.bag.scenario import load_scenario, write_bag
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.unbalance import static_unbalance
from in_process import cvc
from ros_harness import ros_environment
from scenario_reference import expected_outputs

ROOT = Path(__file__).resolve().parents[1]
AGAINST_PINOCCHIO = {'/drive_torque': 2e-12, '/unbalance': 4e-13}
"""Bounds of a replay's outputs against Pinocchio, of each topic's peak (others 4e-15), as
measured: loads 1.5e-15 at most, unbalance 1.3e-13 (Pinocchio's centre of mass, S / m, of a
near-balanced rotor), drive torque 2.8e-13 (alpha from two implementations of the estimator)."""
BUNDLED = sorted(bag.with_suffix('.yaml') for bag in (ROOT / 'bags').glob('*.mcap'))
"""Scenario files of the bundled bags (bags/X.mcap made from bags/X.yaml: ./dev.sh bags)."""
JOINT = 'sensor_msgs/msg/JointState'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
OUTPUTS = ('/bearing_load', '/unbalance', '/drive_torque')


def read_with_rosbags(path):
    """{topic: [(log time, decoded message)]}, by rosbags."""
    out = {}
    with AnyReader([Path(path)]) as reader:
        for connection, timestamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (timestamp, reader.deserialize(raw, connection.msgtype)))
    return out


def read_with_mcap_ros2(path):
    """{topic: [(log time, decoded message)]}, by mcap-ros2-support."""
    out = {}
    for message in read_ros2_messages(str(path)):
        out.setdefault(message.channel.topic, []).append((message.log_time_ns,
                                                          message.ros_msg))
    return out


def stamp_ns(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def wrench(msg):
    w = msg.wrench
    return [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]


def plain(value):
    """Return a decoded message (rosbags dataclasses, numpy arrays) as plain Python values."""
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def bag_contents(path):
    """Everything a reader sees of an MCAP file (the mcap library, CRCs checked; rosbags' CDR)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    with open(path, 'rb') as stream:
        reader = make_mcap_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        header = reader.get_header()
        metadata = [(m.name, m.metadata) for m in reader.iter_metadata()]
        messages = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            messages.setdefault(channel.topic, []).append(
                (message.log_time, message.publish_time, message.sequence,
                 plain(store.deserialize_cdr(message.data, schema.name))))
    return {'header': (header.profile, header.library),
            'schemas': sorted((s.name, s.encoding, s.data) for s in summary.schemas.values()),
            'channels': sorted((c.topic, c.message_encoding, summary.schemas[c.schema_id].name,
                                sorted(c.metadata.items())) for c in summary.channels.values()),
            'metadata': metadata, 'messages': messages}


@pytest.mark.parametrize('scenario_file', BUNDLED, ids=lambda p: p.stem)
def test_bundled_bags_decode_equal_to_a_fresh_simulation(scenario_file, tmp_path):
    """
    A bundled bag is what its scenario makes today (./dev.sh bags makes them again).

    Compared as readers see them, never byte for byte: schemas, channels with their
    metadata (QoS, type hash), Metadata records (rosbag2's), and every message decoded.
    """
    bag = scenario_file.with_suffix('.mcap')
    assert bag.stat().st_size < 2 * 1024 * 1024
    fresh = tmp_path / bag.name          # the same name: rosbag2's record lists the file
    run = cvc('simulate', scenario_file, '-o', fresh)     # in this process
    assert run.returncode == 0, run.stderr
    bundled, simulated = bag_contents(bag), bag_contents(fresh)
    for part in ('header', 'schemas', 'channels', 'metadata'):
        assert bundled[part] == simulated[part], f'{bag.name}: {part} differ: ./dev.sh bags'
    assert bundled['messages'].keys() == simulated['messages'].keys() >= \
        {'/layout', '/joint_states'}
    for topic, messages in simulated['messages'].items():
        assert bundled['messages'][topic] == messages, f'{bag.name} {topic}: ./dev.sh bags'
    assert [name for name, _ in bundled['metadata']] == ['rosbag2', 'rosbag2']


@pytest.fixture(scope='module')
def replayed(tmp_path_factory):
    """
    Return a function of a scenario file: its bundled bag replayed once in this module.

    It returns (replay's summary, the output bag, rosbags' read of it {topic: [(log time,
    message)]}); two tests read the same outputs, and a bundled bag is what its scenario
    makes today (test_bundled_bags_decode_equal_to_a_fresh_simulation).
    """
    folder, done = tmp_path_factory.mktemp('replayed'), {}

    def get(scenario_file):
        if scenario_file not in done:
            out = folder / f'{scenario_file.stem}.mcap'
            summary = replay(scenario_file.with_suffix('.mcap'), out)
            done[scenario_file] = (summary, out, read_with_rosbags(out))
        return done[scenario_file]
    return get


@pytest.mark.parametrize('scenario_file', BUNDLED, ids=lambda p: p.stem)
def test_project_bags_read_with_rosbags_and_mcap_ros2(scenario_file, tmp_path, replayed):
    """Simulated input and replayed output bags: every message, decoded fields agree."""
    scenario = load_scenario(scenario_file)
    inputs = tmp_path / 'in.mcap'
    write_bag(scenario, inputs)
    _, outputs, outputs_by_rosbags = replayed(scenario_file)
    angle, omega = scenario.measured()
    for path in (inputs, outputs):
        by_rosbags = outputs_by_rosbags if path == outputs else read_with_rosbags(path)
        by_mcap = read_with_mcap_ros2(path)
        assert by_rosbags.keys() == by_mcap.keys()
        for topic in by_rosbags:
            assert len(by_rosbags[topic]) == len(by_mcap[topic]), topic
            for (t1, m1), (t2, m2) in zip(by_rosbags[topic], by_mcap[topic]):
                assert t1 == t2
                if topic == '/layout':
                    assert m1.data == m2.data
                elif topic == '/joint_states':
                    assert (stamp_ns(m1), list(m1.position), list(m1.velocity), list(m1.name)) \
                        == (stamp_ns(m2), list(m2.position), list(m2.velocity), list(m2.name))
                else:
                    assert stamp_ns(m1) == stamp_ns(m2) and wrench(m1) == wrench(m2)
                    assert m1.header.frame_id == m2.header.frame_id
        if path == outputs:
            assert set(by_rosbags) >= {'/layout', '/bearing_load', '/unbalance',
                                       '/drive_torque'}
            assert len(by_rosbags['/bearing_load']) == len(scenario.stamps_ns())
            continue
        # What was written is what the scenario made (inputs, exactly).
        joints = by_rosbags['/joint_states']
        assert [stamp_ns(m) for _, m in joints] == scenario.stamps_ns().tolist()
        assert np.array_equal([m.position[0] for _, m in joints], angle)
        assert np.array_equal([m.velocity[0] for _, m in joints], omega)
        layouts = [yaml.safe_load(m.data) for _, m in by_rosbags['/layout']]
        assert layouts == [mapping for _, mapping in scenario.layouts]


@pytest.mark.parametrize('scenario_file', BUNDLED, ids=lambda p: p.stem)
def test_offline_replay_matches_pinocchio_sample_by_sample(scenario_file, replayed):
    """Outputs read back by rosbags against Pinocchio with the live alpha estimator."""
    summary, _, got = replayed(scenario_file)
    expected, _ = expected_outputs(scenario_file)
    stamps = load_scenario(scenario_file).stamps_ns()
    assert summary.accepted == len(stamps) and summary.rejected == 0
    for topic in [t for t in got if t not in ('/layout', '/joint_states')]:
        values = np.array([wrench(m) for _, m in got[topic]])
        reference = np.array([expected[stamp_ns(m)][topic] for _, m in got[topic]])
        scale = np.abs(reference).max()
        bound = AGAINST_PINOCCHIO.get(topic, 4e-15)
        assert np.abs(values - reference).max() <= bound * scale, topic
        frame = 'rotor' if topic in ('/unbalance', '/drive_torque') else 'stator'
        assert {m.header.frame_id for _, m in got[topic]} == {frame}
    assert len(got['/bearing_load']) == len(stamps)


def test_tube_swap_changes_the_static_unbalance_by_the_tube_mass_step():
    """The scenario's known change: 0.5 kg more at the tube (0.62 m, 0 deg)."""
    summary = replay(ROOT / 'bags' / 'spin_up_tube_swap.mcap')
    before, after = (RotorModel.from_layout(s.layout) for s in summary.segments)
    step = np.subtract(static_unbalance(after), static_unbalance(before))
    assert step == pytest.approx([0.5 * 0.62, 0.0], abs=1e-12)
    assert summary.segments[1].layout.components[1].mass == 60.5


def test_counterweight_shift_moves_the_couple_as_the_scenario_says():
    summary = replay(ROOT / 'bags' / 'tilted_shift.mcap')
    models = [RotorModel.from_layout(s.layout) for s in summary.segments]
    assert summary.segments[1].layout.gravity[2] == pytest.approx(9.80665 * math.sin(
        math.radians(20.0)), rel=1e-12)
    # 44 kg at 0.66 m turned from 270.3 to 270.8 deg: static unbalance step, exactly.
    step = np.subtract(static_unbalance(models[2]), static_unbalance(models[1]))
    turn = [44 * 0.66 * (math.cos(math.radians(a)) - math.cos(math.radians(b)))
            for a, b in ((270.8, 270.3),)] + [44 * 0.66 * (
                math.sin(math.radians(270.8)) - math.sin(math.radians(270.3)))]
    assert step == pytest.approx(turn, abs=1e-12)


def test_what_if_layout(tmp_path):
    other = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
    other['components'] = [c for c in other['components'] if c['name'] != 'counterweight_rear']
    path = tmp_path / 'without_rear_counterweight.yaml'
    path.write_text(yaml.safe_dump(other))
    summary = replay(ROOT / 'bags' / 'tilted_shift.mcap', layout_file=path)
    assert len(summary.segments) == 1
    assert summary.segments[0].layout.name == 'ct_gantry_demo'
    assert len(summary.segments[0].layout.components) == 9
    assert summary.segments[0].samples == 6001


def test_layouts_sharing_a_log_time_keep_their_own_texts(tmp_path):
    """
    The output's /layout repeats each accepted layout's own text, even at one log time.

    Before, the text was looked up by log time: a rejected layout before a good one at the
    same time went out as the good one's text, and of two good ones the first twice.
    """
    from cvc_balance.bag.mcap_writer import BagWriter, MessageBlock
    from cvc_balance.messages.cdr import joint_state_layout, string_message
    base = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
    texts = []
    for mass in (60.0, 60.5, 61.0):
        layout = dict(base, components=[dict(c, mass=mass) if c['name'] == 'xray_tube' else c
                                        for c in base['components']])
        texts.append(yaml.safe_dump(layout, sort_keys=False))
    bad = 'name: broken\ncomponents: [{name: x, mass: -1}]\n'
    path = tmp_path / 'in.mcap'
    stamps = np.arange(1_000_000_000, 3_000_000_000, 2_000_000, dtype=np.int64)
    with BagWriter(path) as writer:
        layout_channel = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        joints = writer.add_channel('/joint_states', 'sensor_msgs/msg/JointState',
                                    best_effort=True)
        for log_time, text in ((999_000_000, bad), (999_000_000, texts[0]),
                               (1_999_000_000, texts[1]), (1_999_000_000, texts[2])):
            writer.write(layout_channel, log_time, string_message(text))
        block = MessageBlock([(joints, joint_state_layout('', ['gantry_joint']))], len(stamps))
        block.array['0.sec'], block.array['0.nanosec'] = np.divmod(stamps, 1_000_000_000)
        block.array['0.position_0'] = 0.0
        block.array['0.velocity_0'] = 10.0
        writer.write_block(block, stamps)
    summary = replay(path, tmp_path / 'out.mcap')
    assert any('rejected' in p for p in summary.problems)
    written = read_with_rosbags(tmp_path / 'out.mcap')['/layout']
    assert [(t, m.data) for t, m in written] == \
        [(999_000_000, texts[0]), (1_999_000_000, texts[1]), (1_999_000_000, texts[2])]
    assert [s.layout.digest() for s in summary.segments] == \
        [parse_layout(yaml.safe_load(t)).digest() for t in texts]


def test_truncated_bag_uses_what_could_be_read(tmp_path):
    bag = ROOT / 'bags' / 'tilted_shift.mcap'
    full = replay(bag)
    data = bag.read_bytes()
    for fraction in (0.3, 0.6, 0.9):
        cut = tmp_path / f'cut_{fraction}.mcap'
        cut.write_bytes(data[:int(len(data) * fraction)])
        summary = replay(cut)
        assert any('truncated' in p for p in summary.problems)
        assert 0 < summary.accepted < full.accepted
        # The command once as its own process (what a person sees), then in this one.
        run = cvc('replay', cut) if fraction != 0.3 else subprocess.run(
            [sys.executable, '-m', 'cvc_balance.cli', 'replay', str(cut)],
            capture_output=True, text=True)
        assert run.returncode == 0 and 'truncated' in run.stdout
        assert 'Traceback' not in run.stderr


def test_corrupt_chunk_is_skipped_and_said(tmp_path):
    bag = ROOT / 'bags' / 'tilted_shift.mcap'
    parsed = Bag(bag)
    data = bytearray(bag.read_bytes())
    victim = parsed.chunks[3]
    start = victim.offset + 60
    data[start:start + 40] = b'\xff' * 40
    broken = tmp_path / 'broken.mcap'
    broken.write_bytes(bytes(data))
    summary = replay(broken)
    assert any('unreadable' in p and 'skipped' in p for p in summary.problems)
    assert 0 < summary.accepted < replay(bag).accepted


def test_bags_without_inputs_or_with_wrong_types_get_a_clear_message(tmp_path):
    from cvc_balance.bag.mcap_writer import BagWriter
    from cvc_balance.messages.cdr import string_message
    empty = tmp_path / 'layout_only.mcap'
    with BagWriter(empty) as writer:
        channel = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        writer.write(channel, 1, string_message('name: x'))
    with pytest.raises(BagError, match='no joint_states'):
        replay(empty)
    wrong = tmp_path / 'wrong_type.mcap'
    with BagWriter(wrong) as writer:
        writer.add_channel('/joint_states', 'std_msgs/msg/String')
    with pytest.raises(BagError, match='has type std_msgs/msg/String, expected'):
        replay(wrong)
    not_a_bag = tmp_path / 'text.mcap'
    not_a_bag.write_text('hello')
    for path, words in ((empty, 'no joint_states'), (wrong, 'expected'),
                        (not_a_bag, 'not an MCAP file')):
        run = cvc('replay', path) if path != empty else subprocess.run(
            [sys.executable, '-m', 'cvc_balance.cli', 'replay', str(path)],
            capture_output=True, text=True)         # the first as its own process
        assert run.returncode == 2 and words in run.stderr and 'Traceback' not in run.stderr


@pytest.mark.parametrize('compression', ['zstd', 'lz4', ''])
def test_block_buffers_reused_while_chunks_are_packed(compression, tmp_path):
    """
    Many more chunks than a block has buffers; channels added and loose messages in between.

    Each buffer is refilled while earlier chunks are still being compressed and
    written: every message must come back as it was set, in both readers.
    """
    from cvc_balance.bag.mcap_writer import BagWriter, BUFFERS
    from cvc_balance.messages.cdr import string_message, wrench_stamped_layout
    path = tmp_path / 'many.mcap'
    expected, k = {'/a': [], '/b': [], '/note': []}, 0
    with BagWriter(path, compression=compression, chunk_bytes=2048) as writer:
        a, b = writer.add_channel('/a', WRENCH), writer.add_channel('/b', WRENCH)
        block = writer.block([(a, wrench_stamped_layout('stator')),
                              (b, wrench_stamped_layout('rotor'))])
        for c in range(6 * BUFFERS):
            if c == 2 * BUFFERS:      # a channel registered while chunks are in flight
                note = writer.add_channel('/note', 'std_msgs/msg/String')
            if c >= 2 * BUFFERS and c % 5 == 0:
                writer.write(note, 1_000_000 * k, string_message(f'chunk {c}'))
                expected['/note'].append((1_000_000 * k, f'chunk {c}'))
            n = block.n - c % 3                  # some chunks not full
            i = np.arange(k, k + n)
            block.put(['0.sec', '1.sec'], i, n)
            block.put(['0.nanosec', '1.nanosec'], i % 1000, n)
            block.put(['0.force_x', '0.force_y', '0.force_z'], [i * 0.5, -i * 0.25, i + 0.125], n)
            block.put(['0.torque_x', '0.torque_y', '0.torque_z'], [i * 2.0, i * 3.0, i * 4.0], n)
            block.put(['1.force_x', '1.force_y'], [-i * 0.5, i * 0.75], n)
            block.fields['1.torque_z'][:n] = i * 1.5
            writer.write_block(block, 1_000_000 * i + 1, n)
            for j in i.tolist():
                t = 1_000_000 * j + 1
                expected['/a'].append((t, j, j % 1000, [j * 0.5, -j * 0.25, j + 0.125,
                                                        j * 2.0, j * 3.0, j * 4.0]))
                expected['/b'].append((t, j, j % 1000, [-j * 0.5, j * 0.75, 0.0,
                                                        0.0, 0.0, j * 1.5]))
            k += n
    assert Bag(path).problems == [] and len(Bag(path).chunks) > 5 * BUFFERS
    for read in (read_with_rosbags, read_with_mcap_ros2):
        got = read(path)
        assert [(t, m.data) for t, m in got['/note']] == expected['/note']
        for topic in ('/a', '/b'):
            assert [(t, m.header.stamp.sec, m.header.stamp.nanosec, wrench(m))
                    for t, m in got[topic]] == expected[topic]


def publish_joint_states(publisher, start, until, sent=0):
    """
    Publish JointStates at ~1 kHz until ``until`` s after ``start``; return how many in all.

    Message k (counted from 0 over calls, ``sent`` so far) has position 0.1 k and stamp
    1 s + k us.
    """
    from sensor_msgs.msg import JointState
    while time.monotonic() - start < until:
        msg = JointState(name=['gantry_joint'], position=[0.1 * sent], velocity=[20.0])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1, sent * 1000
        publisher.publish(msg)
        sent += 1
        time.sleep(0.001)
    return sent


def test_recorder_killed_with_sigkill_leaves_all_but_the_last_chunk(tmp_path):
    """4 KiB chunks of JointState at ~1 kHz; kill -9 after 2 s; read with two readers."""
    from sensor_msgs.msg import JointState
    from ros_harness import Probe

    path = tmp_path / 'killed.mcap'
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'cvc_balance.cli', 'record', '-o', str(path), '--chunk-kib', '4',
         'joint_states'], env=ros_environment(), stdout=subprocess.PIPE)
    probe = Probe('kill_probe')
    publisher = probe.publisher(JointState, 'joint_states', sensor=True)
    assert probe.spin_until(lambda: publisher.get_subscription_count() > 0, timeout=20)
    probe.spin_for(1.5)   # the recorder's side of the match may come later
    sent = publish_joint_states(publisher, time.monotonic(), 2.0)
    probe.spin_for(0.5)   # what is in flight arrives (a busy machine's recorder lags)
    recorder.send_signal(signal.SIGKILL)
    recorder.wait()
    probe.close()
    assert recorder.returncode == -signal.SIGKILL
    bag = Bag(path)
    assert any('truncated' in p for p in bag.problems)
    samples = joint_samples(bag, bag.channel('joint_states', JOINT), 'gantry_joint')
    size_per_message = 31 + 76        # record header + this JointState's CDR
    per_chunk = 4 * 1024 // size_per_message + 1
    assert sent - per_chunk - 50 <= len(samples.stamp) <= sent   # 50: still in flight
    assert np.allclose(samples.angle, 0.1 * ((samples.stamp - 1_000_000_000) // 1000),
                       rtol=1e-12, atol=0)
    assert len(bag.chunks) >= 5
    # The mcap library's own stream reader, independent of ours, sees the same messages.
    count = 0
    with open(path, 'rb') as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                count += type(record).__name__ == 'Message'
        except Exception:  # it stops where the file ends; what came before counts
            pass
    assert count == len(samples.stamp)


def test_rerun_opens_a_project_bag(tmp_path):
    """Rerun's own MCAP importer turns a bag into an .rrd file."""
    rerun = shutil.which('rerun', path=str(Path(sys.executable).parent))
    env = {**ros_environment(), 'XDG_CONFIG_HOME': str(tmp_path / 'config')}
    subprocess.run([rerun, 'analytics', 'disable'], env=env, capture_output=True, check=True)
    out = tmp_path / 'bag.rrd'
    subprocess.run([rerun, '--bind', '127.0.0.1', '--port', '0', str(ROOT / 'bags' /
                    'tilted_shift.mcap'), '--save', str(out)], env=env, capture_output=True,
                   check=True, timeout=120)
    from rerun.chunk import RrdReader
    paths = {str(chunk.entity_path) for chunk in RrdReader(str(out)).stream()}
    assert {'/joint_states', '/joint_states/position', '/joint_states/velocity',
            '/layout'} <= paths


def read_with_mcap_library(path):
    """{topic: [(log time, CDR bytes)]} and the summary, by the mcap library, CRCs checked."""
    from mcap.reader import make_reader
    out = {}
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)    # every chunk's CRC
        for _, channel, message in reader.iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
        return out, reader.get_summary()


def test_threaded_zstd_output_read_by_three_readers(tmp_path, monkeypatch):
    """
    A replay's zstd output whose buffers were filled and compressed on the writer's threads.

    Chunks of 8 KiB (replay's CHUNK_BYTES, 4 MiB, made small) give more chunks than a block
    has buffers, across the tube swap's two layouts: many buffers are filled at once, none on
    the replaying thread. The mcap library (each chunk's CRC checked), rosbags and mcap_ros2
    read every message: per topic the replay's accepted samples (the layout: one a
    segment); the three decode the same stamps, frames and wrenches, the engine's own (the
    live alpha estimator, as test_offline_replay_matches_the_engine_sample_by_sample has it).
    """
    import importlib
    import threading
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    from cvc_balance.bag.mcap_writer import BUFFERS
    module = importlib.import_module('cvc_balance.bag.replay')
    monkeypatch.setattr(module, 'CHUNK_BYTES', 8 << 10)
    filled_on = set()
    fill = module.OutputBlocks._fill

    def watched(self, buffer, **kwargs):
        filled_on.add(threading.current_thread().name)
        return fill(self, buffer, **kwargs)
    monkeypatch.setattr(module.OutputBlocks, '_fill', watched)
    scenario_file = ROOT / 'bags' / 'spin_up_tube_swap.yaml'
    out = tmp_path / 'out.mcap'
    summary = module.replay(scenario_file.with_suffix('.mcap'), out, compression='zstd')
    assert filled_on and all(name.startswith('bag_pack') for name in filled_on)
    assert len(summary.segments) == 2 and summary.accepted == \
        len(load_scenario(scenario_file).stamps_ns())
    with open(out, 'rb') as stream:
        chunks = [r for r in StreamReader(stream, emit_chunks=True).records
                  if isinstance(r, Chunk)]
    assert len(chunks) > 4 * BUFFERS and {c.compression for c in chunks} == {'zstd'}
    assert max(c.uncompressed_size for c in chunks) <= 8 << 10

    raw, counts = read_with_mcap_library(out)
    by_rosbags, by_mcap_ros2 = read_with_rosbags(out), read_with_mcap_ros2(out)
    outputs = {'/bearing_load', '/unbalance', '/drive_torque', '/supports/front/load',
               '/supports/rear/load'}
    assert set(raw) == set(by_rosbags) == set(by_mcap_ros2) == outputs | {'/layout'}
    channels = {c.id: c.topic for c in counts.channels.values()}
    for topic in raw:
        count = 2 if topic == '/layout' else summary.accepted
        assert len(raw[topic]) == len(by_rosbags[topic]) == len(by_mcap_ros2[topic]) == count
        assert sum(n for c, n in counts.statistics.channel_message_counts.items()
                   if channels[c] == topic) == count
    expected, _ = expected_outputs(scenario_file)
    for topic in outputs:
        ours = [(t, stamp_ns(m), m.header.frame_id, wrench(m)) for t, m in by_rosbags[topic]]
        theirs = [(t, stamp_ns(m), m.header.frame_id, wrench(m))
                  for t, m in by_mcap_ros2[topic]]
        assert ours == theirs, topic
        assert [t for t, _ in raw[topic]] == [t for t, *_ in ours], topic
        frame = 'rotor' if topic in ('/unbalance', '/drive_torque') else 'stator'
        assert {f for _, _, f, _ in ours} == {frame}
        values = np.array([w for *_, w in ours])
        reference = np.array([expected[s][topic] for _, s, _, _ in ours])
        bound = AGAINST_PINOCCHIO.get(topic, 4e-15)
        assert np.abs(values - reference).max() <= bound * np.abs(reference).max(), topic
