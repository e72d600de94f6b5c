"""
Test harness for the node: run it as its own process, talk to it from a probe node.

Each test run takes a ROS_DOMAIN_ID no other run on this machine holds (a lock file
per id, held for the run's life) and keeps DDS discovery on this machine
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST), so two copies of the suite can run at once.
"""

import fcntl
import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy

DOMAIN_IDS = [i for i in range(1, 101) if i != 42]
"""Ids whose DDS ports stay below Linux's ephemeral range (42: the demo's)."""
_LOCK_DIR = os.environ.get('CVC_BALANCE_LOCK_DIR', '/tmp')


def _claim_domain_id():
    """Return a domain id locked for this process (the lock dies with it)."""
    start = os.getpid() % len(DOMAIN_IDS)
    for domain in DOMAIN_IDS[start:] + DOMAIN_IDS[:start]:
        lock = open(os.path.join(_LOCK_DIR, f'cvc_balance_ros_domain_{domain}.lock'), 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _claim_domain_id.lock = lock      # kept open: the id stays ours until we exit
        return domain
    raise RuntimeError('every ROS domain id 1-100 is held by another test run')


DOMAIN_ID = _claim_domain_id()


def ros_environment():
    """Return the environment for ROS processes of this test run."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(DOMAIN_ID), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               RCUTILS_LOGGING_BUFFERED_STREAM='0', PYTHONUNBUFFERED='1')
    return env


class NodeProcess:
    """The node under test, started as ``python -m MODULE --ros-args ...``."""

    running = []   # every process started and not yet stopped: the fixture ends them

    def __init__(self, module, ros_args, log_path):
        """Start it; its output goes to ``log_path``."""
        NodeProcess.running.append(self)
        self.log_path = log_path
        self._log = open(log_path, 'w')
        self.process = subprocess.Popen(
            [sys.executable, '-m', module, '--ros-args', *ros_args], env=ros_environment(),
            stdout=self._log, stderr=subprocess.STDOUT)

    def stop(self, sig=signal.SIGINT, timeout=10.0):
        """Send ``sig``; return the exit code (None if it had to be killed)."""
        if self in NodeProcess.running:
            NodeProcess.running.remove(self)
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
                self._log.close()
                return None
        self._log.close()
        return self.process.returncode

    def log(self):
        """Return what the node printed so far."""
        if not self._log.closed:
            self._log.flush()
        with open(self.log_path) as stream:
            return stream.read()


class Probe:
    """A test-side node: publishers for the inputs, recorders for the outputs."""

    def __init__(self, name='probe'):
        """Start rclpy in its own context on this run's domain."""
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=DOMAIN_ID)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received = {}

    def publisher(self, msg_type, topic, sensor=False, latched=False):
        """Make a publisher: sensor-data QoS, or transient local for latched topics."""
        if sensor:
            qos = qos_profile_sensor_data
        elif latched:
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        else:
            qos = QoSProfile(depth=10)
        return self.node.create_publisher(msg_type, topic, qos)

    def record(self, msg_type, topic, depth=10000):
        """Keep every message of ``topic`` in ``self.received[topic]``."""
        self.received[topic] = []
        self.node.create_subscription(msg_type, topic, self.received[topic].append,
                                      QoSProfile(depth=depth))
        return self.received[topic]

    def spin_until(self, predicate, timeout=10.0):
        """Spin until ``predicate()`` holds; return whether it did within ``timeout`` s."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.01)
        return predicate()

    def spin_for(self, seconds):
        """Spin for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.005)

    def close(self):
        """Stop the probe."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
