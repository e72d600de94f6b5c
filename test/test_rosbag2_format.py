r"""
The bytes rosbag2 (Jazzy) writes, where it is deterministic: schema texts and metadata.

* Schema texts against ones built here the way rosbag2_cpp's ``get_full_text`` builds
  them (written again, line by line, from its source: the file's text, then per
  dependency in ``std::set`` order, depth first, "\n", 80 '=', "MSG: pkg/Type\n" and the
  file), from the .msg files the ament index gives, for every type the project writes.
* The YAML emitter against files rosbag2 itself wrote (test/data/rosbag2: its
  metadata.yaml, the ``serialized_metadata`` of its two ``rosbag2`` records, its channels'
  QoS): re-emitted from their parsed values, byte for byte.
* The ``rosbag2`` records and metadata.yaml of the project's own bags, read back by the
  ``mcap`` library and rosbags.
"""

from pathlib import Path
import select
import signal
import subprocess
import sys

from mcap.reader import make_reader
import pytest
from rosbags.rosbag2 import Reader as Rosbag2Reader
import yaml

from cvc_balance.bag.rosbag2_metadata import emit
from cvc_balance.messages import topics
from cvc_balance.messages.msg_schema import schema_text

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / 'test' / 'data' / 'rosbag2'
TYPES = sorted({value for name, value in vars(topics).items() if name.endswith('_TYPE')})
PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16',
              'uint16', 'int32', 'uint32', 'int64', 'uint64', 'string'}


def msg_file(kind):
    """Return the .msg file of 'pkg/Type' or 'pkg/msg/Type', found as rosbag2 does."""
    from ament_index_python.packages import get_package_share_directory
    package, *_, name = kind.split('/')
    return Path(get_package_share_directory(package)) / 'msg' / f'{name}.msg'


def used_types(text, package):
    """Return the types a .msg text's fields use, line by line (a line's first word)."""
    used = set()
    for line in text.split('\n'):
        words = line.split()
        if len(words) < 2 or not all(c.isalnum() or c in '_/[]' for c in words[0]):
            continue                 # blank, comment, or a bounded string (string<=N)
        kind = words[0].split('[')[0]
        if kind not in PRIMITIVES:
            used.add(kind if '/' in kind else f'{package}/{kind}')
    return sorted(used)              # std::set<std::string>: byte order


def rosbag2_full_text(root):
    """get_full_text of rosbag2_cpp's LocalMessageDefinitionSource, for .msg files."""
    seen = set()

    def append_recursive(kind):
        result = msg_file(kind).read_bytes().decode()
        for dependency in used_types(result, kind.split('/')[0]):
            if dependency not in seen:
                seen.add(dependency)
                result += '\n' + '=' * 80 + '\n' + f'MSG: {dependency}\n'
                result += append_recursive(dependency)
        return result
    return append_recursive(root)


@pytest.mark.parametrize('msg_type', TYPES)
def test_schema_text_is_rosbag2s(msg_type):
    assert schema_text(msg_type) == rosbag2_full_text(msg_type)


def test_schema_dependencies_in_rosbag2s_order():
    """The issue's example: WrenchStamped's are Wrench, Vector3, Header, Time."""
    text = schema_text(topics.WRENCH_TYPE)
    assert [line for line in text.split('\n') if line.startswith('MSG: ')] == \
        ['MSG: geometry_msgs/Wrench', 'MSG: geometry_msgs/Vector3', 'MSG: std_msgs/Header',
         'MSG: builtin_interfaces/Time']
    assert text.count('\n\n' + '=' * 80 + '\nMSG: ') == 4      # a blank line before each
    assert len(TYPES) >= 8 and topics.DIAGNOSTIC_ARRAY_TYPE in TYPES


def test_emitter_writes_the_bytes_rosbag2_wrote():
    real = (DATA / 'metadata.yaml').read_text()
    assert not real.endswith('\n')                       # rosbag2 ends it so; so do we
    assert emit(yaml.safe_load(real)) == real
    with open(DATA / 'bag_with_topics_and_service_events.mcap', 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        records = [m.metadata['serialized_metadata'] for m in reader.iter_metadata()]
        qos = [c.metadata['offered_qos_profiles']
               for c in reader.get_summary().channels.values()]
    assert len(records) == 2 and '  []' in records[0]      # opened (no topics), closed
    assert len(qos) == 5
    for text in records + qos:
        assert emit(yaml.safe_load(text)) == text


@pytest.fixture(scope='module')
def written(tmp_path_factory):
    """Simulate the tilted-shift scenario with a machine id: a file and a directory."""
    base = tmp_path_factory.mktemp('format')
    for name in ('one.mcap', 'dir'):
        run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'simulate',
                              ROOT / 'bags' / 'tilted_shift.yaml', '-o', base / name,
                              '--machine-id', 'g-7'], capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
    return base


@pytest.mark.parametrize('name, file', [('one.mcap', 'one.mcap'), ('dir', 'dir_0.mcap')])
def test_rosbag2_records_say_what_the_file_holds(written, name, file):
    path = written / name / file if name == 'dir' else written / name
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        records = [(m.name, m.metadata) for m in reader.iter_metadata()]
    assert [n for n, _ in records] == ['rosbag2', 'cvc_balance', 'rosbag2']
    opened, closed = (yaml.safe_load(values['serialized_metadata'])
                      for n, values in records if n == 'rosbag2')
    assert opened['message_count'] == 0 and opened['topics_with_message_count'] == []
    assert opened['starting_time'] == {'nanoseconds_since_epoch': 2**63 - 1}
    statistics = summary.statistics
    counts = {summary.channels[c].topic: n
              for c, n in statistics.channel_message_counts.items()}
    assert closed['ros_distro'] == opened['ros_distro'] == 'jazzy'
    assert closed['version'] == 9 and closed['storage_identifier'] == 'mcap'
    assert closed['message_count'] == statistics.message_count == sum(counts.values())
    assert closed['starting_time']['nanoseconds_since_epoch'] == statistics.message_start_time
    assert closed['duration']['nanoseconds'] == \
        statistics.message_end_time - statistics.message_start_time
    assert {t['topic_metadata']['name']: t['message_count']
            for t in closed['topics_with_message_count']} == counts
    assert closed['relative_file_paths'] == [file] and closed['files'][0]['path'] == file
    assert closed['custom_data'] == opened['custom_data'] == {'machine_id': 'g-7'}
    for channel in summary.channels.values():
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
        profile, = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert isinstance(profile['reliability'], int)        # Foxglove reads integers only
        assert profile['deadline'] == {'sec': 2147483647, 'nsec': 4294967295}
    if name == 'dir':       # metadata.yaml: the closed record under rosbag2_bagfile_information
        text = (written / name / 'metadata.yaml').read_text()
        serialized = dict(records)['rosbag2']['serialized_metadata']   # the last one
        assert text == '\n'.join(['rosbag2_bagfile_information:'] +
                                 ['  ' + line for line in serialized.split('\n')])
        # rosbags matches metadata.yaml's topics to the channels, QoS included: all read
        with Rosbag2Reader(written / name) as reader:
            assert reader.message_count == statistics.message_count
            assert sum(1 for _ in reader.messages()) == statistics.message_count > 6000
            qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
        assert qos['/layout'].durability.name == 'TRANSIENT_LOCAL'
        assert qos['/joint_states'].reliability.name == 'BEST_EFFORT'


def test_record_takes_the_publishers_qos_as_rosbag2_does(tmp_path):
    """
    A topic found by a pattern is subscribed and recorded as its publishers offer.

    Before, by its name: every supports/*/load reliable, so a best-effort publisher's
    messages never came (an incompatible QoS) and its topic was recorded empty.
    """
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import qos_profile_sensor_data, QoSProfile
    from ros_harness import Probe, ros_environment
    probe = Probe('qos_probe')
    out = tmp_path / 'rec.mcap'
    recorder = None
    try:
        front = probe.node.create_publisher(WrenchStamped, 'supports/front/load',
                                            qos_profile_sensor_data)
        rear = probe.node.create_publisher(WrenchStamped, 'supports/rear/load',
                                           QoSProfile(depth=10))
        recorder = subprocess.Popen(
            [sys.executable, '-m', 'cvc_balance.cli', 'record', '-o', str(out),
             'supports/*/load', '--ready-when', 'supports/front/load',
             '--ready-when', 'supports/rear/load'],
            env=ros_environment(), stdout=subprocess.PIPE, text=True)
        assert probe.spin_until(lambda: front.get_subscription_count() >= 1 and
                                rear.get_subscription_count() >= 1, timeout=20)
        said, _, _ = select.select([recorder.stdout], [], [], 20)    # ready, a pattern's too
        assert said and recorder.stdout.readline().strip() == 'ready'
        for _ in range(20):
            front.publish(WrenchStamped())
            rear.publish(WrenchStamped())
            probe.spin_for(0.01)
        probe.spin_for(0.3)
        recorder.send_signal(signal.SIGINT)
        recorder.communicate(timeout=20)
    finally:
        if recorder is not None:
            recorder.kill()
        probe.close()
    with open(out, 'rb') as stream:
        summary = make_reader(stream, validate_crcs=True).get_summary()
    qos = {}
    for channel in summary.channels.values():
        profile, = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        qos[channel.topic] = (profile['reliability'], profile['durability'])
    assert qos == {'/supports/front/load': (2, 2), '/supports/rear/load': (1, 2)}
    counts = {summary.channels[c].topic: n
              for c, n in summary.statistics.channel_message_counts.items()}
    assert counts == {'/supports/front/load': 20, '/supports/rear/load': 20}
