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

Run: ./dev.sh run python benchmarks/keyphasor.py [--samples 1000000] [--repeat 5]
"""

import argparse
from pathlib import Path
import tempfile
import time

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


def best(repeat, work):
    """Return the best wall-clock time (s) of ``repeat`` runs of ``work()``."""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return min(times)


def main():
    """Time both paths and print them side by side."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--samples', type=int, default=1_000_000)
    parser.add_argument('--repeat', type=int, default=5)
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
        encoder_s, tach_s = best(args.repeat, encoder_path), best(args.repeat, tach_path)
        bag = open_bag(tach)
        channel = bag.channel('keyphasor', 'std_msgs/msg/Float64')
        times, values = float64_samples(bag, channel)
        seconds = (times - times[0]) * 1e-9
        raw = signal_marks(seconds, values)
        marks = checked_marks(raw)
        parts = {'read Float64': best(args.repeat, lambda: float64_samples(
                     open_bag(tach), channel)),
                 'marks (crossings)': best(args.repeat, lambda: signal_marks(seconds, values)),
                 'check': best(args.repeat, lambda: checked_marks(raw)),
                 'angle, speed': best(args.repeat, lambda: marks.motion(seconds))}
    n = args.samples
    print(f'{n} motion samples ({len(marks.time)} marks), best of {args.repeat}:')
    print(f'  encoder (JointState -> MotionSamples):  {encoder_s * 1e9 / n:7.1f} ns/sample')
    print(f'  tach    (Float64 -> MotionSamples):     {tach_s * 1e9 / n:7.1f} ns/sample  '
          f'({tach_s / encoder_s - 1.0:+.0%} against the encoder; target within +20 %)')
    for name, seconds in parts.items():
        print(f'    {name:20} {seconds * 1e9 / n:7.1f} ns/sample')


if __name__ == '__main__':
    main()
