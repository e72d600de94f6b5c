"""
The node's keyphasor input (:mod:`cvc_balance.ros.keyphasor_input`) in this process, by hand.

The node takes its tach as raw CDR bytes (test/test_tach_live.py runs the node in another
process, which a mutation run cannot see). Here the same object is given a stand-in node
(it records what would be subscribed, logged, processed and rejected) and the bytes rclpy
itself serialises: a tach of a rotor turning at a constant 2 pi / T rad/s, so every angle
and speed is known by hand: the angle since the newest mark 2 pi (t - t_mark) / T, the
speed 2 pi / T; TimeReference marks each giving 64 samples of the revolution they end.
"""

import math
import struct
from time import monotonic, time_ns
from types import SimpleNamespace

from rclpy.serialization import serialize_message
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64

from cvc_balance.ros.keyphasor_input import KeyphasorInput

FLOAT64, TIME_REFERENCE = 'std_msgs/msg/Float64', 'sensor_msgs/msg/TimeReference'
ORIGIN = 1_700_000_000_123_456_789                     # ns: the first sample's stamp


class Node:
    """What KeyphasorInput asks of its node, recorded."""

    def __init__(self, sim_time=False, recorder=None):
        self.timers, self.destroyed, self.subscriptions, self.logs = [], [], [], []
        self.processed, self.rejected, self.throttled, self.publishers = [], [], [], []
        self.now = 0
        self.publishing = '/ns/tach'                    # the topic the publishers are on
        self.sim_time = sim_time
        if recorder is not None:
            self._recorder = recorder

    def resolve_topic_name(self, topic):
        return topic if topic.startswith('/') else '/ns/' + topic

    def create_timer(self, period, callback):
        self.timers.append((period, callback))
        return ('timer', len(self.timers))

    def destroy_timer(self, timer):
        self.destroyed.append(timer)

    def _guarded(self, callback):
        return ('guarded', callback)

    def get_parameter(self, name):
        assert name == 'use_sim_time'
        return SimpleNamespace(value=self.sim_time)

    def get_publishers_info_by_topic(self, topic):
        return [SimpleNamespace(topic_type=kind) for kind in self.publishers
                if topic == self.publishing]

    def create_subscription(self, msg_type, topic, callback, qos, raw):
        self.subscriptions.append((msg_type, topic, callback, qos, raw))
        return 'subscription'

    def get_logger(self):
        return SimpleNamespace(error=lambda text: self.logs.append(('error', text)),
                               info=lambda text: self.logs.append(('info', text)))

    def get_clock(self):
        return SimpleNamespace(now=lambda: SimpleNamespace(nanoseconds=self.now))

    def _process(self, sec, nanosec, angle, omega, received):
        self.processed.append((sec, nanosec, angle, omega, received))

    def _reject(self, reason):
        self.rejected.append(reason)

    def _log_throttled(self, key, severity, message):
        self.throttled.append((key, severity, message))


def float64(value):
    return bytes(serialize_message(Float64(data=value)))


def time_reference(ns):
    message = TimeReference(source='tach')
    message.header.frame_id = 'gantry'
    message.time_ref.sec, message.time_ref.nanosec = divmod(ns, 10**9)
    return bytes(serialize_message(message))


def test_the_keyphasor_waits_for_one_kind_of_publisher_and_says_any_other():
    node = Node()
    tach = KeyphasorInput(node, 'tach', 'rising', None, 'qos')
    assert tach.topic == '/ns/tach'
    ((period, callback),) = node.timers
    assert (period, callback) == (0.2, ('guarded', tach.discover))
    assert tach.values() == {
        'keyphasor': '/ns/tach (waiting for a publisher)', 'keyphasor problem': '',
        'keyphasor marks': 0, 'keyphasor missed (put back)': 0,
        'keyphasor doubled (dropped)': 0, 'keyphasor irregular periods': 0,
        'keyphasor revolutions': 0, 'keyphasor period [s]': ''}
    tach.discover()                                      # no publisher yet
    assert (node.logs, node.subscriptions, tach.problem) == ([], [], '')
    said = ('/ns/tach is published as std_msgs/msg/Float64, std_msgs/msg/String: a keyphasor '
            'is std_msgs/msg/Float64 (a sampled tach) or sensor_msgs/msg/TimeReference (one '
            'message a mark), one of them')
    node.publishers = ['std_msgs/msg/String', FLOAT64]
    tach.discover()
    tach.discover()                                      # said once
    assert tach.problem == said and node.logs == [('error', f'keyphasor: {said}')]
    node.publishers = ['std_msgs/msg/String']
    tach.discover()
    alone = ('/ns/tach is published as std_msgs/msg/String: a keyphasor is '
             'std_msgs/msg/Float64 (a sampled tach) or sensor_msgs/msg/TimeReference (one '
             'message a mark), one of them')
    assert node.logs[1:] == [('error', f'keyphasor: {alone}')] and node.subscriptions == []
    assert tach.values()['keyphasor problem'] == alone
    node.publishers = [TIME_REFERENCE, TIME_REFERENCE]
    tach.discover()
    assert node.destroyed == [('timer', 1)] and tach.problem == ''
    ((kind, topic, callback, qos, raw),) = node.subscriptions
    assert (kind, topic, qos, raw) == (TimeReference, '/ns/tach', 'qos', True)
    assert callback == ('guarded', tach._on_time_reference)
    assert node.logs[2:] == [('info', 'keyphasor /ns/tach: sensor_msgs/msg/TimeReference')]
    assert tach.values()['keyphasor'] == '/ns/tach (sensor_msgs/msg/TimeReference)'


def test_a_sampled_tach_is_subscribed_and_recorded_when_the_node_records():
    written = []
    recorder = SimpleNamespace(add=lambda topic, kind: (
        written.append(('channel', topic, kind)) or
        (lambda log_time, data: written.append((log_time, data)))))
    node = Node(sim_time=True, recorder=recorder)
    tach = KeyphasorInput(node, '/tach', 'rising', 0.5, 'qos')
    tach.subscribe(FLOAT64)
    ((kind, topic, callback, qos, raw),) = node.subscriptions
    assert (kind, topic, callback, raw) == (Float64, '/tach', ('guarded', tach._on_float64),
                                            True)
    assert node.logs == [('info', 'keyphasor /tach: std_msgs/msg/Float64')]
    assert written == [('channel', '/tach', FLOAT64)]
    node.now = ORIGIN
    tach._on_float64(float64(0.0))                       # stamped by the node's (sim) clock
    assert written[1:] == [(ORIGIN, float64(0.0))] and tach.origin_ns == ORIGIN
    assert node.rejected == ['keyphasor: learning the period (0 marks of 4)']
    # A TimeReference tach with a threshold: the threshold is said to be ignored.
    node = Node(recorder=recorder)
    tach = KeyphasorInput(node, '/mark', 'rising', 0.5, 'qos')
    tach.subscribe(TIME_REFERENCE)
    assert node.logs == [('info', 'keyphasor /mark: sensor_msgs/msg/TimeReference (keyphasor_'
                                  'threshold applies to a sampled tach only: ignored)')]
    assert written[-1] == ('channel', '/mark', TIME_REFERENCE)
    node.now = ORIGIN + 5
    tach._on_time_reference(time_reference(ORIGIN))      # recorded at the node's clock
    assert written[-1] == (ORIGIN + 5, time_reference(ORIGIN)) and tach.origin_ns == ORIGIN
    # Without sim time a sample is stamped by the system clock, at its arrival.
    node = Node()
    tach = KeyphasorInput(node, '/tach', 'rising', 0.5, 'qos')
    before = time_ns()
    tach._on_float64(float64(0.0))
    assert before <= tach.origin_ns <= time_ns()
    assert tach.values()['keyphasor'] == '/tach (waiting for a publisher)'


def test_a_sampled_tach_gives_each_samples_angle_and_speed_by_hand():
    """
    Give each sample's angle since the newest mark and the speed: a sawtooth tach by hand.

    1 kHz samples of a sawtooth (k + 0.5) / 100 at the k-th sample of each T = 0.1 s turn:
    with the threshold 0.5 the rising crossing is midway between samples 49 and 50,
    0.0495 s past each turn's start (linear, so the interpolation is exact). The levels,
    judged at the 256th and 512th sample, are the medians of the samples below and above
    mid-range: about 0.25 and 0.75, so the hysteresis band is about 0.05 and a mark is
    known at sample 55 (0.555 - 0.5 beyond it, 0.545 - 0.5 not). The first mark is at
    0.3495 s, known at 0.355 s; four marks (three periods) learn the period; from the
    fourth (0.6495 s, known at 0.655 s) each sample's angle is 2 pi (t - t_mark) / T from
    the newest mark known, its speed 2 pi / T.
    """
    node = Node()
    tach = KeyphasorInput(node, '/tach', 'rising', 0.5, 'qos')
    omega = 2 * math.pi / 0.1
    resolutions, mark = [], tach.marks.mark
    tach.marks.mark = lambda time, resolution: resolutions.append(resolution) or mark(
        time, resolution)
    for j in range(1000):
        tach.float64(float64((j % 100 + 0.5) / 100.0), ORIGIN + j * 1_000_000, j + 0.5)
    assert node.rejected == \
        ['keyphasor: learning the period (0 marks of 4)'] * 355 + \
        ['keyphasor: learning the period (1 marks of 4)'] * 100 + \
        ['keyphasor: learning the period (2 marks of 4)'] * 100 + \
        ['keyphasor: learning the period (3 marks of 4)'] * 100
    assert len(node.processed) == 345
    for k, (sec, nanosec, angle, speed, received) in enumerate(node.processed):
        j = 655 + k
        mark = 49.5 + 100 * ((j - 55) // 100)            # ms of the newest mark known
        assert (sec, nanosec) == divmod(ORIGIN + j * 1_000_000, 10**9)
        assert received == j + 0.5
        assert abs(angle - omega * (j - mark) / 1000.0) < 1e-6, (j, angle)
        assert abs(speed - omega) < 1e-6 * omega
    marks = tach.marks
    # Each mark judged with the tach's resolution, its sample spacing.
    assert len(resolutions) == 7 and all(abs(r - 1e-3) < 1e-12 for r in resolutions)
    assert (marks.found, marks.revolutions) == (7, 6)
    assert abs(marks.period - 0.1) < 1e-9
    assert tach.values()['keyphasor period [s]'] == marks.period
    assert tach.summary() == ('keyphasor /tach: 7 marks, 0 missed (put back), 0 doubled '
                              '(dropped), 0 irregular periods (no angle there), 6 revolutions')
    assert node.throttled == []                          # nothing repaired: nothing said
    # Bytes that are no Float64: refused in words, nothing taken.
    for data in (float64(1.0)[:11], b'\x01\x00\x00\x00' + float64(1.0)[4:]):
        tach.float64(data, ORIGIN + 10**9, 0.0)
        assert node.rejected[-1] == '/tach message not readable as Float64'
    assert len(node.processed) == 345


def test_a_mark_a_message_gives_the_revolutions_it_ends_by_hand():
    """
    Give each revolution a TimeReference mark ends as 64 samples, by hand.

    Marks every T = 0.25 s: the fourth ends the learning, the three periods learnt come at
    once; each later mark its revolution: samples at start + T i / 64, angle 2 pi i / 64,
    speed 2 pi / T, each as late as the mark that gave it.
    """
    node = Node()
    tach = KeyphasorInput(node, '/mark', 'rising', None, 'qos')
    period_ns, omega = 250_000_000, 2 * math.pi / 0.25
    for k in range(6):
        tach.time_reference(time_reference(ORIGIN + k * period_ns), 100.0 + k)
    assert node.rejected == []
    assert len(node.processed) == 5 * 64
    for n, (sec, nanosec, angle, speed, received) in enumerate(node.processed):
        revolution, i = divmod(n, 64)
        stamp = ORIGIN + revolution * period_ns + round(i * period_ns / 64)
        assert (sec, nanosec) == divmod(stamp, 10**9), (n, sec, nanosec)
        assert abs(angle - 2 * math.pi * i / 64) < 1e-9
        assert abs(speed - omega) < 1e-9 * omega
        mark = 3 if revolution < 3 else revolution + 1   # the mark that gave it
        assert abs(received - (100.0 + mark - (mark - revolution - i / 64) * 0.25)) < 1e-9
    # A mark not after the previous, and bytes that are no TimeReference: said.
    tach.time_reference(time_reference(ORIGIN + 5 * period_ns), 200.0)
    assert node.rejected == [f'/mark: mark at {(ORIGIN + 5 * period_ns) * 1e-9:.9f} s not '
                             'after the previous']
    tach.time_reference(b'\x00\x01\x00\x00' + bytes(4), 200.0)
    assert node.rejected[-1] == ('/mark message not readable as TimeReference: not a '
                                 'little-endian CDR TimeReference')
    data = bytearray(time_reference(ORIGIN))
    struct.pack_into('<I', data, 12, 10**6)              # a frame_id past the message
    tach.time_reference(bytes(data), 200.0)
    assert node.rejected[-1] == ('/mark message not readable as TimeReference: TimeReference '
                                 'frame_id beyond the message')
    assert len(node.processed) == 5 * 64


def test_a_missed_and_a_doubled_mark_are_said_when_the_counts_change():
    node = Node()
    tach = KeyphasorInput(node, '/mark', 'rising', None, 'qos')
    period = 250_000_000
    times = [0, 1, 2, 3, 4, 6, 7, 7.5, 8, 9]             # 5 missed, one extra at 7.5
    for k in times:
        tach.time_reference(time_reference(ORIGIN + int(k * period)), 0.0)
    summary = 'keyphasor /mark: {} marks, {} missed (put back), {} doubled (dropped), 0 ' \
              'irregular periods (no angle there), {} revolutions'
    assert node.throttled == [('keyphasor', 'warning', summary.format(6, 1, 0, 6)),
                              ('keyphasor', 'warning', summary.format(9, 1, 1, 8))]
    assert tach.values()['keyphasor missed (put back)'] == 1
    assert tach.values()['keyphasor doubled (dropped)'] == 1
    # Every revolution between the first and the last mark, each once: 9 x 64 samples.
    assert len(node.processed) == 9 * 64


def test_samples_and_marks_as_they_arrive_are_stamped_and_timed_by_the_clocks():
    """The node's clock stamps a sample; each processed sample is as late as it arrived."""
    node = Node(sim_time=True)
    tach = KeyphasorInput(node, '/tach', 'rising', 0.5, 'qos')
    before = monotonic()
    for j in range(700):
        node.now = ORIGIN + j * 1_000_000
        tach._on_float64(float64((j % 100 + 0.5) / 100.0))
    after = monotonic()
    assert len(node.processed) == 45                      # from 0.655 s on (see above)
    assert all(before <= received <= after for *_, received in node.processed)
    assert node.processed[0][:2] == divmod(ORIGIN + 655 * 1_000_000, 10**9)
    node = Node(sim_time=True)
    tach = KeyphasorInput(node, '/mark', 'rising', None, 'qos')
    before = monotonic()
    for k in range(5):
        tach._on_time_reference(time_reference(ORIGIN + k * 250_000_000))
    after = monotonic()
    assert len(node.processed) == 4 * 64
    # Each sample as late as its revolution's mark came: at most 1 s before it arrived.
    assert all(before - 1.0 <= received <= after for *_, received in node.processed)
