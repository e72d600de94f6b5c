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

Run: ./dev.sh run python benchmarks/replay_throughput.py [--samples 1000000]
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


def read_with_rosbags(bag):
    """Iterate and deserialise every message with rosbags; return the count."""
    from rosbags.highlevel import AnyReader
    count = 0
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            count += 1
    return count


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--samples', type=int, default=1_000_000)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix='cvc_replay_bench_'))
    bag, samples = make_bag(args.samples, folder)
    print(f'bag: {samples} samples, {bag.stat().st_size / 1e6:.1f} MB ({bag})')
    start = time.perf_counter()
    messages = read_with_rosbags(bag)
    rosbags_s = time.perf_counter() - start
    print(f'rosbags read + deserialise: {messages} messages in {rosbags_s:.2f} s '
          f'({samples / rosbags_s / 1e6:.3f} M samples/s)')
    for name, compression in CONFIGURATIONS:
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


if __name__ == '__main__':
    main()
