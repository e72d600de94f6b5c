"""
The live node under hostile input: memory, a big layout swap, a killed recording.

1. Memory: the node (bundled gantry) gets a 5 kHz stream for --seconds (default 60) in
   which most samples are bad (NaN, stamps out of order or 68 years ahead, speeds beyond
   max_speed, JointStates without the joint) and, twice a second, a hostile layout (the
   issue's crashers, an alias bomb, a 10 MB name) or a good one: its resident memory
   after a warm-up and at the end, the samples it answered, and that it is still alive.
2. A 10^5-component layout swapped in three times while 1 kHz samples come: samples sent
   against samples answered.
3. A recording killed: the node records 1 kHz samples to an MCAP file and is killed with
   SIGKILL; the messages each reader gets before and after ``cvc-balance reindex``.

Run: ./dev.sh run python benchmarks/hostile.py [--seconds 60]
"""

import argparse
import json
import math
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402
import yaml  # noqa: E402

from ros_harness import NodeProcess, Probe  # noqa: E402
from test_balance_monitor import joint_state, LAYOUT_A  # noqa: E402
from test_node_hostile import big_layout, HOSTILE_LAYOUTS  # noqa: E402


def rss_mb(pid):
    """Return the resident memory of process ``pid``, MB."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def start(work, **params):
    layout = work / 'layout.yaml'
    layout.write_text(yaml.safe_dump(LAYOUT_A))
    args = ['-p', f'layout_file:={layout}', '-p', 'joint_name:=spin']
    for key, value in params.items():
        args += ['-p', f'{key}:={value}']
    return NodeProcess('cvc_balance.ros.balance_monitor', args, work / f'node_{time.time()}.log')


def connect(probe, node):
    ok = probe.spin_until(lambda: probe.node.count_subscribers('joint_states') >= 1
                          and probe.node.count_publishers('bearing_load') >= 1, 30.0)
    assert ok, node.log()
    probe.spin_for(1.5)


def hostile_stream(work, seconds, rate=5000):
    node = start(work)
    probe = Probe('hostile_benchmark')
    answered = probe.record(WrenchStamped, 'bearing_load', depth=1000)
    layout_pub = probe.publisher(String, 'layout', latched=True)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    connect(probe, node)
    rng = random.Random(1)
    layouts = list(HOSTILE_LAYOUTS.values()) + [yaml.safe_dump(LAYOUT_A)] * 4
    ns, sent, good, start_rss, start_time = 10**10, 0, 0, None, time.monotonic()
    next_layout, next_rss, trace = start_time, start_time + 10.0, []
    while time.monotonic() - start_time < seconds:
        now = time.monotonic() - start_time
        if start_rss is None and now > 5.0:
            start_rss = rss_mb(node.process.pid)
        if time.monotonic() >= next_rss:
            trace.append(f'{now:.0f} s {rss_mb(node.process.pid):.0f} MB')
            next_rss += 10.0
        if time.monotonic() >= next_layout:
            text = rng.choice(layouts)
            layout_pub.publish(text if isinstance(text, bytes) else String(data=text))
            next_layout += 0.5
        for _ in range(50):
            ns += 200_000
            kind = rng.random()
            if kind < 0.3:
                msg, good = joint_state(ns, 0.1, 10.0), good + 1
            elif kind < 0.45:
                msg = joint_state(ns, math.nan, 10.0)
            elif kind < 0.6:
                msg = joint_state(ns - 10**9, 0.1, 10.0)          # out of order
            elif kind < 0.7:
                msg = joint_state(2147483647 * 10**9, 0.1, 10.0)   # 68 years ahead
            elif kind < 0.85:
                msg = joint_state(ns, 0.1, 1e9)                     # beyond max_speed
            else:
                msg = joint_state(ns, 0.1, 10.0, joint='other_joint')
            joints.publish(msg)
            sent += 1
        answered.clear()
        probe.spin_for(max(0.0, sent / rate - (time.monotonic() - start_time)))
    elapsed = time.monotonic() - start_time
    end_rss = rss_mb(node.process.pid)
    alive = node.process.poll() is None
    probe.close()
    code = node.stop(signal.SIGINT)
    counts = node.log().splitlines()[-1] if node.log() else ''
    print(f'1. hostile stream: {sent} samples in {elapsed:.1f} s ({sent / elapsed:.0f}/s), '
          f'{good} of them valid; node alive: {alive}, exit {code}; resident memory '
          f'{start_rss:.1f} MB after 5 s, {end_rss:.1f} MB at the end '
          f'({end_rss - start_rss:+.1f} MB; every 10 s: {", ".join(trace)}); {counts}')


def layout_swap(work, swaps=3, seconds=3.0, depth=None):
    node = start(work, **({'input_depth': depth} if depth else {}))
    probe = Probe('swap_benchmark')
    answered = probe.record(WrenchStamped, 'bearing_load', depth=100_000)
    layout_pub = probe.publisher(String, 'layout', latched=True)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    connect(probe, node)
    big = big_layout(100_000)
    ns, sent = 20 * 10**9, 0
    for swap in range(swaps):
        layout_pub.publish(String(data=big if swap % 2 == 0 else yaml.safe_dump(LAYOUT_A)))
        begin = time.monotonic()
        for k in range(int(seconds * 1000)):
            ns += 1_000_000
            joints.publish(joint_state(ns, 0.001 * k, 10.0))
            sent += 1
            delay = begin + (k + 1) / 1000.0 - time.monotonic()
            probe.spin_for(max(delay, 0.0))
    probe.spin_until(lambda: len(answered) >= sent, 20.0)
    stamps = {o.header.stamp.sec * 10**9 + o.header.stamp.nanosec for o in answered}
    probe.close()
    node.stop(signal.SIGINT)
    print(f'2. 10^5-component layout swapped {swaps} times at 1 kHz: {sent} samples sent, '
          f'{len(stamps)} answered, {sent - len(stamps)} lost')


def killed_recording(work, seconds=10.0):
    from mcap.reader import make_reader
    from mcap.stream_reader import StreamReader
    from rosbags.highlevel import AnyReader
    from cvc_balance.bag.mcap_reader import Bag

    record = work / 'killed.mcap'
    node = start(work, record_path=record)
    probe = Probe('kill_benchmark')
    probe.record(DiagnosticArray, '/diagnostics')
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    connect(probe, node)
    ns, begin = 30 * 10**9, time.monotonic()
    for k in range(int(seconds * 1000)):
        ns += 1_000_000
        joints.publish(joint_state(ns, 0.001 * k, 10.0))
        probe.spin_for(max(begin + (k + 1) / 1000.0 - time.monotonic(), 0.0))
    node.process.send_signal(signal.SIGKILL)
    node.process.wait()
    probe.close()

    def counts():
        out = {}
        ours = Bag(record)
        out['cvc_balance'] = sum(ours.message_count(c) for c in ours.channels.values())
        n = 0
        with open(record, 'rb') as stream:
            try:
                for r in StreamReader(stream).records:
                    n += type(r).__name__ == 'Message'
            except Exception:
                pass
        out['mcap stream reader'] = n
        try:
            with open(record, 'rb') as stream:
                out['mcap indexed reader'] = sum(1 for _ in make_reader(stream).iter_messages())
        except Exception as error:
            out['mcap indexed reader'] = f'0 ({type(error).__name__})'
        try:
            with AnyReader([record]) as reader:
                out['rosbags'] = sum(1 for _ in reader.messages())
        except Exception as error:
            out['rosbags'] = f'0 ({type(error).__name__})'
        return out
    before = counts()
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'reindex', str(record)],
                         capture_output=True, text=True)
    after = counts()
    print(f'3. node recording killed with SIGKILL after {seconds:g} s at 1 kHz; messages '
          f'read before / after cvc-balance reindex:')
    for name in before:
        print(f'   {name:22} {before[name]!s:>28} / {after[name]}')
    print('   ' + run.stdout.strip().replace('\n', '\n   '))


def main():
    """Run the three measurements and print their figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=60.0)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix='cvc_hostile_'))
    hostile_stream(work, args.seconds)
    layout_swap(work)
    killed_recording(work)
    print(json.dumps({'work folder': str(work)}))


if __name__ == '__main__':
    os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    main()
