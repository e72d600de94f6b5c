"""
Latency of balance_monitor against a bare relay, in one run, and their top input rates.

Starts the node (bundled CT gantry layout) and a relay (benchmarks/relay_node.py,
input remapped to ``relay_in``) as processes. This process is the probe: a
thread publishes JointState with header stamps from the system clock, the main
thread receives ``bearing_load`` and ``relay_out`` and records (receive time -
input stamp). The two targets get the input in alternating blocks of
--block seconds, so that neither competes with the other for the 2 cores while
both see the same machine over the same minutes:

1. 1 kHz for --seconds per target (default 30): p50 / p99 / max and drops
   (inputs without an output);
2. a rate sweep (--sweep-seconds per target and rate): the highest rate each
   follows with no drop.

Run: ./dev.sh run python benchmarks/latency.py
All traffic stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST,
its own ROS_DOMAIN_ID).
"""

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SWEEP = (2000, 3000, 4000, 5000, 6000, 8000)
TARGETS = {'node': ('joint_states', 'bearing_load'), 'relay': ('relay_in', 'relay_out')}


class Probe:
    """Publishes paced JointState to a target's input and records its outputs."""

    def __init__(self):
        """Make the probe node: a publisher per target input, a recorder per output."""
        import rclpy
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from geometry_msgs.msg import WrenchStamped
        from sensor_msgs.msg import JointState
        from cvc_balance.ros.balance_monitor import input_qos

        self.rclpy = rclpy
        rclpy.init()
        self.node = rclpy.create_node('latency_probe')
        self.received = {name: {} for name in TARGETS}
        self.publishers = {}
        for name, (topic_in, topic_out) in TARGETS.items():
            self.publishers[name] = self.node.create_publisher(JointState, topic_in,
                                                               input_qos(200))
            self.node.create_subscription(
                WrenchStamped, topic_out, self._recorder(self.received[name]),
                QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.msg = JointState(name=['gantry_joint'], position=[0.0], velocity=[23.27])

    @staticmethod
    def _recorder(store):
        def record(msg):
            store[msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec] = \
                time.time_ns()
        return record

    def wait_for_targets(self, timeout=30.0):
        """Wait until both targets subscribe to their inputs."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(p.get_subscription_count() >= 1 for p in self.publishers.values()):
                time.sleep(1.0)
                return
            time.sleep(0.05)
        raise RuntimeError('the node and the relay did not come up')

    def publish(self, name, rate, seconds):
        """Publish at ``rate`` Hz for ``seconds`` to a target; return (stamps, achieved rate)."""
        publisher, msg = self.publishers[name], self.msg
        period, stamps = 1.0 / rate, []
        start = time.perf_counter()
        for k in range(int(rate * seconds)):
            left = start + k * period - time.perf_counter()
            if left > 0:
                time.sleep(left)  # no busy wait: two cores are shared by everything here
            now = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
            msg.position[0] = (k * period * 23.27) % 6.283185307179586
            publisher.publish(msg)
            stamps.append(now)
        return stamps, len(stamps) / (time.perf_counter() - start)

    def spin(self, stop):
        """Receive in this thread until ``stop`` is set (events executor, spin_once loop)."""
        from rclpy.experimental import EventsExecutor
        executor = EventsExecutor()
        executor.add_node(self.node)
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()

    def latencies(self, name, stamps):
        """Return (latencies in ms of the outputs that came, number of drops)."""
        got = self.received[name]
        values = np.array([(got[s] - s) / 1e6 for s in stamps if s in got])
        return values, len(stamps) - len(values)


def run_blocks(probe, rate, seconds, block):
    """Alternate the targets in blocks; return per target (stamps, achieved rates)."""
    sent = {name: ([], []) for name in TARGETS}
    left = seconds
    while left > 1e-9:
        chunk = min(block, left)
        for name in TARGETS:
            stamps, achieved = probe.publish(name, rate, chunk)
            sent[name][0].extend(stamps)
            sent[name][1].append(achieved)
            time.sleep(0.5)  # drain
        left -= chunk
    return sent


def main():
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--sweep-seconds', type=float, default=3.0)
    parser.add_argument('--block', type=float, default=5.0)
    args = parser.parse_args()
    os.environ.update(ROS_DOMAIN_ID=str(150 + os.getpid() % 50),
                      ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    work = Path(tempfile.mkdtemp(prefix='cvc_latency_'))
    log = open(work / 'processes.log', 'w')
    layout = ROOT / 'config' / 'ct_gantry.yaml'
    processes = [subprocess.Popen([sys.executable, *command], stdout=log,
                                  stderr=subprocess.STDOUT, cwd=ROOT) for command in (
        ['-m', 'cvc_balance.ros.balance_monitor', '--ros-args', '-p', f'layout_file:={layout}'],
        [str(HERE / 'relay_node.py'), '--ros-args', '-r', 'joint_states:=relay_in'])]
    probe = Probe()
    stop = threading.Event()
    receiver = threading.Thread(target=probe.spin, args=(stop,))
    receiver.start()
    try:
        probe.wait_for_targets()
        runs = [(1000, run_blocks(probe, 1000, args.seconds, args.block))]
        for rate in SWEEP:
            runs.append((rate, run_blocks(probe, rate, args.sweep_seconds, args.block)))
        time.sleep(1.0)
    finally:
        stop.set()
        receiver.join()
        for process in processes:
            process.send_signal(signal.SIGINT)
        for process in processes:
            process.wait(20)
        log.close()
    print(f'{"":30}{"p50 [ms]":>10}{"p99 [ms]":>10}{"max [ms]":>10}{"drops":>8}{"sent/s":>9}')
    highest, p50 = {}, {}
    for rate, sent in runs:
        for name, (stamps, achieved) in sent.items():
            values, drops = probe.latencies(name, stamps)
            if drops == 0:
                highest[name] = max(highest.get(name, 0), rate)
            label = f'{name} at {rate} Hz, {len(stamps) / rate:g} s'
            median, p99 = np.percentile(values, [50, 99]) if len(values) else (np.nan,) * 2
            if rate == 1000:
                p50[name] = median
            print(f'{label:30}{median:10.3f}{p99:10.3f}{values.max():10.3f}{drops:8d}'
                  f'{min(achieved):9.0f}')
    print(f'node p50 / relay p50 at 1 kHz: {p50["node"] / p50["relay"]:.3f}')
    for name in TARGETS:
        print(f'highest input rate without drops, {name}: {highest.get(name, 0)} Hz '
              f'(rates tried: 1000, {", ".join(map(str, SWEEP))})')
    probe.node.destroy_node()
    probe.rclpy.try_shutdown()


if __name__ == '__main__':
    main()
