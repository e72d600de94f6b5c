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

``--tune``: how the output's zstd level and chunk size were chosen. First the compressor
alone on a replay's own chunks (its uncompressed output, re-cut): per level and chunk size,
GB/s of one thread (CPU time, best of 3: the machine's load counts little) and the ratio,
and zstd's own threads on a chunk (wall time); then whole replays with zstd output at each
chunk size and level, ``--repeat`` times interleaved, against replay without output: wall
time (median and spread), CPU time of the process, output size, load average; with
``--before PATH``, also the replay of the code in PATH (a checkout before the change, run in
a fresh process with this environment: its wall and CPU time measured around its second
replay call, as the others' are, repeats), the baseline.

Run: ./dev.sh run python benchmarks/replay_throughput.py [--samples 1000000] [--foreign-only]
     [--tune [--repeat 5] [--before /tmp/before]]
"""

import argparse
import importlib
import os
from pathlib import Path
import resource
import statistics
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


def replay_chunks(bag, folder, limit=128 << 20):
    """Return the records of a replay's uncompressed output chunks, joined (at most ``limit``)."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    out = folder / 'tune_uncompressed.mcap'
    replay(bag, out, compression='')
    parts, size = [], 0
    with open(out, 'rb') as stream:
        for record in StreamReader(stream, emit_chunks=True).records:
            if isinstance(record, Chunk) and size < limit:
                parts.append(record.data)
                size += len(record.data)
    out.unlink()
    return b''.join(parts)[:limit]


def compression_table(data):
    """Print GB/s (one thread, CPU time) and ratio per zstd level and chunk size."""
    import zstandard
    print(f'zstd on {len(data) / 1e6:.0f} MB of replay output records (load average '
          f'{os.getloadavg()[0]:.1f}); GB/s of one thread (best of 3, CPU time), ratio:')
    sizes = (1 << 20, 2 << 20, 4 << 20, 8 << 20)
    print(f"{'level':>6}" + ''.join(f'{f"{size >> 20} MiB chunks":>22}' for size in sizes))
    for level in (1, -1, -3, -5, -7, -10):
        compressor = zstandard.ZstdCompressor(level=level)
        cells = []
        for size in sizes:
            best, packed = float('inf'), 0
            for _ in range(3):
                began = time.thread_time()
                packed = sum(len(compressor.compress(data[i:i + size]))
                             for i in range(0, len(data), size))
                best = min(best, time.thread_time() - began)
            cells.append(f'{len(data) / best / 1e9:9.2f} GB/s {len(data) / packed:5.2f}')
        print(f'{level:6}' + ''.join(f'{cell:>22}' for cell in cells))
    for threads in (1, 2):
        compressor = zstandard.ZstdCompressor(level=-7, threads=threads)
        walls = []
        for _ in range(3):
            began = time.perf_counter()
            for i in range(0, len(data), 4 << 20):
                compressor.compress(data[i:i + (4 << 20)])
            walls.append(time.perf_counter() - began)
        print(f"zstd's own threads: level -7, 4 MiB chunks, threads={threads}: "
              f'{len(data) / min(walls) / 1e9:.2f} GB/s wall (best of 3)')


BEFORE = """
import os, resource, sys, time
from cvc_balance.bag.replay import replay
replay(sys.argv[1], sys.argv[2])          # a first run pays for its buffers: not timed
before = resource.getrusage(resource.RUSAGE_SELF)
began = time.perf_counter()
summary = replay(sys.argv[1], sys.argv[2])
wall = time.perf_counter() - began
after = resource.getrusage(resource.RUSAGE_SELF)
print(wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime,
      os.stat(sys.argv[2]).st_size, summary.accepted)
"""


def replay_before(path, bag, out):
    """Replay with zstd output by the code in ``path``: (wall s, CPU s, bytes, samples)."""
    import subprocess
    import sys
    done = subprocess.run([sys.executable, '-c', BEFORE, str(bag), str(out)], check=True,
                          capture_output=True, text=True, cwd=Path(out).parent,
                          env=dict(os.environ, PYTHONPATH=str(path)))
    wall, cpu, size, accepted = done.stdout.split()
    return float(wall), float(cpu), int(size), int(accepted)


def tuning_table(bag, folder, repeat, before=None):
    """Print whole replays with zstd output per chunk size and level, interleaved runs."""
    module = importlib.import_module('cvc_balance.bag.replay')
    chosen = (module.CHUNK_BYTES, module.LEVELS['zstd'])
    configurations = [None] + [(size, level) for level in (-5, -7)
                               for size in (1 << 20, 2 << 20, 4 << 20)]
    if before:
        configurations.insert(1, 'before')
    runs = {c: [] for c in configurations}
    out = folder / 'tune.mcap'
    for _ in range(repeat):
        for configuration in configurations:
            if configuration == 'before':
                load = os.getloadavg()[0]
                wall, cpu, size, accepted = replay_before(before, bag, out)
                runs[configuration].append((wall, cpu, size, load, accepted))
                out.unlink()
                continue
            if configuration is not None:
                module.CHUNK_BYTES, module.LEVELS['zstd'] = configuration
            usage = resource.getrusage(resource.RUSAGE_SELF)
            load = os.getloadavg()[0]
            began = time.perf_counter()
            summary = replay(bag, out if configuration else None)
            wall = time.perf_counter() - began
            after = resource.getrusage(resource.RUSAGE_SELF)
            cpu = after.ru_utime + after.ru_stime - usage.ru_utime - usage.ru_stime
            size = out.stat().st_size if configuration else 0
            runs[configuration].append((wall, cpu, size, load, summary.accepted))
            if configuration:
                out.unlink()
    module.CHUNK_BYTES, module.LEVELS['zstd'] = chosen
    print(f'\nwhole replays, {repeat} runs each, interleaved (chosen: '
          f'{chosen[0] >> 20} MiB chunks, level {chosen[1]}):')
    print(f"{'output':28}{'wall s: median':>15}{'spread':>15}{'M samples/s':>12}"
          f"{'CPU s':>8}{'MB':>6}{'load':>16}")
    for configuration, values in runs.items():
        wall = statistics.median(v[0] for v in values)
        name = 'none' if configuration is None else 'before (--before), zstd' \
            if configuration == 'before' else \
            f'zstd {configuration[1]}, {configuration[0] >> 20} MiB'
        loads = '/'.join(f'{v[3]:.1f}' for v in values)
        print(f'{name:28}{wall:15.2f}{min(v[0] for v in values):8.2f} -'
              f'{max(v[0] for v in values):5.2f}{values[0][4] / wall / 1e6:12.2f}'
              f'{statistics.median(v[1] for v in values):8.2f}{values[0][2] / 1e6:6.0f}'
              f'  {loads}')


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--samples', type=int, default=1_000_000)
    parser.add_argument('--foreign-only', action='store_true',
                        help='only the bags written by the mcap library and rosbags')
    parser.add_argument('--tune', action='store_true',
                        help='only the tables that chose the zstd level and chunk size')
    parser.add_argument('--repeat', type=int, default=5, help='runs of each, with --tune')
    parser.add_argument('--before', metavar='PATH', help='with --tune: also replay with the '
                        'code in PATH (a checkout before the change: the baseline)')
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix='cvc_replay_bench_'))
    bag, samples = make_bag(args.samples, folder)
    print(f'bag: {samples} samples, {bag.stat().st_size / 1e6:.1f} MB ({bag}); '
          f'{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}')
    if args.tune:
        compression_table(replay_chunks(bag, folder))
        tuning_table(bag, folder, args.repeat, args.before)
        return
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
