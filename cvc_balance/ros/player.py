"""
Play a bag's inputs into the ROS graph with their timing, and record what comes back.

``cvc-balance play BAG [--rate X] [-o OUT]``: layout messages go out latched
(transient local), motion samples (joint_states or speed) as their raw bytes
at their log times scaled by 1 / rate. After each layout the player pauses
50 ms (bag time is then shifted) so that the node has it in force before the
next sample. With ``-o`` the node's outputs (topics derived from the bag's
layouts) are recorded to OUT by a ``cvc-balance record`` child process, for
1 s after the last input. Samples start once the node subscribes to them, the
recorder has matched the node's outputs, and 1.5 s more (DDS discovery is
one-sided: the other end may match a moment later).
"""

import signal
import subprocess
import sys
import time

from cvc_balance.bag.inputs import input_channels, InputTopics
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import read_string_message
from cvc_balance.ros.qos import input_qos, LAYOUT_QOS
from cvc_balance.ros.recorder import message_class

LAYOUT_PAUSE = 0.05


def output_topics(layout_texts):
    """Output topics of the node for the layouts a bag holds (their supports)."""
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    names = list(topics.OUTPUTS)
    for text in layout_texts:
        try:
            layout = layout_from_text(text)
        except LayoutError:
            continue
        for support in layout.supports:
            topic = topics.support_load(support.name)
            if topic not in names:
                names.append(topic)
    return names


def play(bag_path, rate=1.0, output=None, wait_for_subscriber=20.0, quiet=1.0, settle=1.5,
         names=None):
    """
    Publish the bag's inputs; return (messages published, recorder's report or None).

    ``bag_path``: a bag file or rosbag2 directory; ``names`` (InputTopics): its input
    topics if not the node's own. They are published on the node's topic names.
    """
    import rclpy

    bag = open_bag(bag_path)
    channels = input_channels(bag, names)      # BagError names the bag's topics
    inputs = []
    for topic, msg_type, qos, channel in (
            (topics.JOINT_STATES, topics.JOINT_STATE_TYPE, input_qos(1000),
             channels.joint_states),
            (topics.SPEED, topics.FLOAT64_TYPE, input_qos(1000), channels.speed),
            (topics.LAYOUT, topics.STRING_TYPE, LAYOUT_QOS, channels.layout)):
        if channel is not None:
            inputs.append((topic, msg_type, qos, bag.messages(channel)))
    for problem in bag.problems:
        print(f'play: {bag_path}: {problem}')
    layouts = [data for topic, _, _, messages in inputs if topic == topics.LAYOUT
               for _, data in messages]
    outputs = output_topics([read_string_message(data) for data in layouts])
    rclpy.init()
    node = rclpy.create_node('cvc_balance_player')
    publishers = {topic: node.create_publisher(message_class(msg_type), topic, qos)
                  for topic, msg_type, qos, _ in inputs}
    events = sorted((log_time, topic, data) for topic, _, _, messages in inputs
                    for log_time, data in messages)
    # The recorder runs in its own process: its thousands of callbacks a second must not
    # starve this one's timing (bursts would overflow the node's input queue).
    recorder = None
    if output:
        recorder = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'record', '-o',
                                     str(output), '--ready-when', outputs[0], *outputs],
                                    stdout=subprocess.PIPE, text=True)
    motion = topics.JOINT_STATES if topics.JOINT_STATES in publishers else topics.SPEED
    if not _wait(lambda: publishers[motion].get_subscription_count() > 0, wait_for_subscriber):
        print(f'play: nobody subscribes to {motion}; publishing anyway')
    first_sample = next(i for i, (_, topic, _) in enumerate(events) if topic != topics.LAYOUT)
    for log_time, topic, data in events[:first_sample]:
        publishers[topic].publish(data)          # the layouts in force from the start
    if recorder is not None and recorder.stdout.readline().strip() != 'ready':
        print('play: the recorder did not get ready; recording anyway')
    if first_sample and outputs[3:]:     # the first layout's supports are being published
        _wait(lambda: node.count_publishers(outputs[3]) > 0, wait_for_subscriber)
    # DDS matching is one-sided: what this side sees, the other may see a moment later.
    time.sleep(settle)
    published, start_log = first_sample, events[first_sample][0]
    start_wall = time.monotonic()
    for log_time, topic, data in events[first_sample:]:
        left = start_wall + (log_time - start_log) * 1e-9 / rate - time.monotonic()
        if left > 0:
            time.sleep(left)
        publishers[topic].publish(data)
        published += 1
        if topic == topics.LAYOUT:
            time.sleep(LAYOUT_PAUSE)
            start_wall += LAYOUT_PAUSE
    report = None
    if recorder is not None:
        time.sleep(quiet)
        recorder.send_signal(signal.SIGINT)
        report = recorder.communicate(timeout=30)[0].strip()
    node.destroy_node()
    rclpy.try_shutdown()
    return published, report


def _wait(condition, timeout):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def play_main(args):
    """Run ``cvc-balance play``; return the exit code."""
    names = InputTopics(getattr(args, 'joint_states', None), getattr(args, 'speed', None),
                        getattr(args, 'layout', None))
    published, report = play(args.bag, args.rate, args.output, names=names)
    print(f'{args.bag}: published {published} messages')
    if report:
        print(f'recorded {report}')
    return 0
