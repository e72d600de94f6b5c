"""
Play a bag's inputs into the ROS graph with their timing, and record what comes back.

``cvc-balance play BAG [--rate X] [-o OUT]``: layout messages go out latched
(transient local), motion samples (joint_states, speed, or a keyphasor's
messages on ``keyphasor``: the node takes them with ``keyphasor_topic:=keyphasor``)
as their raw bytes at their log times scaled by 1 / rate (never in a burst: a player
descheduled for more than 50 ms goes on from where it is, and says so). After each layout
the player pauses (bag time is then shifted) until the node says, on ``/diagnostics``, that
it has that layout in force (its digest), so that the next sample is computed with it, as
replay computes it; at least 50 ms, at most ``wait`` s (a layout the node refuses: then it
says so and goes on). With ``-o`` the node's outputs (topics derived from the bag's
layouts) are recorded to OUT by a ``cvc-balance record`` child process, until they have
been quiet for 1 s after the last input (a node that fell behind answers its backlog
first). Samples start once the node subscribes to them, the recorder has matched the
node's outputs, and 1.5 s more (DDS discovery is one-sided: the other end may match a
moment later). Each wait says what it waits for and gives up after ``wait`` seconds with a
:class:`PlayError` naming it.

While playing it listens to ``/diagnostics`` and, at the end, reports the node's
own verdict per layout (the last status it published for each layout digest).
"""

import select
import signal
import subprocess
import sys
import threading
import time

from cvc_balance.bag.inputs import input_channels
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import read_string_message
from cvc_balance.physics.keyphasor import marks_summary
from cvc_balance.ros.qos import input_qos, LAYOUT_QOS, OUTPUT_QOS
from cvc_balance.ros.recorder import message_class

MAX_LATE = 0.05
"""Most (s) the player lets itself fall behind the bag's pace: later than that (the process
was descheduled on a busy machine) it goes on from where it is, bag time shifted, rather
than send the late messages at once: a burst of seconds of 1 kHz samples overflows the
node's best-effort input queue (1000), and 637 of 6001 samples were lost that way."""
LAYOUT_PAUSE = 0.05
"""Least pause (s) after a layout, and the whole pause for one the player cannot parse."""
WAIT = 20.0
"""Default time (s) to wait for the node and the recorder before giving up."""


class PlayError(RuntimeError):
    """Nothing to play into (no node, no recorder); ``str()`` says what was waited for."""


def parsed_layouts(layout_texts):
    """
    Return ({text: its digest, None if it is no layout}, the node's output topics for them).

    The digest is the one the node names on /diagnostics for the layout in force; the
    topics are the node's outputs with each layout's supports. Each text is parsed once.
    """
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    digests, names = {}, list(topics.OUTPUTS)
    for text in layout_texts:
        if text in digests:
            continue
        try:
            layout = layout_from_text(text)
        except LayoutError:
            digests[text] = None
            continue
        digests[text] = layout.digest()
        for support in layout.supports:
            topic = topics.support_load(support.name)
            if topic not in names:
                names.append(topic)
    return digests, names


def cell_channels(bag):
    """Return [(the node's topic, channel)] of the bag's load cells (supports/*/measured_load)."""
    found = []
    for channel in bag.channels.values():
        parts = channel.topic.strip('/').split('/')
        if len(parts) >= 3 and parts[-3] == 'supports' and parts[-1] == topics.MEASURED_LOAD \
                and channel.msg_type == topics.WRENCH_TYPE:
            found.append((topics.measured_load(parts[-2]), channel))
    return found


def play(bag_path, rate=1.0, output=None, wait=WAIT, quiet=1.0, settle=1.5, say=print,
         names=None):
    """
    Publish the bag's inputs; return (messages published, recorder's report, verdicts).

    ``bag_path``: a bag file or rosbag2 directory; ``names`` (InputTopics): its input
    topics if not the node's own. They are published on the node's topic names.

    ``verdicts``: {layout digest: {key: value}} of the last /diagnostics status the node
    published for each layout, in the order first seen. Raises :class:`PlayError` when
    no node subscribes to the motion topic, or the recorder does not match the node's
    outputs, within ``wait`` s.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    bag = open_bag(bag_path)
    channels = input_channels(bag, names)      # BagError names the bag's topics
    inputs = []
    for topic, msg_type, qos, channel in (
            (topics.JOINT_STATES, topics.JOINT_STATE_TYPE, input_qos(1000),
             channels.joint_states),
            (topics.SPEED, topics.FLOAT64_TYPE, input_qos(1000), channels.speed),
            (topics.KEYPHASOR, channels.keyphasor and channels.keyphasor.msg_type,
             input_qos(1000), channels.keyphasor),
            (topics.LAYOUT, topics.STRING_TYPE, LAYOUT_QOS, channels.layout)):
        if channel is not None:
            inputs.append((topic, msg_type, qos, bag.messages(channel)))
    for topic, channel in cell_channels(bag):       # load cells are inputs too
        inputs.append((topic, topics.WRENCH_TYPE, input_qos(1000), bag.messages(channel)))
    for problem in bag.problems:
        say(f'play: {bag_path}: {problem}')
    layouts = [data for topic, _, _, messages in inputs if topic == topics.LAYOUT
               for _, data in messages]
    digests, outputs = parsed_layouts([read_string_message(data) for data in layouts])
    if any(topic.endswith(topics.MEASURED_LOAD) for topic, *_ in inputs):
        outputs += [topics.IDENTIFIED_UNBALANCE, topics.UNBALANCE_RESIDUAL]
    rclpy.init()
    node = rclpy.create_node('cvc_balance_player')
    verdicts = VerdictLog(node)
    answers = AnswerClock(node, outputs[0])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor,), daemon=True)
    spinner.start()
    recorder = None
    try:
        publishers = {topic: node.create_publisher(message_class(msg_type), topic, qos)
                      for topic, msg_type, qos, _ in inputs}
        events = sorted((log_time, topic, data) for topic, _, _, messages in inputs
                        for log_time, data in messages)
        motion = next(t for t in (topics.JOINT_STATES, topics.SPEED, topics.KEYPHASOR)
                      if t in publishers)
        name = node.resolve_topic_name(motion)
        say(f'play: waiting up to {wait:g} s for a node subscribed to {name} '
            '(balance_monitor)', flush=True)
        if not _wait(lambda: publishers[motion].get_subscription_count() > 0, wait):
            hint = (f' with -p keyphasor_topic:={topics.KEYPHASOR}'
                    if motion == topics.KEYPHASOR else '')
            raise PlayError(f'no node subscribed to {name} within {wait:g} s: start the '
                            f'balance_monitor node first{hint} (./dev.sh demo does), or wait '
                            'longer with --wait')
        subscribers = sorted({f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                              for i in node.get_subscriptions_info_by_topic(name)
                              if 'UNKNOWN' not in i.node_name})
        say(f"play: {name} is subscribed"
            + (f" by {', '.join(subscribers)}" if subscribers else ''), flush=True)
        # The recorder runs in its own process: its thousands of callbacks a second must
        # not starve this one's timing (bursts would overflow the node's input queue).
        # Started once a node is there, so that giving up leaves no empty file behind.
        if output:
            recorder = subprocess.Popen(
                [sys.executable, '-m', 'cvc_balance.cli', 'record', '-o', str(output),
                 '--ready-when', outputs[0], *outputs, topics.DIAGNOSTICS],
                stdout=subprocess.PIPE, text=True)
        first_sample = next(i for i, (_, topic, _) in enumerate(events)
                            if topic != topics.LAYOUT)

        def put_in_force(data):
            return _put_in_force(publishers[topics.LAYOUT], data,
                                 digests[read_string_message(data)], verdicts, wait, say)

        for log_time, topic, data in events[:first_sample]:
            if topic == topics.LAYOUT:                # the layouts in force from the start
                put_in_force(data)
            else:
                publishers[topic].publish(data)
        if recorder is not None:
            say(f'play: waiting up to {wait:g} s for the recorder to match the node\'s '
                f'{node.resolve_topic_name(outputs[0])} output', flush=True)
            if _read_line(recorder.stdout, wait) != 'ready':
                raise PlayError(f'the recorder saw no publisher of '
                                f'{node.resolve_topic_name(outputs[0])} within {wait:g} s: '
                                'is the node running with a layout?')
        if first_sample and outputs[3:]:     # the first layout's supports are being published
            _wait(lambda: node.count_publishers(outputs[3]) > 0, wait)
        # DDS matching is one-sided: what this side sees, the other may see a moment later.
        time.sleep(settle)
        published, start_log = first_sample, events[first_sample][0]
        start_wall = time.monotonic()
        behind, paused = 0, 0.0
        for log_time, topic, data in events[first_sample:]:
            left = start_wall + (log_time - start_log) * 1e-9 / rate - time.monotonic()
            if left > 0:
                time.sleep(left)
            elif left < -MAX_LATE:          # descheduled: go on from here, no burst
                behind, paused, start_wall = behind + 1, paused - left, start_wall - left
            if topic == topics.LAYOUT:
                start_wall += put_in_force(data)
            else:
                publishers[topic].publish(data)
            published += 1
        if behind:
            say(f"play: fell behind the bag's pace {behind} time{'s' if behind > 1 else ''} "
                f'(a busy machine?): paused {paused:.2f} s in all rather than send the late '
                'messages in a burst', flush=True)
        # The last outputs, and the node's verdict, come back: a node that fell behind (a
        # busy machine) answers its backlog first, so wait for its outputs to go quiet.
        time.sleep(quiet)
        if not _wait(lambda: time.monotonic() - answers.last >= quiet, wait):
            say(f'play: the node still answered {wait:g} s after the last input; '
                'recording stops', flush=True)
        report = None
        if recorder is not None:
            recorder.send_signal(signal.SIGINT)
            report = recorder.communicate(timeout=30)[0].strip()
            recorder = None
        return published, report, verdicts.latest()
    finally:
        if recorder is not None:          # given up: the recorder we started goes too
            recorder.send_signal(signal.SIGINT)
            try:
                recorder.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                recorder.kill()
                recorder.communicate()
        executor.shutdown()
        spinner.join(timeout=5)
        node.destroy_node()
        rclpy.try_shutdown()


def _put_in_force(publisher, data, digest, verdicts, wait, say):
    """
    Publish a layout; wait until the node has it in force; return the seconds it took.

    ``digest``: the layout's (None: it is no layout, the node will refuse it: then only
    LAYOUT_PAUSE). In force: the node published a /diagnostics status with that digest
    after this layout went out (a layout equal to the one in force too: it is put in
    force again). At most ``wait`` s, then it says so and goes on.
    """
    seen = verdicts.statuses(digest)
    started = time.monotonic()
    publisher.publish(data)
    time.sleep(LAYOUT_PAUSE)
    if digest is not None and not _wait(lambda: verdicts.statuses(digest) > seen, wait):
        say(f'play: the node did not put layout {digest} in force within {wait:g} s '
            '(refused? see its log); playing on', flush=True)
    return time.monotonic() - started


class AnswerClock:
    """When the node last published an output (monotonic s): whether it still answers."""

    def __init__(self, node, topic):
        """Subscribe ``node`` to the output ``topic`` (raw: only the arrival counts)."""
        self.last = time.monotonic()
        node.create_subscription(message_class(topics.WRENCH_TYPE), topic, self._on_output,
                                 OUTPUT_QOS, raw=True)

    def _on_output(self, _):
        self.last = time.monotonic()


class VerdictLog:
    """The balance_monitor's /diagnostics, kept per layout digest (last status wins)."""

    def __init__(self, node):
        """Subscribe ``node`` to /diagnostics."""
        from diagnostic_msgs.msg import DiagnosticArray
        self._by_digest = {}
        self._statuses = {}        # statuses seen per layout digest (any level)
        self._lock = threading.Lock()
        node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_array, 50)

    def _on_array(self, array):
        for status in array.status:
            values = {kv.key: kv.value for kv in status.values}
            digest = values.get('layout digest')
            if digest:
                with self._lock:
                    self._statuses[digest] = self._statuses.get(digest, 0) + 1
                    if values.get('verdict level'):
                        self._by_digest[digest] = values

    def statuses(self, digest):
        """How many statuses the node has published with layout ``digest`` in force."""
        with self._lock:
            return self._statuses.get(digest, 0)

    def latest(self):
        """{layout digest: diagnostics values}, in the order the layouts were first seen."""
        with self._lock:
            return dict(self._by_digest)


def _spin(executor):
    try:
        executor.spin()
    except Exception:   # shut down while waiting (the context went first)
        pass


def _read_line(stream, timeout):
    """One line of ``stream`` (stripped), or '' at its end or after ``timeout`` s."""
    ready, _, _ = select.select([stream], [], [], timeout)
    return stream.readline().strip() if ready else ''


def _wait(condition, timeout):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def play_main(args, names=None):
    """
    Run ``cvc-balance play``; return the exit code (1: nothing to play into).

    ``names`` (InputTopics): the bag's input topics, if not the node's own.
    """
    try:
        published, report, verdicts = play(args.bag, args.rate, args.output, args.wait,
                                           names=names)
    except PlayError as error:
        print(f'cvc-balance: error: play: {error}', file=sys.stderr)
        return 1
    print(f'{args.bag}: published {published} messages')
    if report:
        print(f'recorded {report}')
    print(format_verdicts(verdicts))
    return 0


def format_verdicts(verdicts):
    """Describe the node's verdict per layout, one line each, for people."""
    if not verdicts:
        return 'the node published no verdict (/diagnostics) while playing'
    lines = ["balance_monitor's verdict per layout (its /diagnostics):"]
    for digest, values in verdicts.items():
        lines.append(f"  {values.get('layout', '?')} {digest}: "
                     f"{values.get('verdict level', '?')}  {values.get('verdict', '')}")
        if values.get('verdict source') == 'measured':     # the layout's, beside it
            lines.append(f"      the layout expects {values.get('layout verdict level', '?')}: "
                         f"{values.get('layout verdict', '')}")
        if 'keyphasor marks' in values:             # the node's check of the tach's marks
            lines.append('      ' + marks_summary(
                values['keyphasor'].split(' ')[0], values['keyphasor marks'],
                values['keyphasor missed (put back)'], values['keyphasor doubled (dropped)'],
                values['keyphasor irregular periods'], values['keyphasor revolutions']))
    return '\n'.join(lines)
