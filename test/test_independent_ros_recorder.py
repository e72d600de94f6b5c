"""
The bag recorder (:mod:`cvc_balance.ros.recorder`) in this process, read back by ``mcap``.

``cvc-balance record`` and the node's recording run it in their own processes
(test/test_bags.py, test/test_data_loss.py), which a mutation run cannot see. Here it is
attached to a stand-in node that records what would be subscribed, and the bag it writes
is read back by the ``mcap`` library: each topic's channel and type, the QoS it offers
(rmw's integers: reliability 1 reliable, 2 best effort; durability 1 transient local,
2 volatile), each message's bytes and log time, the machine's id and run label.
"""

from types import SimpleNamespace

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from mcap.reader import make_reader
import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
import yaml

from cvc_balance.bag.mcap_reader import BagError
from cvc_balance.bag.run_label import RunLabel
from cvc_balance.ros.recorder import BagRecorder, DEFAULT_TOPICS, message_class

RELIABLE, BEST_EFFORT = ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT
LATCHED, VOLATILE = DurabilityPolicy.TRANSIENT_LOCAL, DurabilityPolicy.VOLATILE


class Node:
    """What BagRecorder asks of its node, recorded."""

    def __init__(self):
        self.subscriptions, self.timers, self.offers, self.topics = {}, [], {}, []
        self.now = 1_000

    def resolve_topic_name(self, topic):
        return topic if topic.startswith('/') else '/ns/' + topic

    def create_timer(self, period, callback):
        timer = SimpleNamespace(period=period, callback=callback, cancelled=False)
        timer.cancel = lambda: setattr(timer, 'cancelled', True)
        self.timers.append(timer)
        return timer

    def get_topic_names_and_types(self):
        return self.topics

    def get_publishers_info_by_topic(self, name):
        return [SimpleNamespace(qos_profile=SimpleNamespace(reliability=r, durability=d))
                for r, d in self.offers.get(name, ())]

    def get_clock(self):
        return SimpleNamespace(now=lambda: SimpleNamespace(nanoseconds=self.now))

    def create_subscription(self, msg_type, name, callback, qos, raw):
        assert raw is True
        self.subscriptions[name] = (msg_type, callback, qos)
        return SimpleNamespace(name=name, get_publisher_count=lambda: self.publishers.get(
            name, 0))

    publishers = {}

    def destroy_node(self):
        self.destroyed = True


def read(path):
    """Return {topic: (type, best effort, latched, [(log time, bytes)])} and the metadata."""
    topics, metadata = {}, {}
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        for channel in summary.channels.values():
            (profile,) = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            assert profile['reliability'] in (1, 2) and profile['durability'] in (1, 2)
            topics[channel.topic] = (summary.schemas[channel.schema_id].name,
                                     profile['reliability'] == 2, profile['durability'] == 1,
                                     [])
        for _, channel, message in reader.iter_messages(log_time_order=True):
            topics[channel.topic][3].append((message.log_time, message.data))
        for record in reader.iter_metadata():
            metadata.update(record.metadata)
        compressions = {c.compression for c in summary.chunk_indexes}
    return topics, metadata, compressions


def test_message_classes_by_their_names():
    assert message_class('std_msgs/msg/Float64') is Float64
    assert message_class('geometry_msgs/msg/WrenchStamped') is WrenchStamped
    assert message_class('diagnostic_msgs/msg/DiagnosticArray') is DiagnosticArray


def test_the_default_topics_subscribed_with_the_qos_their_publishers_offer(tmp_path):
    node = Node()
    node.offers = {'/ns/speed': [(RELIABLE, VOLATILE)],                 # reliable offered
                   '/ns/layout': [(RELIABLE, LATCHED), (RELIABLE, VOLATILE)],
                   '/ns/unbalance': [(RELIABLE, LATCHED), (BEST_EFFORT, LATCHED)]}
    recorder = BagRecorder(node, tmp_path / 'run.mcap', machine_id='gantry-7',
                           label=RunLabel('check'))
    expected = {  # topic: (class, best effort, latched)
        '/ns/joint_states': (JointState, True, False),      # no publisher: sensor data
        '/ns/speed': (Float64, False, False),
        '/ns/layout': (String, False, False),                # not every publisher latches
        '/ns/bearing_load': (WrenchStamped, False, False),
        '/ns/unbalance': (WrenchStamped, True, True),
        '/ns/drive_torque': (WrenchStamped, False, False),
        '/ns/identified_unbalance': (WrenchStamped, False, False),
        '/ns/unbalance_residual': (WrenchStamped, False, False),
        '/diagnostics': (DiagnosticArray, False, False)}
    assert set(node.subscriptions) == set(expected)
    for name, (kind, best_effort, latched) in expected.items():
        msg_type, _, qos = node.subscriptions[name]
        assert msg_type is kind, name
        assert qos.depth == 1000
        assert qos.reliability == (BEST_EFFORT if best_effort else RELIABLE), name
        assert qos.durability == (LATCHED if latched else VOLATILE), name
        assert recorder.subscription(name).name == name
    assert recorder.subscription('/ns/other') is None
    assert recorder.counts == dict.fromkeys(expected, 0)
    (timer,) = node.timers
    assert (timer.period, timer.callback) == (0.2, recorder.discover)
    # Cells and support loads appear later: subscribed once they match a pattern.
    node.topics = [('/ns/supports/front/measured_load', ['geometry_msgs/msg/WrenchStamped']),
                   ('/ns/supports/rear/load', ['geometry_msgs/msg/WrenchStamped']),
                   ('/ns/supports/rear/measured_load', []),           # no type yet
                   ('/other/supports/front/load', ['geometry_msgs/msg/WrenchStamped']),
                   ('/ns/supports/front/temperature', ['std_msgs/msg/Float64']),
                   ('/ns/speed', ['std_msgs/msg/String'])]             # subscribed already
    recorder.discover()
    recorder.discover()
    assert set(node.subscriptions) - set(expected) == {
        '/ns/supports/front/measured_load', '/ns/supports/rear/load'}
    cell = node.subscriptions['/ns/supports/front/measured_load']
    assert cell[0] is WrenchStamped and cell[2].reliability == BEST_EFFORT
    assert node.subscriptions['/ns/supports/rear/load'][2].reliability == RELIABLE
    assert node.subscriptions['/ns/speed'][0] is Float64
    # Messages: each written with the node's clock at its arrival.
    node.now = 5_000
    node.subscriptions['/ns/speed'][1](b'speed one')
    node.now = 6_000
    node.subscriptions['/ns/supports/front/measured_load'][1](b'cell one')
    node.subscriptions['/ns/speed'][1](b'speed two')
    own = recorder.add('keyphasor', 'std_msgs/msg/Float64')
    own(7_000, b'mark')
    own(7_500, b'mark two')
    recorder.write('layout', 8_000, b'layout text')
    recorder.write('/ns/layout', 8_500, b'layout two')
    assert recorder.counts['/ns/speed'] == 2 and recorder.counts['/ns/keyphasor'] == 2
    assert recorder.counts['/ns/layout'] == 2
    recorder.close()
    assert timer.cancelled
    topics, metadata, compressions = read(tmp_path / 'run.mcap')
    assert compressions == {'zstd'}
    for name, (kind, best_effort, latched) in expected.items():
        assert topics[name][:3] == (kind.__module__.split('.')[0] + '/msg/' + kind.__name__,
                                    best_effort, latched), name
    assert topics['/ns/supports/front/measured_load'][1:] == (True, False,
                                                              [(6_000, b'cell one')])
    assert topics['/ns/speed'][3] == [(5_000, b'speed one'), (6_000, b'speed two')]
    assert topics['/ns/keyphasor'] == ('std_msgs/msg/Float64', False, False,
                                       [(7_000, b'mark'), (7_500, b'mark two')])
    assert topics['/ns/layout'][3] == [(8_000, b'layout text'), (8_500, b'layout two')]
    assert metadata['machine_id'] == 'gantry-7' and metadata['run'] == 'check'


def test_given_topics_and_patterns_an_absolute_pattern_and_no_compression(tmp_path):
    node = Node()
    recorder = BagRecorder(node, tmp_path / 'run.mcap', ['layout', '/abs/*/x', 'a/*'],
                           compression='', chunk_bytes=1024)
    assert set(node.subscriptions) == {'/ns/layout'}
    layout = node.subscriptions['/ns/layout'][2]
    assert (layout.reliability, layout.durability) == (RELIABLE, LATCHED)
    node.topics = [('/abs/b/x', ['std_msgs/msg/String']), ('/ns/a/c', ['std_msgs/msg/Float64']),
                   ('/a/c', ['std_msgs/msg/Float64'])]
    recorder.discover()
    assert set(node.subscriptions) == {'/ns/layout', '/abs/b/x', '/ns/a/c'}
    for k in range(200):
        node.subscriptions['/ns/a/c'][1](bytes(16))
    recorder.close()
    topics, _, compressions = read(tmp_path / 'run.mcap')
    assert compressions == {''}
    assert topics['/ns/layout'][:3] == ('std_msgs/msg/String', False, True)
    assert len(topics['/ns/a/c'][3]) == 200
    with open(tmp_path / 'run.mcap', 'rb') as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) > 1      # 1 KiB chunks
    # Without patterns: no timer; an existing file is never replaced.
    node = Node()
    recorder = BagRecorder(node, tmp_path / 'two.mcap', ['speed'])
    assert node.timers == [] and set(node.subscriptions) == {'/ns/speed'}
    recorder.close()
    before = (tmp_path / 'run.mcap').read_bytes()
    with pytest.raises(BagError):
        BagRecorder(Node(), tmp_path / 'run.mcap', DEFAULT_TOPICS)
    assert (tmp_path / 'run.mcap').read_bytes() == before


def test_the_record_command_records_until_stopped_and_says_what_it_wrote(
        tmp_path, monkeypatch, capsys):
    """
    Run ``cvc-balance record`` with rclpy's start, node and spin stood in for.

    Ready once every topic named in ``ready_when`` has a publisher (checked every 0.05 s);
    the bag finalised, the node destroyed and rclpy shut down after spinning; one line of
    counts per topic.
    """
    import rclpy
    from cvc_balance.ros import recorder as module
    node, started, shut = Node(), [], []

    def spin(spun):
        assert spun is node
        ((period, check),) = [(t.period, t.callback) for t in node.timers
                              if t.period != 0.2]
        assert period == 0.05
        check()                                   # no publisher yet: not ready
        node.publishers = {'/ns/speed': 1}
        check()                                   # one of two: not ready
        print('checked', flush=True)
        node.publishers = {'/ns/speed': 1, '/ns/layout': 2}
        check()
        node.subscriptions['/ns/speed'][1](b'one')
        node.subscriptions['/ns/speed'][1](b'two')
        node.subscriptions['/ns/layout'][1](b'text')
        for _ in range(200):                      # 47 bytes a record: about 22 a chunk
            node.subscriptions['/ns/layout'][1](bytes(16))
    monkeypatch.setattr(module, 'init', lambda args: started.append(args))
    monkeypatch.setattr(module, 'spin', spin)
    monkeypatch.setattr(rclpy, 'create_node', lambda name: started.append(name) or node)
    monkeypatch.setattr(rclpy, 'try_shutdown', lambda: shut.append(True))
    args = SimpleNamespace(ros_args=['-r', '__ns:=/ns'], output=str(tmp_path / 'r.mcap'),
                           topics=['speed', 'layout', 'other/*'], compression='none',
                           chunk_kib=1, machine_id='gantry-9', run_label=RunLabel('trim'),
                           ready_when=['speed', 'layout'])
    assert module.record_main(args) == 0
    assert started == [['cvc_balance_record', '--ros-args', '-r', '__ns:=/ns'],
                       'cvc_balance_recorder']
    assert node.destroyed and shut == [True]
    assert all(t.cancelled for t in node.timers)
    assert capsys.readouterr().out == (f'checked\nready\n{tmp_path / "r.mcap"}: 203 messages: '
                                       '/ns/layout 201, /ns/speed 2\n')
    topics, metadata, compressions = read(tmp_path / 'r.mcap')
    assert set(topics) == {'/ns/speed', '/ns/layout'} and compressions == {''}
    with open(tmp_path / 'r.mcap', 'rb') as stream:
        assert 5 < len(make_reader(stream).get_summary().chunk_indexes) < 20    # 1 KiB
    assert topics['/ns/speed'][3] == [(1_000, b'one'), (1_000, b'two')]
    assert (metadata['machine_id'], metadata['run']) == ('gantry-9', 'trim')
    # The default topics, zstd, no readiness asked: spun at once.
    node = Node()
    monkeypatch.setattr(module, 'spin', lambda spun: node.subscriptions['/ns/speed'][1](b'x'))
    args = SimpleNamespace(ros_args=[], output=str(tmp_path / 'd.mcap'), topics=None,
                           compression='zstd', chunk_kib=1024, machine_id=None,
                           run_label=None, ready_when=None)
    assert module.record_main(args) == 0
    assert set(node.subscriptions) == {
        '/ns/joint_states', '/ns/speed', '/ns/layout', '/ns/bearing_load', '/ns/unbalance',
        '/ns/drive_torque', '/ns/identified_unbalance', '/ns/unbalance_residual',
        '/diagnostics'}
    assert [t.period for t in node.timers] == [0.2]
    out = capsys.readouterr().out
    assert out.startswith(f'{tmp_path / "d.mcap"}: 1 messages: /diagnostics 0, ')
    topics, metadata, compressions = read(tmp_path / 'd.mcap')
    assert metadata.get('machine_id') is None and compressions == {'zstd'}
