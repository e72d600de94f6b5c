"""
The tach path's cost per motion sample beside the encoder path's, offline.

One run, two bags of the same sample count (default 10^6 at 1 kHz, a rotor at 55 rev/s:
18 tach samples a revolution, with 0.2 % speed wobble):

* encoder: /joint_states (JointState, one joint), read into MotionSamples by
  ``mcap_reader.joint_samples`` (the path replay, identify and the field commands take);
* tach: /keyphasor (Float64, a 0/1 pick-up), read into the same MotionSamples by
  ``channels.keyphasor_motion``: decode, the threshold's crossings, the marks' check, the
  angle and speed at every tach sample.

Each is the wall-clock time from opening the bag to the MotionSamples, best of
``--repeat`` runs, printed per sample side by side, with the tach path's share of it:
reading the Float64 values, the marks, their check, and the motion.

Live (``--live N`` samples, default 20000): the node (bundled CT gantry layout, its
publishers matched by nothing) in this process, each path's callback called N times in
a row, best of ``--repeat``: a JointState's CDR bytes (``_on_joint_states``: read, stamp
gate, engine, five outputs published) against a sampled tach's (the Float64 read, the
system clock read as ``_on_float64`` does without sim time, the crossing, the marks' check, the
extrapolation, then the same). Both accept every sample (said).

Run: ./dev.sh run python benchmarks/keyphasor.py [--samples 1000000] [--repeat 5] [--live N]
"""

import argparse
from pathlib import Path
import tempfile
import time
from time import time_ns

import numpy as np

from cvc_balance.bag.channels import keyphasor_motion
from cvc_balance.bag.mcap_reader import float64_samples, joint_samples
from cvc_balance.bag.mcap_writer import MessageBlock
from cvc_balance.bag.rosbag2 import open_bag, open_writer
from cvc_balance.messages.cdr import CdrLayout, joint_state_layout
from cvc_balance.physics.frames import wrap_angle
from cvc_balance.physics.keyphasor import checked_marks, signal_marks

RATE = 1000.0
SPEED = 2 * np.pi * 55.0


def make_bags(samples, folder):
    """Write the encoder's and the tach's bag of the same run; return their paths."""
    t = np.arange(samples) / RATE
    omega = SPEED * (1.0 + 0.002 * np.sin(2 * np.pi * 0.05 * t))
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) / RATE)])
    stamps = 1_700_000_000 * 10 ** 9 + np.rint(t * 1e9).astype(np.int64)
    encoder, tach = folder / 'encoder.mcap', folder / 'tach.mcap'
    with open_writer(encoder, chunk_bytes=1 << 20) as writer:
        channel = writer.add_channel('/joint_states', 'sensor_msgs/msg/JointState',
                                     best_effort=True)
        block = MessageBlock([(channel, joint_state_layout('', ['gantry_joint']))], samples)
        block.array['0.sec'], block.array['0.nanosec'] = np.divmod(stamps, 1_000_000_000)
        block.array['0.position_0'], block.array['0.velocity_0'] = wrap_angle(angle), omega
        writer.write_block(block, stamps)
    scalar = CdrLayout()
    scalar.number('data', '<f8')
    with open_writer(tach, chunk_bytes=1 << 20) as writer:
        channel = writer.add_channel('/keyphasor', 'std_msgs/msg/Float64', best_effort=True)
        block = MessageBlock([(channel, scalar)], samples)
        block.array['0.data'] = (np.mod(angle, 2 * np.pi) < 1.0).astype(float)
        writer.write_block(block, stamps)
    return encoder, tach


def best(repeat, *works):
    """
    Return the best wall-clock time (s) of each of ``works`` over ``repeat`` runs.

    The runs take turns (one of each, then again), so that a machine shared with other
    work loads each path alike.
    """
    times = [[] for _ in works]
    for _ in range(repeat):
        for work, spent in zip(works, times):
            started = time.perf_counter()
            work()
            spent.append(time.perf_counter() - started)
    return [min(spent) for spent in times]


def live_paths(samples, repeat):
    """Return {path: (best s per sample, samples accepted)} of the node's two callbacks."""
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from cvc_balance.ros.balance_monitor import BalanceMonitor

    layout = Path(__file__).resolve().parents[1] / 'config' / 'ct_gantry.yaml'
    rclpy.init()
    node = BalanceMonitor(parameter_overrides=[
        Parameter('layout_file', value=str(layout)), Parameter('keyphasor_topic', value='tach'),
        Parameter('max_stamp_jump', value=1e6)])
    node._keyphasor.subscribe('std_msgs/msg/Float64')
    # One time line: the runs of each path take turns, each run D s after the last.
    t = np.arange(samples) / RATE
    run_s = samples / RATE + 1.0
    angle = SPEED * t
    values = [serialize_message(Float64(data=float(v)))
              for v in (np.mod(angle, 2 * np.pi) < 1.0)]
    joints, tach, stamps = [], [], []
    for run in range(repeat):
        start = 1_700_000_000 * 10 ** 9 + int(2 * run * run_s * 1e9)
        for q, ns in zip(angle, start + np.rint(t * 1e9).astype(np.int64)):
            msg = JointState(name=['gantry_joint'], position=[float(wrap_angle(q))],
                             velocity=[SPEED])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(ns), 10 ** 9)
            joints.append(serialize_message(msg))
        tach += values
        stamps += (start + int(run_s * 1e9) + np.rint(t * 1e9).astype(np.int64)).tolist()
    keyphasor, spent = node._keyphasor, {'encoder': [], 'tach': []}
    accepted = dict.fromkeys(spent, 0)

    def encoder(block):
        for data in joints[block]:
            node._on_joint_states(data)

    def tachometer(block):
        started = time.perf_counter()
        for data, stamp in zip(tach[block], stamps[block]):
            time_ns()                   # what _on_float64 reads (its stamp)
            keyphasor.float64(data, stamp, started)

    try:
        for run in range(repeat):       # the two paths take turns
            block = slice(run * samples, (run + 1) * samples)
            for name, work in (('encoder', encoder), ('tach', tachometer)):
                before, started = node._counts['accepted'], time.perf_counter()
                work(block)
                spent[name].append(time.perf_counter() - started)
                accepted[name] += node._counts['accepted'] - before
        out = {name: (min(times) / samples, accepted[name]) for name, times in spent.items()}
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return out


def main():
    """Time both paths and print them side by side."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--samples', type=int, default=1_000_000)
    parser.add_argument('--repeat', type=int, default=5)
    parser.add_argument('--live', type=int, default=20000, metavar='N',
                        help='motion samples per live run (0: offline only)')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        encoder, tach = make_bags(args.samples, Path(folder))

        def encoder_path():
            bag = open_bag(encoder)
            return joint_samples(bag, bag.channel('joint_states', 'sensor_msgs/msg/JointState'),
                                 'gantry_joint')

        def tach_path():
            return keyphasor_motion(open_bag(tach))

        motion = tach_path()
        assert len(motion.stamp) >= args.samples - 40, len(motion.stamp)
        encoder_s, tach_s = best(args.repeat, encoder_path, tach_path)
        bag = open_bag(tach)
        channel = bag.channel('keyphasor', 'std_msgs/msg/Float64')
        times, values = float64_samples(bag, channel)
        seconds = (times - times[0]) * 1e-9
        raw = signal_marks(seconds, values)
        marks = checked_marks(raw)
        parts = dict(zip(('read Float64', 'marks (crossings)', 'check', 'angle, speed'), best(
            args.repeat, lambda: float64_samples(open_bag(tach), channel),
            lambda: signal_marks(seconds, values), lambda: checked_marks(raw),
            lambda: marks.motion(seconds))))
    n = args.samples
    print(f'{n} motion samples ({len(marks.time)} marks), best of {args.repeat}:')
    print(f'  encoder (JointState -> MotionSamples):  {encoder_s * 1e9 / n:7.1f} ns/sample')
    print(f'  tach    (Float64 -> MotionSamples):     {tach_s * 1e9 / n:7.1f} ns/sample  '
          f'({tach_s / encoder_s - 1.0:+.0%} against the encoder; target within +20 %)')
    for name, seconds in parts.items():
        print(f'    {name:20} {seconds * 1e9 / n:7.1f} ns/sample')
    if args.live:
        live = live_paths(args.live, args.repeat)
        (encoder_live, encoder_n), (tach_live, tach_n) = live['encoder'], live['tach']
        print(f'live, the node\'s callback, {args.live} samples a run, best of {args.repeat}:')
        print(f'  encoder (JointState CDR -> outputs):    {encoder_live * 1e6:7.2f} us/sample '
              f'({encoder_n} accepted)')
        print(f'  tach    (Float64 CDR -> outputs):       {tach_live * 1e6:7.2f} us/sample '
              f'({tach_n} accepted; {tach_live / encoder_live - 1.0:+.0%} against the encoder; '
              'target within +20 %)')


if __name__ == '__main__':
    main()
