"""
Record ROS topics to a bag: raw CDR bytes straight from the subscriptions.

A :class:`BagRecorder` attaches to any node: it subscribes (raw, no
deserialisation) to the topics it is given, to topics matching a pattern as
they appear (``supports/*/load``), and writes each message with its receive
time as log time. Used by ``cvc-balance record``, ``cvc-balance play`` and the
node's ``record_path`` parameter. Finalise with :meth:`close` (SIGINT/SIGTERM
handlers do); a killed process leaves all finished chunks readable.
"""

import fnmatch
import importlib

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from cvc_balance.bag.machine import custom_data
from cvc_balance.bag.rosbag2 import open_writer
from cvc_balance.messages import topics
from cvc_balance.ros.executor import init, spin

DEFAULT_TOPICS = (topics.JOINT_STATES, topics.SPEED, topics.LAYOUT, *topics.OUTPUTS,
                  topics.support_load('*'), topics.measured_load('*'),
                  topics.IDENTIFIED_UNBALANCE, topics.UNBALANCE_RESIDUAL, topics.DIAGNOSTICS)
KNOWN_TYPES = {topics.JOINT_STATES: topics.JOINT_STATE_TYPE,
               topics.SPEED: topics.FLOAT64_TYPE, topics.LAYOUT: topics.STRING_TYPE,
               topics.DIAGNOSTICS.strip('/'): topics.DIAGNOSTIC_ARRAY_TYPE}


def message_class(msg_type):
    """Return the Python class of 'pkg/msg/Type'."""
    package, _, name = msg_type.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


class BagRecorder:
    """Record topics of a node's graph to ``path`` (see the module's description)."""

    def __init__(self, node, path, names=DEFAULT_TOPICS, compression='zstd',
                 chunk_bytes=1 << 20, machine_id=None, label=None):
        """
        Subscribe ``node`` to topic ``names`` (or patterns with '*'), write ``path``.

        ``path``: a .mcap file, or else a rosbag2 directory (see ``bag.rosbag2``), created:
        an existing name (also a link to a file) is refused with a BagError, never
        replaced; ``machine_id``: the machine recorded, ``label``: the field-balancing run
        it is (``bag.run_label``), both written into the bag (``bag.machine``).
        """
        self.node = node
        self.writer = open_writer(path, compression=compression, chunk_bytes=chunk_bytes,
                                  custom_data=custom_data(machine_id, label),
                                  exclusive=True)
        self.counts = {}
        self._patterns = []
        self._subscribed = {}
        self._channels = {}
        for topic in names:
            name = node.resolve_topic_name(topic) if '*' not in topic else topic
            if '*' in topic:
                self._patterns.append(topic if topic.startswith('/') else
                                      node.resolve_topic_name('x')[:-1] + topic)
            else:
                self._subscribe(name, KNOWN_TYPES.get(name.rsplit('/', 1)[-1],
                                                      topics.WRENCH_TYPE))
        self._timer = node.create_timer(0.2, self.discover) if self._patterns else None

    def discover(self):
        """Subscribe to topics that match the patterns and have appeared since."""
        for name, types in self.node.get_topic_names_and_types():
            if name not in self._subscribed and types and any(
                    fnmatch.fnmatchcase(name, p) for p in self._patterns):
                self._subscribe(name, types[0])

    def subscription(self, name):
        """Return the subscription of a recorded topic (None if not subscribed)."""
        return self._subscribed.get(name)

    def add(self, topic, msg_type):
        """Return a function(log_time_ns, data) writing messages the node itself makes."""
        name = self.node.resolve_topic_name(topic)
        channel = self.writer.add_channel(name, msg_type)
        self.counts[name] = 0

        def write(log_time, data):
            self.writer.write(channel, log_time, data)
            self.counts[name] += 1
        return write

    def write(self, topic, log_time, data):
        """
        Write a message of a recorded topic that did not come through the subscription.

        (The node's layout from its layout_file: it is in force, so the bag carries it.)
        """
        name = self.node.resolve_topic_name(topic)
        self.writer.write(self._channels[name], log_time, data)
        self.counts[name] += 1

    def _offered(self, name):
        """
        Return (best effort, latched) as rosbag2 adapts to the topic's publishers, or None.

        rosbag2's recorder (``Rosbag2QoS::adapt_request_to_offers``) subscribes reliable
        only when every publisher offers reliable, transient local only when every one
        does, and records the publishers' offers. The bag gets that profile, in the
        form both rosbag2 and Foxglove read (``bag.rosbag2_metadata``: integers, Foxy's
        infinite durations). None without publishers yet.
        """
        offers = [info.qos_profile for info in self.node.get_publishers_info_by_topic(name)]
        if not offers:
            return None
        return (any(q.reliability != ReliabilityPolicy.RELIABLE for q in offers),
                all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offers))

    def _subscribe(self, name, msg_type):
        short = name.rsplit('/', 1)[-1]
        # Without publishers yet, what the project's own publishers offer (ros/qos.py): the
        # layout latched; sensor streams best effort (a reliable subscription would match
        # none of them).
        best_effort, latched = self._offered(name) or (
            short in (topics.JOINT_STATES, topics.SPEED, topics.MEASURED_LOAD),
            short == topics.LAYOUT)
        channel = self.writer.add_channel(name, msg_type, latched=latched,
                                          best_effort=best_effort)
        self._channels[name] = channel
        qos = QoSProfile(depth=1000,
                         reliability=(ReliabilityPolicy.BEST_EFFORT if best_effort
                                      else ReliabilityPolicy.RELIABLE),
                         durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                     else DurabilityPolicy.VOLATILE))
        self.counts[name] = 0
        clock = self.node.get_clock()

        def record(data):
            self.writer.write(channel, clock.now().nanoseconds, data)
            self.counts[name] += 1

        self._subscribed[name] = self.node.create_subscription(
            message_class(msg_type), name, record, qos, raw=True)

    def close(self):
        """Finalise the bag (summary, footer)."""
        if self._timer is not None:
            self._timer.cancel()
        self.writer.close()


def record_main(args):
    """Run ``cvc-balance record``: record until SIGINT or SIGTERM; return the exit code."""
    import rclpy

    init(args=['cvc_balance_record', '--ros-args', *args.ros_args])
    node = rclpy.create_node('cvc_balance_recorder')
    recorder = BagRecorder(node, args.output, args.topics or DEFAULT_TOPICS,
                           '' if args.compression == 'none' else args.compression,
                           args.chunk_kib * 1024, args.machine_id, args.run_label)
    try:     # from here on a Ctrl-C still finalises the bag
        if args.ready_when:
            # Say 'ready' once the subscriptions have matched a publisher (reader side); a
            # topic found by a pattern has its subscription once it is discovered.
            names = [node.resolve_topic_name(t) for t in args.ready_when]

            def check():
                wanted = [recorder.subscription(name) for name in names]
                if all(s is not None and s.get_publisher_count() > 0 for s in wanted):
                    print('ready', flush=True)
                    timer.cancel()
            timer = node.create_timer(0.05, check)
        spin(node)
    finally:
        recorder.close()
        node.destroy_node()
        rclpy.try_shutdown()
    total = sum(recorder.counts.values())
    print(f'{args.output}: {total} messages: ' + ', '.join(
        f'{topic} {count}' for topic, count in sorted(recorder.counts.items())))
    return 0
