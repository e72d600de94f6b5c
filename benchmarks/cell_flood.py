"""
The live node under a load-cell flood: motion samples answered while cells stream fast.

The node (bundled gantry layout) gets joint_states at --motion-rate (default 1 kHz) for
--seconds, and each of its two cells (supports/front and rear/measured_load) readings at
--cell-rate (default 2 kHz each: 4 kHz of cells). The publisher is its own process
(``--publish``), as sensors are. Printed: good motion samples sent, accepted by the
node (its own count at shutdown), lost (%), cell readings sent and taken by the fit
(the node's count), and the node's CPU time per second.

Run: ./dev.sh run python benchmarks/cell_flood.py [--cell-rate 2000] [--seconds 10]
"""

import argparse
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from ros_harness import NodeProcess, ros_environment  # noqa: E402


def publish(motion_rate, cell_rate, seconds):
    """Publish motion and cell messages (this process is the sensors); print counts."""
    from geometry_msgs.msg import WrenchStamped
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    import ros_harness
    # The parent's domain (its lock), not one of this process's own.
    ros_harness.DOMAIN_ID = int(os.environ['ROS_DOMAIN_ID'])
    probe = ros_harness.Probe('flood_probe')
    assert rclpy.ok(context=probe.context)
    joints = probe.node.create_publisher(JointState, 'joint_states', qos_profile_sensor_data)
    cells = [probe.node.create_publisher(WrenchStamped, f'supports/{name}/measured_load',
                                         qos_profile_sensor_data) for name in ('front', 'rear')]
    probe.spin_until(lambda: probe.node.count_subscribers('joint_states') >= 1 and all(
        probe.node.count_subscribers(f'supports/{n}/measured_load') >= 1
        for n in ('front', 'rear')), 30.0)
    probe.spin_for(1.5)
    omega = 20.0
    msg = JointState(name=['gantry_joint'], position=[0.0], velocity=[omega])
    cell = WrenchStamped()
    sent = cell_sent = 0
    start = time.perf_counter()
    next_motion = next_cell = 0.0
    while True:
        now = time.perf_counter() - start
        if now >= seconds:
            break
        if now >= next_motion:
            stamp = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            msg.position[0] = math.remainder(omega * now, 2 * math.pi)
            joints.publish(msg)
            sent += 1
            next_motion += 1.0 / motion_rate
        if cell_rate and now >= next_cell:
            stamp = time.time_ns()
            cell.header.stamp.sec, cell.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            angle = omega * now
            for k, pub in enumerate(cells):
                cell.wrench.force.x = 100.0 * math.cos(angle)
                cell.wrench.force.y = 1500.0 + 100.0 * math.sin(angle)
                pub.publish(cell)
                cell_sent += 1
            next_cell += 1.0 / cell_rate
        wait = min(next_motion, next_cell if cell_rate else math.inf) - \
            (time.perf_counter() - start)
        if wait > 0.0002:
            time.sleep(wait - 0.0001)
    print(f'sent {sent} {cell_sent}', flush=True)
    probe.close()


def cpu_seconds(pid):
    """User + system CPU time of process ``pid``, s."""
    with open(f'/proc/{pid}/stat') as stat:
        fields = stat.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def run(motion_rate, cell_rate, seconds, node_root=ROOT):
    """Start a node, flood it; return (sent, accepted, cells sent, node CPU s per s)."""
    with tempfile.TemporaryDirectory() as folder:
        here = os.getcwd()
        os.chdir(node_root)         # python -m imports the node from its working directory
        try:
            node = NodeProcess('cvc_balance.ros.balance_monitor',
                               ['-p', f"layout_file:={ROOT / 'config' / 'ct_gantry.yaml'}"],
                               Path(folder) / 'node.log')
        finally:
            os.chdir(here)
        time.sleep(2.0)
        cpu0, wall0 = cpu_seconds(node.process.pid), time.monotonic()
        out = subprocess.run([sys.executable, __file__, '--publish', '--motion-rate',
                              str(motion_rate), '--cell-rate', str(cell_rate), '--seconds',
                              str(seconds)], env=ros_environment(), capture_output=True,
                             text=True, timeout=seconds + 120)
        cpu = (cpu_seconds(node.process.pid) - cpu0) / (time.monotonic() - wall0)
        time.sleep(0.5)
        node.stop(signal.SIGINT)
        log = node.log()
    sent, cells = map(int, re.search(r'sent (\d+) (\d+)', out.stdout).groups())
    accepted = int(re.search(r'motion samples: (\d+) accepted', log)[1])
    taken = re.search(r'load cell readings \(layout in force\): (\d+) front, (\d+) rear', log)
    return sent, accepted, cells, cpu, (int(taken[1]) + int(taken[2])) if taken else None


def main():
    """Run the flood and print what the node answered."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--motion-rate', type=float, default=1000.0)
    parser.add_argument('--cell-rate', type=float, default=2000.0,
                        help='readings per second of each of the two cells')
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--runs', type=int, default=1)
    parser.add_argument('--baseline', type=Path, help='a checkout of the node to compare '
                        '(e.g. a git worktree of main), run alternately with this one')
    parser.add_argument('--publish', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.publish:
        publish(args.motion_rate, args.cell_rate, args.seconds)
        return
    roots = [('this', ROOT)] + ([('baseline', args.baseline)] if args.baseline else [])
    for _ in range(args.runs):
        for name, root in roots:
            sent, accepted, cells, cpu, taken = run(args.motion_rate, args.cell_rate,
                                                    args.seconds, root)
            lost = 100 * (sent - accepted) / sent
            print(f'{name}: motion {args.motion_rate:g} Hz, cells {2 * args.cell_rate:g} Hz in '
                  f'all: {accepted} of {sent} motion samples answered ({lost:.2f} % lost), '
                  f'{cells} cell readings sent, {taken} taken by the fit; node CPU '
                  f'{cpu:.2f} s/s', flush=True)


if __name__ == '__main__':
    main()
