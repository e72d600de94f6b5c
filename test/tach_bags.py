"""
A rotor's run recorded twice: with an exact encoder, and with a tach instead (no encoder).

The run is a simulator scenario (the CT gantry of config/ct_gantry.yaml, load cells under
both supports, a loose bracket the layout does not list): spin-up from rest at 4 rad/s^2
to 23.27 rad/s, 5 s steady, coast-down at 4 rad/s^2 to 12 rad/s. The encoder bag is the
simulator's (angle and speed exact: no noise). The tach bag has the same /layout and
load cells and no JointState; its tach is made here from the scenario's exact angle
theta(t) (piecewise constant alpha, evaluated in closed form at any time):

* a sampled tach (std_msgs/Float64, 0-5 V, at the encoder's sample times): a linear edge
  over 3 samples' worth of angle at each mark theta = 2 pi k (so each crossing is timed
  exactly by interpolation at steady speed), the strip 1.2 rad wide;
* a TimeReference tach: the mark times, found by bisection on theta, one message a mark.

Messages are serialised by rosbags (not the project's CDR code).
"""

import math

import numpy as np
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.mcap_reader import Bag
from cvc_balance.bag.mcap_writer import BagWriter
from cvc_balance.bag.scenario import exact_motion, load_scenario, write_bag

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
SCENARIO = {
    'name': 'tach_run', 'layout': None, 'joint_name': 'gantry_joint', 'rate': 1000,
    'seed': 4, 'noise': {'angle': 0.0, 'speed': 0.0},
    'profile': [{'type': 'spin_up', 'to': 23.27, 'alpha': 4.0},
                {'type': 'steady', 'duration': 5.0},
                {'type': 'coast_down', 'to': 12.0, 'alpha': -4.0}],
    'hidden': [{'at': 0.0, 'add': {'name': 'loose_bracket', 'mass': 0.3, 'radius': 0.5,
                                   'angle_deg': 130.0, 'z': 0.12}}],
    'load_cells': {'rate': 250, 'noise': 15.0,
                   'bias': {'front': [120.0, -340.0, 5.0], 'rear': [-80.0, 55.0, -3.0]}},
}
EDGE_SAMPLES = 3.0
STRIP = 1.2            # rad


def scenario(folder, root):
    """Write the scenario file (layout: the bundled CT gantry); return the Scenario."""
    spec = dict(SCENARIO, layout=str(root / 'config' / 'ct_gantry.yaml'))
    path = folder / 'tach_run.yaml'
    path.write_text(yaml.safe_dump(spec))
    return load_scenario(path)


def theta(run, t):
    """Return the scenario's exact angle (rad, unwrapped) at ``t`` s after its start."""
    return exact_motion(run.pieces, np.asarray(t, float))[0]


def mark_times(run):
    """Return the exact marks theta = 2 pi k (k >= 1), s after the start, by bisection."""
    end = run.time[-1]
    k = np.arange(1, int(theta(run, np.array([end]))[0] / (2 * math.pi)) + 1)
    lo, hi = np.zeros(len(k)), np.full(len(k), end)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = theta(run, mid) < 2 * math.pi * k
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def tach_volts(run, t):
    """Return a 0-5 V pick-up at ``t``: a linear edge over 3 samples' angle at each mark."""
    angle, omega, _ = exact_motion(run.pieces, np.asarray(t, float))
    wrapped = np.mod(angle + math.pi, 2 * math.pi) - math.pi
    edge = np.maximum(EDGE_SAMPLES * omega / run.rate, 1e-3)
    return 5.0 * np.clip(0.5 + wrapped / edge, 0.0, 1.0) * (wrapped < STRIP)


def serialized(msg, msg_type):
    return TYPESTORE.serialize_cdr(msg, msg_type).tobytes()


def float64(value):
    return serialized(TYPESTORE.types['std_msgs/msg/Float64'](data=float(value)),
                      'std_msgs/msg/Float64')


def time_reference(ns, received_ns):
    types = TYPESTORE.types
    time = types['builtin_interfaces/msg/Time']
    header = types['std_msgs/msg/Header'](stamp=time(sec=received_ns // 10 ** 9,
                                                     nanosec=received_ns % 10 ** 9),
                                          frame_id='tach')
    return serialized(types['sensor_msgs/msg/TimeReference'](
        header=header, time_ref=time(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9),
        source='pick-up'), 'sensor_msgs/msg/TimeReference')


def copy_channels(writer, bag, leave_out=()):
    """Copy every channel of ``bag`` but ``leave_out`` into ``writer`` (/layout latched)."""
    source = Bag(bag)
    for channel in source.channels.values():
        if channel.topic in leave_out:
            continue
        out = writer.add_channel(channel.topic, channel.msg_type,
                                 latched=channel.topic == '/layout',
                                 best_effort=channel.topic != '/layout')
        for log_time, data in source.messages(channel):
            writer.write(out, log_time, data)


def write_run(folder, root, tach='float64', topic='/keyphasor', tach_values=None,
              marks=None):
    """
    Write the encoder bag and the tach bag of the run; return (Scenario, encoder, tach).

    ``tach``: 'float64' (a sampled tach at the encoder's sample times; ``tach_values``
    replaces its volts) or 'time_reference' (``marks``, s after the start, replace the
    exact ones). The tach bag holds the encoder bag's /layout and load cells too.
    """
    run = scenario(folder, root)
    encoder, tach_bag = folder / 'encoder.mcap', folder / f'tach_{tach}.mcap'
    write_bag(run, encoder)
    start = round(run.start * 1e9)
    with BagWriter(tach_bag, chunk_bytes=1 << 16) as writer:
        copy_channels(writer, encoder, leave_out=('/joint_states',))
        if tach == 'float64':
            channel = writer.add_channel(topic, 'std_msgs/msg/Float64', best_effort=True)
            values = tach_volts(run, run.time) if tach_values is None else tach_values
            for ns, value in zip(run.stamps_ns(), values):
                writer.write(channel, int(ns), float64(value))
        else:
            channel = writer.add_channel(topic, 'sensor_msgs/msg/TimeReference')
            for s in mark_times(run) if marks is None else marks:
                ns = start + round(s * 1e9)
                writer.write(channel, ns + 2_000_000, time_reference(ns, ns + 2_000_000))
    return run, encoder, tach_bag


def merge(path, *bags, change=None):
    """
    Write every channel of ``bags`` (each topic once, the first bag's) into one bag.

    ``change``: {topic: function(log time, bytes) -> (topic, bytes)} to rewrite a topic's
    messages on the way (another topic, other values).
    """
    change = change or {}
    with BagWriter(path, chunk_bytes=1 << 16) as writer:
        made, copied = {}, set()
        for source in map(Bag, bags):
            for channel in source.channels.values():
                if channel.topic in copied:
                    continue
                copied.add(channel.topic)
                for log_time, data in source.messages(channel):
                    topic, data = change.get(channel.topic, lambda t, d, c=channel: (
                        c.topic, d))(log_time, data)
                    if topic not in made:
                        made[topic] = writer.add_channel(
                            topic, channel.msg_type, latched=topic == '/layout',
                            best_effort=topic != '/layout')
                    writer.write(made[topic], log_time, data)
    return path


TYPES = {'float64': 'std_msgs/msg/Float64', 'time_reference': 'sensor_msgs/msg/TimeReference'}
"""The tach's message type of each kind of write_run."""
