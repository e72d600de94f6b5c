"""
Bags written by others than the project, replayed: the mcap library, mcap-ros2, rosbags' rosbag2.

One run (the bundled ``tilted_shift`` scenario: 6001 JointState samples, three layouts) is
written by each foreign writer in each configuration (chunked or not, zstd/lz4/none, small
chunks, no message indexes, no summary; rosbag2 directories with mcap and sqlite3 storage, a
run split over three files), its CDR made by rosbags' serialiser or mcap-ros2's encoder (not
the project's). Each is replayed and its outputs, read back with the ``mcap`` library's reader
(CRCs validated) and rosbags' deserialiser, are compared with

* Pinocchio: ``scenario_reference`` (the scenario's known motion, the live alpha estimator and
  Pinocchio's RNEA of each layout; independent of the bag reading, the vectorised replay
  and cvc_balance's physics), and
* the replay of the project's own bag of the same run: equal to the last bit.

Also: JointStates with several joints and a second publisher on the topic, namespaced topics
and the topic options, truncated and corrupt foreign bags, directories without metadata.yaml,
and every kind of bag the project writes read by the mcap library with CRCs validated.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import shutil
import subprocess
import sys

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer as McapWriter
from mcap_ros2.writer import Writer as McapRos2Writer
import numpy as np
import pytest
from rosbags.rosbag2 import Reader as Rosbag2Reader, StoragePlugin, Writer as Rosbag2Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.inputs import InputTopics
from cvc_balance.bag.mcap_reader import BagError, joint_samples
from cvc_balance.bag.replay import read_inputs, replay
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.bag.scenario import load_scenario, write_bag
from in_process import cvc
from scenario_reference import expected_outputs

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / 'bags' / 'tilted_shift.yaml'
STORE = get_typestore(Stores.ROS2_JAZZY)
JOINT_STATE, STRING = 'sensor_msgs/msg/JointState', 'std_msgs/msg/String'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
TOLERANCE = 1e-12
"""Outputs against Pinocchio, relative to each output's peak (measured: at most 2.3e-13,
the drive torque, whose alpha goes through two implementations of the estimator; the
unbalance 7.3e-14, Pinocchio's centre of mass S / m of a near-balanced rotor; loads
1.4e-15)."""


@dataclass
class Run:
    """The scenario's messages as a recorder would have them: (log time, topic, type, CDR)."""

    stamps: np.ndarray
    angle: np.ndarray
    omega: np.ndarray
    events: list


def joint_state(stamp, names, positions, velocities):
    """Make a sensor_msgs/JointState, as rosbags' message object."""
    types = STORE.types
    return types[JOINT_STATE](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=stamp // 1_000_000_000,
                                                       nanosec=stamp % 1_000_000_000),
            frame_id=''),
        name=list(names), position=np.array(positions, dtype=float),
        velocity=np.array(velocities, dtype=float), effort=np.zeros(0))


def cdr(message, msg_type):
    return bytes(STORE.serialize_cdr(message, msg_type))


def make_run(names=('gantry_joint',), other=None, prefix=''):
    """
    Serialise the scenario with rosbags: layouts and JointStates in log-time order.

    ``names`` are the joints of each message (the gantry's at its place, others at 0.3
    rad, 0 rad/s); ``other`` (every n-th sample) adds a message of a second publisher
    that lacks the gantry joint; ``prefix`` is a namespace for the topics.
    """
    scenario = load_scenario(SCENARIO)
    stamps = scenario.stamps_ns()
    angle, omega = scenario.measured()
    events = []
    for at, mapping in scenario.layouts:
        log_time = int(round((scenario.start + at - 0.5 / scenario.rate) * 1e9))
        text = yaml.safe_dump(mapping, sort_keys=False)
        events.append((log_time, f'{prefix}/layout', STRING,
                       cdr(STORE.types[STRING](data=text), STRING)))
    for i, (stamp, q, w) in enumerate(zip(stamps.tolist(), angle, omega)):
        positions = [q if n == 'gantry_joint' else 0.3 for n in names]
        velocities = [w if n == 'gantry_joint' else 0.0 for n in names]
        events.append((stamp, f'{prefix}/joint_states', JOINT_STATE,
                       cdr(joint_state(stamp, names, positions, velocities), JOINT_STATE)))
        if other and i % other == 0:
            events.append((stamp + 1, f'{prefix}/joint_states', JOINT_STATE,
                           cdr(joint_state(stamp + 1, ['table_joint'], [0.1], [0.0]),
                               JOINT_STATE)))
    events.sort(key=lambda e: e[0])
    return Run(stamps, angle, omega, events)


def msgdef(msg_type):
    return STORE.generate_msgdef(msg_type, ros_version=2)[0]


def write_mcap(path, run, **options):
    """Write with the mcap library's writer (mcap.writer.Writer), ``options``, profile ros2."""
    with open(path, 'wb') as stream:
        writer = McapWriter(stream, **options)
        writer.start(profile='ros2', library='test')
        schemas, channels = {}, {}
        for log_time, topic, msg_type, data in run.events:
            if msg_type not in schemas:
                schemas[msg_type] = writer.register_schema(msg_type, 'ros2msg',
                                                           msgdef(msg_type).encode())
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, 'cdr', schemas[msg_type])
            writer.add_message(channels[topic], log_time, data, log_time)
        writer.finish()


def write_mcap_ros2(path, run, **options):
    """mcap-ros2's writer: its own encoder makes the CDR from plain values."""
    scenario = load_scenario(SCENARIO)
    with open(path, 'wb') as stream:
        writer = McapRos2Writer(stream, **options)
        joint_schema = writer.register_msgdef(JOINT_STATE, msgdef(JOINT_STATE))
        string_schema = writer.register_msgdef(STRING, msgdef(STRING))
        layouts = [(int(round((scenario.start + at - 0.5 / scenario.rate) * 1e9)),
                    yaml.safe_dump(mapping, sort_keys=False)) for at, mapping in scenario.layouts]
        samples = [(int(s), q, w) for s, q, w in zip(run.stamps, run.angle, run.omega)]
        events = sorted([(t, 0, text) for t, text in layouts] +
                        [(s, 1, (q, w)) for s, q, w in samples], key=lambda e: e[0])
        for log_time, kind, value in events:
            if kind == 0:
                writer.write_message('/layout', string_schema, {'data': value}, log_time,
                                     log_time)
                continue
            writer.write_message('/joint_states', joint_schema, {
                'header': {'stamp': {'sec': log_time // 1_000_000_000,
                                     'nanosec': log_time % 1_000_000_000}, 'frame_id': ''},
                'name': ['gantry_joint'], 'position': [value[0]], 'velocity': [value[1]],
                'effort': []}, log_time, log_time)
        writer.finish()


def write_rosbag2(path, events, storage, compression=None):
    """Write with rosbags' rosbag2 Writer (metadata.yaml version 9), ``storage``, compression."""
    writer = Rosbag2Writer(path, version=9, storage_plugin=storage)
    if compression is not None:
        writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        connections = {}
        for log_time, topic, msg_type, data in events:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msg_type, typestore=STORE)
            writer.write(connections[topic], log_time, data)


def write_split(path, run, parts=3):
    """
    Write a rosbag2 directory of ``parts`` MCAP files, as ``ros2 bag record`` splits a run.

    Each time slice is written by rosbags' Writer; the files are gathered in one
    directory as ``NAME_i.mcap`` and metadata.yaml lists them (rosbag2's layout:
    relative_file_paths and per-file entries), its counts summed from the parts'.
    """
    path.mkdir()
    bounds = np.linspace(0, len(run.events), parts + 1).astype(int)
    infos = []
    for i, (a, b) in enumerate(zip(bounds, bounds[1:])):
        part = path.parent / f'{path.name}_part{i}'
        write_rosbag2(part, run.events[a:b], StoragePlugin.MCAP)
        info = yaml.safe_load((part / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        name = f'{path.name}_{i}.mcap'
        shutil.move(part / info['relative_file_paths'][0], path / name)
        shutil.rmtree(part)
        info['files'][0]['path'] = name
        infos.append(info)
    merged = dict(infos[0])
    merged['relative_file_paths'] = [info['files'][0]['path'] for info in infos]
    merged['files'] = [info['files'][0] for info in infos]
    merged['message_count'] = sum(info['message_count'] for info in infos)
    start = min(info['starting_time']['nanoseconds_since_epoch'] for info in infos)
    end = max(info['starting_time']['nanoseconds_since_epoch'] + info['duration']['nanoseconds']
              for info in infos)
    merged['starting_time'] = {'nanoseconds_since_epoch': start}
    merged['duration'] = {'nanoseconds': end - start}
    counts = {}
    for info in infos:
        for topic in info['topics_with_message_count']:
            name = topic['topic_metadata']['name']
            counts.setdefault(name, [topic['topic_metadata'], 0])[1] += topic['message_count']
    merged['topics_with_message_count'] = [{'topic_metadata': meta, 'message_count': n}
                                           for meta, n in counts.values()]
    (path / 'metadata.yaml').write_text(yaml.safe_dump(
        {'rosbag2_bagfile_information': merged}, sort_keys=False))


def bag_files(path):
    path = Path(path)
    return sorted(path.glob('*.mcap')) if path.is_dir() else [path]


def read_outputs(path):
    """
    {topic: (stamps, (n, 6) wrench)} of a replay's output, sorted by stamp.

    Read by the mcap library's reader with chunk CRCs validated, decoded by rosbags.
    """
    found = {}
    for file in bag_files(path):
        with open(file, 'rb') as stream:
            for schema, channel, message in make_reader(stream, validate_crcs=True) \
                    .iter_messages():
                if schema.name != WRENCH:
                    continue
                msg = STORE.deserialize_cdr(message.data, WRENCH)
                w = msg.wrench
                found.setdefault(channel.topic, []).append(
                    (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                     [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]))
    out = {}
    for topic, rows in found.items():
        rows.sort(key=lambda row: row[0])
        out[topic] = (np.array([r[0] for r in rows]), np.array([r[1] for r in rows]))
    return out


@pytest.fixture(scope='module')
def reference(tmp_path_factory):
    """Return the engine's outputs per topic and the replay of the project's own bag of the run."""
    folder = tmp_path_factory.mktemp('own')
    own = folder / 'own.mcap'
    write_bag(load_scenario(SCENARIO), own)
    replay(own, folder / 'own_out.mcap')
    expected, _ = expected_outputs(SCENARIO)
    stamps = sorted(expected)
    engine = {topic: (np.array(stamps), np.array([expected[s][topic] for s in stamps]))
              for topic in expected[stamps[0]]}
    return engine, read_outputs(folder / 'own_out.mcap')


@pytest.fixture(scope='module')
def run():
    return make_run()


def assert_outputs(path, reference, errors=None):
    """Check that the outputs at ``path`` equal Pinocchio's (TOLERANCE) and the own bag's."""
    engine, own = reference
    got = read_outputs(path)
    assert got.keys() == engine.keys() == own.keys()
    for topic, (stamps, values) in engine.items():
        assert np.array_equal(got[topic][0], stamps), topic
        scale = np.abs(values).max()
        error = np.abs(got[topic][1] - values).max() / scale
        assert error <= TOLERANCE, (topic, error)
        if errors is not None:
            errors[topic] = error
        assert np.array_equal(got[topic][0], own[topic][0]), topic
        assert np.array_equal(got[topic][1], own[topic][1]), topic    # to the last bit


def assert_inputs_read(path, run, names=None):
    """Check that the motion the reader finds is the scenario's, exactly."""
    motion, layouts = read_inputs(open_bag(path), 'gantry_joint', names)
    assert np.array_equal(motion.stamp, run.stamps)
    assert np.array_equal(motion.log_time, run.stamps)
    assert np.array_equal(motion.angle, run.angle)
    assert np.array_equal(motion.omega, run.omega)
    assert len(layouts) == 3


MCAP_CONFIGURATIONS = {
    'defaults (zstd, 1 MiB chunks)': {},
    'lz4': {'compression': CompressionType.LZ4},
    'uncompressed chunks': {'compression': CompressionType.NONE},
    'small chunks': {'chunk_size': 1024},
    'no message indexes': {'index_types': IndexType.CHUNK, 'chunk_size': 8192},
    'no summary': {'index_types': IndexType.NONE, 'repeat_channels': False,
                   'repeat_schemas': False, 'use_statistics': False,
                   'use_summary_offsets': False, 'chunk_size': 8192},
    'unchunked': {'use_chunking': False},
}


def records_after_data_end(path):
    """Kinds of the top-level records of a file, read by the mcap library's stream reader."""
    with open(path, 'rb') as stream:
        return [type(r).__name__ for r in StreamReader(stream, skip_magic=False,
                                                       emit_chunks=True).records]


@pytest.mark.parametrize('name', MCAP_CONFIGURATIONS)
def test_mcap_library_bags_replay_as_the_engine(name, run, reference, tmp_path):
    options = MCAP_CONFIGURATIONS[name]
    path = tmp_path / 'foreign.mcap'
    write_mcap(path, run, **options)
    kinds = records_after_data_end(path)
    # The file is what its configuration says (else this test would prove nothing).
    assert ('Chunk' in kinds) == options.get('use_chunking', True)
    if options.get('use_chunking', True):
        assert ('MessageIndex' in kinds) == (name not in ('no message indexes', 'no summary'))
        # Channels only inside the chunks (and repeated in the summary, where there is one).
        assert 'Channel' not in kinds[:kinds.index('DataEnd')]
    if name == 'no summary':
        assert kinds[kinds.index('DataEnd') + 1:] == ['Footer']
    assert_inputs_read(path, run)
    summary = replay(path, tmp_path / 'out.mcap')
    assert (summary.accepted, summary.rejected, summary.skipped) == (len(run.stamps), 0, 0)
    assert summary.problems == []
    errors = {}
    assert_outputs(tmp_path / 'out.mcap', reference, errors)
    print(name, {t: f'{e:.1e}' for t, e in errors.items()})


@pytest.mark.parametrize('compression', ['ZSTD', 'LZ4', 'NONE'])
def test_mcap_ros2_writer_bags_replay_as_the_engine(compression, run, reference, tmp_path):
    """mcap-ros2's own writer and CDR encoder, Schema and Channel records inside chunks."""
    path = tmp_path / 'ros2.mcap'
    write_mcap_ros2(path, run, compression=CompressionType[compression], chunk_size=16384)
    assert_inputs_read(path, run)
    summary = replay(path, tmp_path / 'out')        # a rosbag2 directory this time
    assert (summary.accepted, summary.rejected) == (len(run.stamps), 0)
    assert summary.problems == []
    assert_outputs(tmp_path / 'out', reference)


@pytest.mark.parametrize('storage, compression', [('MCAP', None), ('SQLITE3', None),
                                                  ('MCAP', 'MESSAGE'), ('MCAP', 'FILE'),
                                                  ('SQLITE3', 'FILE')])
def test_rosbags_rosbag2_directories_replay_as_the_engine(storage, compression, run, reference,
                                                          tmp_path):
    """Directories by rosbags' rosbag2 writer: mcap, sqlite3 storage, per-message and file zstd."""
    path = tmp_path / 'rosbag2'
    write_rosbag2(path, run.events, StoragePlugin[storage],
                  CompressionMode[compression] if compression else None)
    suffix = {'MCAP': '.mcap', 'SQLITE3': '.db3'}[storage] + ('.zstd' if compression == 'FILE'
                                                              else '')
    assert [''.join(p.suffixes) for p in path.iterdir() if p.name != 'metadata.yaml'] == \
        [suffix]
    assert_inputs_read(path, run)
    summary = replay(path, tmp_path / 'out.mcap')
    assert (summary.accepted, summary.rejected) == (len(run.stamps), 0)
    assert summary.problems == []
    assert_outputs(tmp_path / 'out.mcap', reference)
    if compression is None:   # the storage file alone (without its directory) is a bag too
        (file,) = path.glob(f'*{suffix}')
        assert replay(file).accepted == len(run.stamps)


def test_split_rosbag2_directory_is_one_run(run, reference, tmp_path):
    path = tmp_path / 'split'
    write_split(path, run)
    names = sorted(p.name for p in path.iterdir())
    assert names == ['metadata.yaml', 'split_0.mcap', 'split_1.mcap', 'split_2.mcap']
    with Rosbag2Reader(path) as reader:      # rosbags takes the directory as one bag
        assert [t for _, t, _ in reader.messages()] == [e[0] for e in run.events]
    # The layouts are all in the first file, the samples spread over three.
    bag = open_bag(path)
    assert len(bag.parts) == 3
    assert_inputs_read(path, run)
    summary = replay(path, tmp_path / 'out.mcap')
    assert (summary.accepted, summary.rejected) == (len(run.stamps), 0)
    assert len(summary.segments) == 3 and summary.problems == []
    assert_outputs(tmp_path / 'out.mcap', reference)
    # Listed out of order, the files are still one run in log-time order.
    info = yaml.safe_load((path / 'metadata.yaml').read_text())
    info['rosbag2_bagfile_information']['relative_file_paths'].reverse()
    (path / 'metadata.yaml').write_text(yaml.safe_dump(info))
    assert_inputs_read(path, run)
    # A recording killed before metadata.yaml was written: its files in name order.
    (path / 'metadata.yaml').unlink()
    assert_inputs_read(path, run)
    assert any('no metadata.yaml' in p for p in open_bag(path).problems)
    # A listed file missing: said, the rest used.
    write_split(tmp_path / 'gap', run)
    (tmp_path / 'gap' / 'gap_1.mcap').unlink()
    summary = replay(tmp_path / 'gap')
    assert any('gap_1.mcap' in p and 'missing' in p for p in summary.problems)
    assert 0 < summary.accepted < len(run.stamps)


def test_several_joints_and_a_second_publisher(reference, tmp_path):
    """The rotor's joint found by name in a JointState of three; another publisher skipped."""
    run = make_run(names=('table_joint', 'tilt_joint', 'gantry_joint'), other=7)
    table_messages = sum(1 for i in range(len(run.stamps)) if i % 7 == 0)
    path = tmp_path / 'multi.mcap'
    write_mcap(path, run, chunk_size=65536)
    summary = replay(path, tmp_path / 'out.mcap')
    assert (summary.accepted, summary.rejected) == (len(run.stamps), 0)
    assert summary.skipped == table_messages
    assert "without joint 'gantry_joint' (they name: table_joint)" in summary.skipped_reason
    assert_outputs(tmp_path / 'out.mcap', reference)
    # The chunks hold two layouts (publishers): both are read a layout at a time.
    bag = open_bag(path)
    motion = joint_samples(bag, bag.channel('joint_states', JOINT_STATE), 'gantry_joint')
    assert np.array_equal(motion.angle, run.angle) and motion.skipped == table_messages
    # A joint no message has: one line naming the joints there are.
    with pytest.raises(BagError, match="no /joint_states message carries joint 'spindle'.*"
                       'table_joint, tilt_joint'):
        replay(path, joint_name='spindle')


def test_namespaced_topics_and_the_topic_options(reference, tmp_path):
    run = make_run(prefix='/gantry')
    path = tmp_path / 'namespaced.mcap'
    write_mcap(path, run)
    summary = replay(path, tmp_path / 'out.mcap')   # found under the namespace by default
    assert summary.accepted == len(run.stamps)
    assert_outputs(tmp_path / 'out.mcap', reference)
    # A second namespace: the default is ambiguous; the options choose.
    both = make_run(prefix='/gantry')
    both.events += [(t + 3, topic.replace('/gantry', '/table'), kind, data)
                    for t, topic, kind, data in both.events]
    both.events.sort(key=lambda e: e[0])
    two = tmp_path / 'two.mcap'
    write_mcap(two, both)
    with pytest.raises(BagError, match='several topics match joint_states: '
                       '/gantry/joint_states, /table/joint_states; choose one with '
                       '--joint-states'):
        replay(two)
    names = InputTopics('/gantry/joint_states', layout='gantry/layout')
    assert_inputs_read(two, run, names)
    # The command line (its own process once, then in this one): options, and bad topics
    # named with what the bag has.
    cli = [sys.executable, '-m', 'cvc_balance.cli']
    ok = subprocess.run(cli + ['replay', str(two), '--joint-states', '/gantry/joint_states',
                               '--layout-topic', '/gantry/layout'], capture_output=True, text=True)
    assert ok.returncode == 0 and f'{len(run.stamps)} used' in ok.stdout, ok.stderr
    for args, words in (
            (['--joint-states', '/nowhere'], 'no topic /nowhere (given with --joint-states); '
             'the bag has: /gantry/joint_states (sensor_msgs/msg/JointState), /gantry/layout '
             '(std_msgs/msg/String), /table/joint_states'),
            (['--joint-states', '/gantry/layout'], 'topic /gantry/layout has type '
             'std_msgs/msg/String, expected sensor_msgs/msg/JointState'),
            (['--layout-topic', 'config/ct_gantry.yaml'], 'not a topic name: '
             "'config/ct_gantry.yaml' (a layout file goes with --layout-file FILE)")):
        for command in ('replay', 'view'):
            extra = ['-o', str(tmp_path / 'v.rrd')] if command == 'view' else []
            bad = cvc(command, two, *args, *extra)
            assert bad.returncode == 2 and words in bad.stderr, (command, bad.stderr)
            assert 'Traceback' not in bad.stderr
    speed_only = cvc('replay', two, '--speed-topic', '/gantry/speed')
    assert speed_only.returncode == 2 and 'no topic /gantry/speed' in speed_only.stderr


def test_truncated_foreign_bag_is_read_up_to_its_last_whole_chunk(run, tmp_path):
    """Cut anywhere: every message of every whole chunk, as the mcap library's reader sees."""
    path = tmp_path / 'whole.mcap'
    write_mcap_ros2(path, run, chunk_size=4096)
    data = path.read_bytes()
    for fraction in (0.05, 0.3, 0.6, 0.9, 0.999):
        cut = tmp_path / f'cut_{fraction}.mcap'
        cut.write_bytes(data[:int(len(data) * fraction)])
        expected = 0
        with open(cut, 'rb') as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    expected += type(record).__name__ == 'Message' and record.channel_id == 2
            except Exception:   # it stops where the file ends; what came before counts
                pass
        bag = open_bag(cut)
        if expected < len(run.stamps):
            assert any('truncated' in p for p in bag.problems), bag.problems
        else:                                   # cut in the summary: every message is there
            assert bag.problems[0].endswith('in its summary (every message was read)')
        motion = joint_samples(bag, bag.channel('joint_states', JOINT_STATE), 'gantry_joint')
        assert len(motion.stamp) == expected > 0, fraction
        assert np.array_equal(motion.angle, run.angle[:expected])
        command = cvc('replay', cut)
        assert command.returncode == 0 and 'problem: file ends' in command.stdout
        assert f'{expected} motion samples' in command.stdout


def test_chunk_with_a_bad_crc_is_said_and_the_rest_used(run, tmp_path):
    path = tmp_path / 'foreign.mcap'
    write_mcap(path, run, compression=CompressionType.NONE, chunk_size=32768)
    with open(path, 'rb') as stream:
        chunk = make_reader(stream).get_summary().chunk_indexes[5]
    data = bytearray(path.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    broken = tmp_path / 'broken.mcap'
    broken.write_bytes(bytes(data))
    in_chunk = int(((run.stamps >= chunk.message_start_time) &
                    (run.stamps <= chunk.message_end_time)).sum())
    summary = replay(broken)
    assert any('CRC mismatch' in p and 'skipped' in p for p in summary.problems)
    assert summary.accepted == len(run.stamps) - in_chunk > 0


def test_every_bag_the_project_writes_reads_with_the_mcap_library(tmp_path):
    """Simulated, replayed and bundled bags, files and directories: CRCs and metadata checked."""
    from cvc_balance.cli import main          # in this process: the bags, not the command
    scenario = load_scenario(SCENARIO)
    made = {}
    for name in ('sim.mcap', 'sim_dir'):
        assert main(['simulate', str(SCENARIO), '-o', str(tmp_path / name)]) == 0
        made[name] = {'/joint_states': len(scenario.stamps_ns()), '/layout': 3}
    outputs = {'/bearing_load', '/unbalance', '/drive_torque', '/supports/front/load',
               '/supports/rear/load'}
    for compression in ('zstd', 'lz4', 'none'):
        for name in (f'out_{compression}.mcap', f'out_{compression}'):
            assert main(['replay', str(tmp_path / 'sim_dir'), '-o', str(tmp_path / name),
                         '--compression', compression]) == 0
            made[name] = {**{t: len(scenario.stamps_ns()) for t in outputs}, '/layout': 3}
    for bundled in sorted((ROOT / 'bags').glob('*.mcap')):
        made[bundled] = None
    for name, counts in made.items():
        path = tmp_path / name
        got = {}
        for file in bag_files(path):
            with open(file, 'rb') as stream:
                reader = make_reader(stream, validate_crcs=True)
                # File order: every chunk read and its CRC checked, without a heap sort.
                for schema, channel, message in reader.iter_messages(log_time_order=False):
                    STORE.deserialize_cdr(message.data, schema.name)
                    got[channel.topic] = got.get(channel.topic, 0) + 1
        assert got == counts or counts is None and set(got) >= {'/joint_states', '/layout'}
        if path.is_dir():
            assert [p.name for p in sorted(path.iterdir())] == ['metadata.yaml',
                                                                f'{name}_0.mcap']
            with Rosbag2Reader(path) as reader:      # rosbags' rosbag2 reader: metadata.yaml
                assert reader.message_count == sum(counts.values())
                topics = reader.topics
                assert {t: i.msgcount for t, i in topics.items()} == counts
                for connection in reader.connections:
                    assert connection.digest == STORE.hash_rihs01(connection.msgtype)
                    assert connection.msgdef.data      # the schema, from the MCAP file
            info = yaml.safe_load((path / 'metadata.yaml').read_text())
            info = info['rosbag2_bagfile_information']
            assert (info['version'], info['storage_identifier']) == (9, 'mcap')
            qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles'][0]
                   for t in info['topics_with_message_count']}
            assert qos['/layout']['durability'] == 'transient_local'
    # A replay's output directory is replaced by the next; a directory of other files is not
    # (the command as its own process, as a person runs it).
    cli = [sys.executable, '-m', 'cvc_balance.cli']
    again = subprocess.run(cli + ['replay', str(tmp_path / 'sim.mcap'), '-o',
                                  str(tmp_path / 'out_zstd')], capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    (tmp_path / 'mine').mkdir()
    (tmp_path / 'mine' / 'notes.txt').write_text('keep me')
    refused = subprocess.run(cli + ['replay', str(tmp_path / 'sim.mcap'), '-o',
                                    str(tmp_path / 'mine')], capture_output=True, text=True)
    assert refused.returncode == 2 and 'not overwritten' in refused.stderr
    assert (tmp_path / 'mine' / 'notes.txt').read_text() == 'keep me'


def test_not_a_bag_gets_one_line(tmp_path):
    cli = [sys.executable, '-m', 'cvc_balance.cli', 'replay']
    (tmp_path / 'empty_dir').mkdir()
    (tmp_path / 'bad_meta').mkdir()
    (tmp_path / 'bad_meta' / 'metadata.yaml').write_text('rosbag2_bagfile_information: [1')
    (tmp_path / 'notes.txt').write_text('hello')
    for path, words in ((tmp_path / 'empty_dir', 'not a rosbag2 directory'),
                        (tmp_path / 'bad_meta', 'metadata.yaml: unreadable'),
                        (tmp_path / 'notes.txt', 'not a bag'),
                        (tmp_path / 'missing', 'No such file or directory')):
        # The first as its own process (what a person sees), the others in this one.
        run = cvc('replay', path) if path.name != 'empty_dir' else \
            subprocess.run(cli + [str(path)], capture_output=True, text=True)
        assert run.returncode == 2 and words in run.stderr, (path, run.stderr)
        assert run.stderr.count('\n') == 1 and 'Traceback' not in run.stderr


def test_many_layouts_of_one_topic_do_not_lose_samples(tmp_path):
    """Chunks where every message has its own layout (more than LAYOUTS) decode one by one."""
    from cvc_balance.bag import mcap_reader
    run = make_run()
    frames = [f'frame{"x" * (i % (2 * mcap_reader.LAYOUTS))}' for i in range(len(run.stamps))]
    events, k = [], 0
    for log_time, topic, msg_type, data in run.events:
        if msg_type == JOINT_STATE:
            q, w = run.angle[k], run.omega[k]
            message = joint_state(log_time, ['gantry_joint'], [q], [w])
            message.header.frame_id = frames[k]
            data = cdr(message, JOINT_STATE)
            k += 1
        events.append((log_time, topic, msg_type, data))
    path = tmp_path / 'frames.mcap'
    write_mcap(path, Run(run.stamps, run.angle, run.omega, events), chunk_size=1 << 20)
    assert_inputs_read(path, run)
    assert math.isfinite(replay(path).segments[0].peak_total)


def test_fuzzed_foreign_bags_give_a_bag_error_or_what_can_be_read(tmp_path):
    """
    Bytes changed, overwritten or cut out at random in foreign bags of every layout.

    Reading must end in a BagError (one line) or in what could be read, never another
    exception (9000 such mutations found none while this test was written).
    """
    import random
    from cvc_balance.bag.mcap_reader import BagError
    full = make_run(names=('a', 'gantry_joint'))
    run = Run(full.stamps[:300], full.angle[:300], full.omega[:300],
              [e for e in full.events if e[0] <= full.stamps[299]])
    sources = []
    for i, options in enumerate([
            {}, {'chunk_size': 1024},
            {'index_types': IndexType.NONE, 'chunk_size': 1024, 'repeat_channels': False,
             'repeat_schemas': False},
            {'use_chunking': False}, {'compression': CompressionType.NONE, 'chunk_size': 2048},
            {'compression': CompressionType.LZ4, 'chunk_size': 2048}]):
        write_mcap(tmp_path / f'{i}.mcap', run, **options)
        sources.append((tmp_path / f'{i}.mcap').read_bytes())
    rng = random.Random(11)
    outcomes = {'error': 0, 'read': 0}
    for _ in range(600):
        data = bytearray(rng.choice(sources))
        for _ in range(rng.choice([1, 1, 2, 5, 20])):
            k, mode = rng.randrange(len(data)), rng.random()
            if mode < 0.6:
                data[k] = rng.randrange(256)
            elif mode < 0.8:
                data[k:k + 8] = rng.randbytes(8)
            else:
                del data[k:k + rng.randrange(1, 50)]
        path = tmp_path / 'fuzzed.mcap'
        path.write_bytes(bytes(data))
        try:
            motion, _ = read_inputs(open_bag(path), 'gantry_joint')
        except BagError as error:
            assert '\n' not in str(error)
            outcomes['error'] += 1
            continue
        assert len(motion.stamp) == len(motion.angle) == len(motion.omega)
        outcomes['read'] += 1
    # Both outcomes drawn (the reader goes on past damaged records since issue 24: errors
    # went from over 50 to 34 of 600).
    assert min(outcomes.values()) > 20, outcomes


def test_fast_path_gathers_a_chunk_at_once(monkeypatch, tmp_path):
    """
    No message-by-message decoding of foreign bags: one gather per chunk and layout.

    Chunks are opened at open time only to find channels the summary does not list:
    none when it lists them (the mcap library's defaults), the first with message
    indexes and no channels in the summary, every one with neither.
    """
    from cvc_balance.bag import mcap_reader
    layouts, decoded = [], []
    one_layout, decode = mcap_reader._one_layout, mcap_reader._decode
    monkeypatch.setattr(mcap_reader, '_one_layout',
                        lambda b, o, *rest: layouts.append(len(o)) or one_layout(b, o, *rest))
    monkeypatch.setattr(mcap_reader, '_decode', lambda c: decoded.append(c) or decode(c))
    run = make_run(names=('table_joint', 'gantry_joint', 'tilt_joint'))
    for options, opened in (({'chunk_size': 65536}, 0),
                            ({'chunk_size': 65536, 'repeat_channels': False}, 1),
                            ({'chunk_size': 65536, 'index_types': IndexType.NONE}, 0),
                            ({'chunk_size': 65536, 'index_types': IndexType.NONE,
                              'repeat_channels': False}, None)):
        path = tmp_path / 'multi.mcap'
        write_mcap(path, run, **options)
        decoded.clear()
        bag = open_bag(path)
        assert len(decoded) == (len(bag.chunks) if opened is None else opened), options
        layouts.clear()
        motion = joint_samples(bag, bag.channel('joint_states', JOINT_STATE), 'gantry_joint')
        assert np.array_equal(motion.angle, run.angle)
        assert len(layouts) == len(bag.chunks) > 10 and sum(layouts) == len(run.stamps)
    # A second publisher on the topic: two gathers per chunk, none message by message.
    write_mcap(path, make_run(names=('gantry_joint', 'table_joint'), other=3),
               chunk_size=65536)
    bag = open_bag(path)
    layouts.clear()
    joint_samples(bag, bag.channel('joint_states', JOINT_STATE), 'gantry_joint')
    assert len(layouts) == 2 * len(bag.chunks)


def test_speed_only_split_directory_listed_out_of_order(tmp_path):
    """Float64 speed under a remapped name, split over files listed in reverse: one run."""
    full = make_run()
    float64 = 'std_msgs/msg/Float64'
    events = [e for e in full.events if e[2] == STRING]
    events += [(int(t), '/drive/speed', float64, cdr(STORE.types[float64](data=w), float64))
               for t, w in zip(full.stamps, full.omega)]
    events.sort(key=lambda e: e[0])
    run = Run(full.stamps, full.angle, full.omega, events)
    split, single = tmp_path / 'split', tmp_path / 'single.mcap'
    write_split(split, run)
    write_mcap(single, run)
    info = yaml.safe_load((split / 'metadata.yaml').read_text())
    info['rosbag2_bagfile_information']['relative_file_paths'].reverse()
    del info['rosbag2_bagfile_information']['files']        # no start times to sort by
    (split / 'metadata.yaml').write_text(yaml.safe_dump(info))
    names = InputTopics(speed='/drive/speed')
    a = replay(split, tmp_path / 'a.mcap', names=names)
    b = replay(single, tmp_path / 'b.mcap', names=names)
    assert a.accepted == b.accepted == len(run.stamps) and a.problems == b.problems == []
    got, want = read_outputs(tmp_path / 'a.mcap'), read_outputs(tmp_path / 'b.mcap')
    assert got.keys() == want.keys() and len(got) == 5
    for topic in got:
        assert np.array_equal(got[topic][0], run.stamps)
        assert np.array_equal(got[topic][1], want[topic][1]), topic
    motion, _ = read_inputs(open_bag(split), 'gantry_joint', names)
    assert np.array_equal(motion.omega, run.omega)


def test_directory_of_a_killed_recording(run, tmp_path):
    """No metadata.yaml, a last file left empty: the whole files are the run, the rest said."""
    killed = tmp_path / 'killed'
    killed.mkdir()
    write_mcap(killed / 'killed_0.mcap', run)
    (killed / 'killed_1.mcap').write_bytes(b'')
    summary = replay(killed)
    assert summary.accepted == len(run.stamps)
    assert any(p.startswith('no metadata.yaml') for p in summary.problems)
    assert any(p.startswith('killed_1.mcap: skipped: not an MCAP file') for p in summary.problems)
    # metadata.yaml with per-file entries that make no sense: the listed order is kept.
    (killed / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'storage_identifier': 'mcap', 'relative_file_paths': ['killed_0.mcap'],
        'files': [{'path': 'killed_0.mcap', 'starting_time': 'yesterday'}, 7]}}))
    assert replay(killed).accepted == len(run.stamps)
    (killed / 'killed_0.mcap').write_bytes(b'')
    with pytest.raises(BagError, match='no readable bag file'):
        replay(killed)
