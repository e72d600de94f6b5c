"""
The node as a ROS integrator meets it: under a namespace, with the shipped parameters file.

Issue 27: config/balance_monitor.yaml was keyed ``balance_monitor:``, so under
``-r __ns:=/gantry1`` it was silently ignored (166 samples rejected with the default joint
name); a wrong joint name was refused without naming the joints seen; STALE named no
resolved topic; ``--help`` omitted the load-cell input and the identified outputs; the
diagnostic status name ignored the namespace; ``hardware_id`` was the node's name, not
``machine_id``. One node run under /gantry1 checks each, against the ROS graph itself
(what the node subscribes and publishes, its parameters as its own service lists them).
"""

from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.srv import ListParameters
from sensor_msgs.msg import JointState
import yaml

from ros_harness import NodeProcess, Probe
from test_balance_monitor import LAYOUT_A

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_parameters_file_is_keyed_for_any_name_and_namespace():
    config = yaml.safe_load((ROOT / 'config' / 'balance_monitor.yaml').read_text())
    assert list(config) == ['/**']
    from cvc_balance.ros.balance_monitor import PARAMETERS
    declared = {name: default for name, default, _, _ in PARAMETERS}
    for name, value in config['/**']['ros__parameters'].items():
        assert name in declared and type(value) is type(declared[name]), name


def statuses(probe):
    """Return the last DiagnosticArray's statuses, or []."""
    arrays = probe.received['/diagnostics']
    return list(arrays[-1].status) if arrays else []


def help_topics():
    """Return {topic: type} that ``balance-monitor --help`` lists."""
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.ros.balance_monitor', '--help'],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0
    listed = dict(re.findall(r'^  (\S+) \((\w+/msg/\w+)\): ', run.stdout, re.M))
    parameters = re.findall(r'^  (\w+) \(default ', run.stdout, re.M)
    return listed, parameters


def test_under_a_namespace_with_the_shipped_parameters_file(tmp_path):
    """
    Under /gantry1 with a copy of the shipped file (joint 'spin', machine 'CT-0042').

    The file applies (the joint is taken); STALE names the resolved topics and, nothing
    publishing there but JointState on /robot/joint_states, the remap; a JointState
    without the joint is refused naming the joints it has; the statuses are named after
    /gantry1/balance_monitor with hardware_id CT-0042; every topic the node subscribes
    and publishes, and every parameter it has, is in --help.
    """
    config = yaml.safe_load((ROOT / 'config' / 'balance_monitor.yaml').read_text())
    layout = tmp_path / 'layout.yaml'
    layout.write_text(yaml.safe_dump(LAYOUT_A))
    config['/**']['ros__parameters'].update(joint_name='spin', machine_id='CT-0042',
                                            stale_after=0.5, diagnostics_period=0.2,
                                            layout_file=str(layout))
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump(config))
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['--params-file', str(params), '-r', '__ns:=/gantry1'],
                       tmp_path / 'node.log')
    probe = Probe('conventions_probe')
    probe.record(DiagnosticArray, '/diagnostics')
    outputs = probe.record(WrenchStamped, '/gantry1/bearing_load')
    try:
        elsewhere = probe.publisher(JointState, '/robot/joint_states', sensor=True)
        hint = ('no motion sample yet on /gantry1/joint_states or /gantry1/speed, where '
                'nothing publishes; JointState is published on /robot/joint_states: remap '
                'with -r joint_states:=/robot/joint_states (stale after 0.5 s)')
        assert probe.spin_until(lambda: any(s.message.startswith(hint)
                                            for s in statuses(probe)), 20.0), \
            ([s.message for s in statuses(probe)], node.log())
        probe.node.destroy_publisher(elsewhere)
        joints = probe.publisher(JointState, '/gantry1/joint_states', sensor=True)
        assert probe.spin_until(
            lambda: probe.node.count_subscribers('/gantry1/joint_states') >= 1, 20.0)
        probe.spin_for(1.5)
        wrong = JointState(name=['a', 'b'], position=[0.0, 0.0], velocity=[1.0, 1.0])
        wrong.header.stamp.sec, wrong.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
        joints.publish(wrong)
        refusal = "/gantry1/joint_states without joint 'spin' (it names 'a', 'b'): set joint_name"
        assert probe.spin_until(lambda: any(kv.value == refusal for s in statuses(probe)
                                            for kv in s.values), 10.0), node.log()
        for k in range(50):
            msg = JointState(name=['spin'], position=[0.01 * k], velocity=[10.0])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            joints.publish(msg)
            probe.spin_for(0.001)
        assert probe.spin_until(lambda: len(outputs) >= 50, 10.0), (len(outputs), node.log())
        probe.spin_for(0.5)
        names = {s.name: s.hardware_id for s in statuses(probe)}
        assert names['/gantry1/balance_monitor: rotor balance'] == 'CT-0042'
        assert names['/gantry1/balance_monitor: input checks'] == 'CT-0042'
        # The graph against --help.
        listed, parameters = help_topics()
        expected = {}
        for name, kind in listed.items():
            for support in ('front', 'rear'):
                full = name.replace('<name>', support)
                expected[full if full.startswith('/') else f'/gantry1/{full}'] = kind
        seen = probe.node.get_subscriber_names_and_types_by_node('balance_monitor', '/gantry1')
        seen += probe.node.get_publisher_names_and_types_by_node('balance_monitor', '/gantry1')
        ours = {name: kinds for name, kinds in seen
                if not name.endswith(('/parameter_events', '/rosout'))}
        assert '/gantry1/supports/front/measured_load' in ours
        for name, kinds in ours.items():
            assert name in expected and expected[name] in kinds, (name, kinds)
        client = probe.node.create_client(ListParameters, '/gantry1/balance_monitor/'
                                          'list_parameters')
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(ListParameters.Request())
        assert probe.spin_until(future.done, 10.0)
        rclpy_own = {'use_sim_time', 'start_type_description_service'}
        declared = set(future.result().result.names) - rclpy_own
        assert declared == set(parameters)
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
    assert 'motion samples: 50 accepted, 1 rejected, 0 dropped' in node.log()
