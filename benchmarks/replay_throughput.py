"""
Offline replay speed on a 1-million-sample bag, against merely reading it with rosbags.

Makes a bag of 10^6 JointState samples (1 kHz, 1000 s, with layout messages) by
simulation, then times in the same process:

* rosbags: iterate every message (AnyReader) and deserialise every JointState;
* ``cvc_balance.bag.replay``: read + vectorised compute + write all outputs (bearing load,
  2 supports, unbalance, drive torque: five WrenchStamped per sample, and the layouts)
  with zstd chunks, lz4 chunks and uncompressed chunks, and read + compute without
  output. Each is the wall-clock time of the whole ``replay`` call (open, read,
  compute, write, close), run twice: the first run and a repeat. Memory a process
  touches for the first time is slow on some virtual machines (a first run pays for
  its buffers and for the page cache of its output), so both are printed.

Then the same run as others write it, each against rosbags reading that same bag in the same
run: a bag written by the ``mcap`` library's writer (``mcap.writer.Writer`` defaults: zstd
chunks of 1 MiB, Schema and Channel records inside the chunks, summary), and a rosbag2
directory split in three MCAP files (each written by rosbags' rosbag2 Writer, gathered with a
metadata.yaml as ``ros2 bag record --max-bag-duration`` leaves them).

Run: ./dev.sh run python benchmarks/replay_throughput.py [--samples 1000000] [--foreign-only]
"""

import argparse
from pathlib import Path
import tempfile
import time

import yaml

from cvc_balance.bag.replay import replay
from cvc_balance.bag.scenario import load_scenario, write_bag

ROOT = Path(__file__).resolve().parents[1]
CONFIGURATIONS = (('zstd', 'zstd'), ('lz4', 'lz4'), ('uncompressed', ''), ('no output', None))


def make_bag(samples, folder):
    """Simulate a bag of ``samples`` JointState samples at 1 kHz."""
    seconds = (samples - 1) / 1000.0
    scenario = {
        'name': 'million', 'layout': str(ROOT / 'config' / 'ct_gantry.yaml'),
        'rate': 1000, 'seed': 3, 'noise': {'angle': 1e-4, 'speed': 0.005},
        'profile': [{'type': 'spin_up', 'to': 23.27, 'alpha': 4.0},
                    {'type': 'steady', 'duration': seconds - 23.27 / 4.0}],
        'events': [{'at': seconds / 2, 'set': {'component': 'xray_tube', 'mass': 60.5}}]}
    path = folder / 'scenario.yaml'
    path.write_text(yaml.safe_dump(scenario))
    bag = folder / 'input.mcap'
    count = write_bag(load_scenario(path), bag, chunk_bytes=1 << 20)
    return bag, count


def foreign_messages(bag):
    """Every message of the project's bag as (log time, topic, type, CDR), in log-time order."""
    from cvc_balance.bag.mcap_reader import Bag
    own = Bag(bag)
    messages = [(t, c.topic, c.msg_type, data) for c in own.channels.values()
                for t, data in own.messages(c)]
    return sorted(messages, key=lambda m: m[0])


def write_with_mcap_library(messages, path):
    """Write the run as the mcap library's writer makes it (its defaults), schemas from rosbags."""
    from mcap.writer import Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='benchmark')
        channels = {}
        for log_time, topic, msg_type, data in messages:
            if topic not in channels:
                text = store.generate_msgdef(msg_type, ros_version=2)[0]
                schema = writer.register_schema(msg_type, 'ros2msg', text.encode())
                channels[topic] = writer.register_channel(topic, 'cdr', schema)
            writer.add_message(channels[topic], log_time, data, log_time)
        writer.finish()
    return path


def write_split_directory(messages, path, parts=3):
    """Write the run split in ``parts`` MCAP files of one rosbag2 directory (rosbags' Writer)."""
    import sys
    from types import SimpleNamespace
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
    from test_foreign_bags import write_split      # the tests' split directory, as rosbag2's
    write_split(path, SimpleNamespace(events=messages), parts)
    return path


def read_with_rosbags(bag):
    """Iterate and deserialise every message with rosbags; return the count."""
    from rosbags.highlevel import AnyReader
    count = 0
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            count += 1
    return count


def time_replays(bag, rosbags_s, configurations):
    """Print replay's time for each configuration, first run and repeat."""
    folder = Path(bag).parent
    for name, compression in configurations:
        out = folder / f'out_{name.replace(" ", "_")}.mcap' if compression is not None else None
        what = 'read + compute' + (f' + write, {name}' if out else ' (no output)')
        for run in ('first', 'repeat'):
            start = time.perf_counter()
            summary = replay(bag, out, compression='zstd' if out is None else compression)
            seconds = time.perf_counter() - start
            size = f', output {out.stat().st_size / 1e6:.0f} MB' if out else ''
            print(f'replay {what} ({run}): {summary.accepted} samples in {seconds:.3f} s '
                  f'({summary.accepted / seconds / 1e6:.2f} M samples/s; '
                  f'{rosbags_s / seconds:.1f}x rosbags reading){size}')
            if out:
                out.unlink()


def time_rosbags(bag, samples, what):
    """Time rosbags reading ``bag``; print and return the seconds."""
    start = time.perf_counter()
    messages = read_with_rosbags(bag)
    seconds = time.perf_counter() - start
    print(f'rosbags read + deserialise, {what}: {messages} messages in {seconds:.2f} s '
          f'({samples / seconds / 1e6:.3f} M samples/s)')
    return seconds


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--samples', type=int, default=1_000_000)
    parser.add_argument('--foreign-only', action='store_true',
                        help='only the bags written by the mcap library and rosbags')
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix='cvc_replay_bench_'))
    bag, samples = make_bag(args.samples, folder)
    print(f'bag: {samples} samples, {bag.stat().st_size / 1e6:.1f} MB ({bag})')
    if not args.foreign_only:
        time_replays(bag, time_rosbags(bag, samples, "the project's bag"), CONFIGURATIONS)
    messages = foreign_messages(bag)
    foreign = (('mcap library bag', write_with_mcap_library(messages, folder / 'mcap_lib.mcap')),
               ('split rosbag2 directory', write_split_directory(messages, folder / 'split')))
    del messages
    for what, path in foreign:
        size = sum(p.stat().st_size for p in ([path] if path.is_file() else path.iterdir()))
        print(f'{what}: {size / 1e6:.1f} MB ({path})')
        time_replays(path, time_rosbags(path, samples, what),
                     [c for c in CONFIGURATIONS if c[0] in ('zstd', 'no output')])


if __name__ == '__main__':
    main()
