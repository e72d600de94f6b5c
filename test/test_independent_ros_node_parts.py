"""
The node's parts that need no ROS graph, in this process.

QoS, the spin loop, the layout's preparation, the run label, the help and the arguments
refused before ROS starts.

The node and ``record`` run them in their own processes (test/test_ros_conventions.py,
test/test_command_line_edges.py, test/test_node_hostile.py), which a mutation run cannot
see. The spin loop is driven here by a stand-in executor (what rclpy's would be told:
add the node, spin once with a 0.1 s timeout until the context ends or a signal came,
shut down); the layout's aggregates are worked out by hand for two point masses.
"""

import json
import math
import signal

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
import yaml

from cvc_balance.bag.run_label import RunLabel
from cvc_balance.physics.layout import LayoutError
from cvc_balance.ros import executor
from cvc_balance.ros.balance_monitor import _text, main, PARAMETERS, prepare_layout, \
    recording_label, TOPICS, usage
from cvc_balance.ros.qos import input_qos

LAYOUT = """
name: two masses
components:
  - {name: a, mass: 2.0, radius: 0.5, angle_deg: 0.0, z: -0.1}
  - {name: b, mass: 1.0, radius: 0.25, angle_deg: 90.0, z: 0.2}
supports:
  - {name: front, z: -0.3}
  - {name: rear, z: 0.3, axial: true}
"""


def test_the_inputs_qos_is_sensor_data_with_a_deeper_history():
    """Best effort and volatile (rclpy's sensor-data preset), keep last ``depth``."""
    qos = input_qos(200)
    assert (qos.depth, qos.history, qos.reliability, qos.durability) == (
        200, HistoryPolicy.KEEP_LAST, ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE)


class Executor:
    """A stand-in for rclpy's executor: spin_once raises what it is given, in turn."""

    def __init__(self, context, outcomes, stop_after):
        self.context, self.outcomes, self.stop_after = context, list(outcomes), stop_after
        self.nodes, self.spins, self.shut = [], [], False

    def add_node(self, node):
        self.nodes.append(node)

    def spin_once(self, timeout_sec):
        self.spins.append(timeout_sec)
        if len(self.spins) >= self.stop_after:
            executor._stop.set()
        outcome = self.outcomes.pop(0) if self.outcomes else None
        if outcome is not None:
            raise outcome

    def shutdown(self):
        self.shut = True


@pytest.fixture
def spun(monkeypatch):
    """Return a function running executor.spin with a stand-in executor and context."""
    import rclpy
    import rclpy.experimental
    made = []
    monkeypatch.setattr(rclpy, 'ok', lambda context: context == 'context')
    monkeypatch.setattr(executor, '_stop', executor.threading.Event())

    def spin(outcomes=(), stop_after=3, on_error=None, context='context'):
        def events_executor(context):
            made.append(Executor(context, outcomes, stop_after))
            return made[-1]
        monkeypatch.setattr(rclpy.experimental, 'EventsExecutor', events_executor,
                            raising=False)
        executor._stop.clear()
        node = type('Node', (), {'context': context})()
        executor.spin(node, on_error)
        return node, made[-1]
    return spin


def test_the_spin_loop_spins_until_a_signal_or_the_context_ends(spun):
    node, made = spun(stop_after=3)
    assert (made.context, made.nodes, made.spins, made.shut) == ('context', [node],
                                                                 [0.1] * 3, True)
    _, made = spun(context='ended')                       # rclpy.ok is False: no spin
    assert (made.spins, made.shut) == ([], True)


def test_a_message_rclpy_cannot_hand_over_is_lost_not_the_node(spun):
    errors = []
    broken = ValueError('not UTF-8')
    _, made = spun([broken, None, broken], stop_after=4, on_error=errors.append)
    assert errors == [broken, broken] and len(made.spins) == 4 and made.shut
    with pytest.raises(ValueError):                       # without on_error: raised
        spun([broken], stop_after=4)
    assert made.shut
    # Ctrl-C and an external shutdown end the loop quietly.
    from rclpy.executors import ExternalShutdownException
    for stop in (KeyboardInterrupt(), ExternalShutdownException()):
        _, made = spun([stop], stop_after=9, on_error=errors.append)
        assert (len(made.spins), made.shut, len(errors)) == (1, True, 2)


def test_without_the_events_executor_the_default_one_spins(monkeypatch):
    import builtins
    import rclpy
    real = builtins.__import__
    made = []

    def no_experimental(name, *args, **kwargs):
        if name == 'rclpy.experimental':
            raise ImportError(name)
        return real(name, *args, **kwargs)

    def single(context):
        made.append(Executor(context, (), 2))
        return made[-1]
    monkeypatch.setattr(builtins, '__import__', no_experimental)
    monkeypatch.setattr(rclpy.executors, 'SingleThreadedExecutor', single)
    monkeypatch.setattr(rclpy, 'ok', lambda context: True)
    monkeypatch.setattr(executor, '_stop', executor.threading.Event())
    executor.spin(type('Node', (), {'context': 'c'})())
    assert (made[0].context, made[0].spins, made[0].shut) == ('c', [0.1, 0.1], True)


def test_init_starts_rclpy_without_its_handlers_and_a_signal_stops_the_loop(monkeypatch):
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    started, handlers = [], {}
    monkeypatch.setattr(rclpy, 'init', lambda **kwargs: started.append(kwargs))
    monkeypatch.setattr(signal, 'signal', lambda number, handler: handlers.update(
        {number: handler}))
    monkeypatch.setattr(executor, '_stop', executor.threading.Event())
    executor.init(['node', '--ros-args'])
    assert started == [{'args': ['node', '--ros-args'],
                        'signal_handler_options': SignalHandlerOptions.NO}]
    assert set(handlers) == {signal.SIGINT, signal.SIGTERM}
    assert not executor._stop.is_set()
    handlers[signal.SIGTERM](signal.SIGTERM, None)
    assert executor._stop.is_set()
    executor._stop.clear()
    handlers[signal.SIGINT](signal.SIGINT, None)
    assert executor._stop.is_set()
    executor.init()
    assert started[-1]['args'] is None


def test_a_layout_prepared_with_its_aggregates_by_hand_or_refused_in_one_line(monkeypatch):
    prepared = prepare_layout(LAYOUT, 'two.yaml')
    assert (prepared.text, prepared.source) == (LAYOUT, 'two.yaml')
    assert prepared.layout.name == 'two masses'
    # U = 2 x 0.5 at 0 deg + 1 x 0.25 at 90 deg = (1.0, 0.25) kg m.
    assert prepared.static == pytest.approx((1.0, 0.25), abs=1e-15)
    # Couple about the centre of mass (z_c = (2 x -0.1 + 1 x 0.2) / 3 = 0): U_i (z_i - z_c).
    assert prepared.couple == pytest.approx((1.0 * -0.1, 0.25 * 0.2), abs=1e-15)
    assert prepared.warnings == ()                          # nothing looks mistaken
    # The digest is the layout's, however written: the same in JSON, another for 2.5 kg.
    as_json = json.dumps(yaml.safe_load(LAYOUT))
    assert prepare_layout(as_json, 'two.json').digest == prepared.digest
    assert prepare_layout(LAYOUT.replace('mass: 2.0', 'mass: 2.5'), 'x').digest != \
        prepared.digest
    # The static loads: 3 kg x 9.80665 down (-y), half on each support (z_c = 0, -+0.3 m).
    assert set(prepared.shares) == {'front', 'rear'}
    for share in prepared.shares.values():
        assert abs(share - complex(0.0, -1.5 * 9.80665)) < 1e-9, prepared.shares
    with pytest.raises(LayoutError) as caught:
        from cvc_balance.physics.layout_file import layout_from_text
        layout_from_text('components: 3', source='bad.yaml')
    assert prepare_layout('components: 3', 'bad.yaml') == str(caught.value)
    import cvc_balance.ros.balance_monitor as monitor

    def broken(layout):
        raise RuntimeError('boom\n  at line 2')
    monkeypatch.setattr(monitor.RotorModel, 'from_layout', broken)
    assert prepare_layout(LAYOUT, 'two.yaml') == 'two.yaml: RuntimeError: boom at line 2'


def test_the_recordings_run_label_or_the_parameters_named():
    assert recording_label('', '') is None and recording_label('', None) is None
    assert recording_label('check', '') == RunLabel('check')
    trial = recording_label('trial', 'I:0.2@0,0.68')
    assert trial.kind == 'trial' and trial.trial.plane == 'I'
    assert (trial.trial.mass, trial.trial.radius) == (0.2, 0.68)
    for kind, text, said in (
            ('', 'I:0.2@0,0.68', 'record_trial goes with record_run trial (say what run '
                                 'this is)'),
            ('visit', '', "record_run: give one of baseline, trial, check, trim, got 'visit'"),
            ('trial', '', 'record_run trial: give the trial weight too (record_trial '
                          'PLANE:MASS_KG@ANGLE_DEG,RADIUS_M, e.g. I:0.2@0,0.68)'),
            ('check', 'I:0.2@0,0.68', 'record_trial goes with record_run trial only (this run '
                                      'is a check run)')):
        with pytest.raises(ValueError) as caught:
            recording_label(kind, text)
        assert str(caught.value) == f'parameters record_run/record_trial: {said}'


def test_status_values_as_text():
    assert [_text(v) for v in (1.23456789, 2.0, 1e-7, 3, 'x', True, None, math.inf)] == \
        ['1.23457', '2', '1e-07', '3', 'x', 'True', 'None', 'inf']


def test_the_help_lists_every_topic_and_parameter_and_starts_nothing(capsys, monkeypatch):
    import cvc_balance.ros.balance_monitor as monitor

    def forbidden(*args, **kwargs):
        raise AssertionError('ROS started')
    for name in ('init', 'spin', 'BalanceMonitor'):       # none of them may be reached
        monkeypatch.setattr(monitor, name, forbidden)
    text = usage()
    lines = text.split('\n')
    assert lines[:10] == [
        'usage: balance-monitor [-h] [--ros-args [-p NAME:=VALUE] [--params-file FILE] '
        '[-r FROM:=TO] ...]',
        '',
        'ROS 2 node balance_monitor: bearing loads, drive torque and unbalance of a rotor',
        'from its encoder (joint_states or speed) or tach (keyphasor_topic) and its',
        'component layout, with the ISO 21940-11 verdict on /diagnostics. Runs until',
        'SIGINT or SIGTERM. Topic names are relative: -r __ns:=/gantry1 puts them under',
        '/gantry1, -r joint_states:=/x remaps one. <name>: each support of the layout in',
        'force.',
        '',
        'inputs:']
    inputs, outputs, parameters = (lines.index('inputs:'), lines.index('outputs:'),
                                   lines.index('parameters (-p NAME:=VALUE after --ros-args, '
                                               'or --params-file FILE: config/balance_'
                                               'monitor.yaml, keyed /** for any name and '
                                               'namespace):'))
    assert inputs < outputs < parameters
    ins = [n for n, _, way, _ in TOPICS if way == 'in']
    outs = [n for n, _, way, _ in TOPICS if way == 'out']
    assert [line.split(' ')[2] for line in lines[inputs + 1:outputs]] == ins
    assert [line.split(' ')[2] for line in lines[outputs + 1:parameters - 1]] == outs
    assert lines[parameters - 1] == ''
    assert '  speed (std_msgs/msg/Float64): ' in text
    assert len(lines) == parameters + 1 + len(PARAMETERS)
    window = [line for line in lines if line.startswith('  identify_window_revs ')]
    assert window == ['  identify_window_revs (default 10, 1 to 100000): revolutions over '
                      'which the load cells fit the measured unbalance '
                      '(supports/<name>/measured_load)']
    assert "  joint_name (default 'gantry_joint'): JointState joint" in text
    assert "  keyphasor_threshold (default nan): a sampled tach's threshold" in text
    for argv in (['balance_monitor', '-h'], ['balance_monitor', '--help'],
                 ['balance_monitor', '--ros-args', '-p', 'x:=1', '--help']):
        assert main(argv) == 0
        assert capsys.readouterr() == (text + '\n', '')
    assert main(['balance_monitor', 'layout.yaml', '--ros-args']) == 2
    assert capsys.readouterr() == ('', "balance_monitor: error: unexpected argument "
                                       "'layout.yaml' (ROS arguments go after --ros-args; "
                                       'see --help)\n')
    assert main(['balance_monitor', 'x']) == 2
    assert "unexpected argument 'x'" in capsys.readouterr().err


def test_the_node_started_after_ros_spun_and_shut_down_or_refused_in_words(
        monkeypatch, capsys):
    """With rclpy's start, the node and the spin loop stood in for: each step and its words."""
    import sys
    import cvc_balance.ros.balance_monitor as monitor
    done = []
    node = type('Node', (), {'lost_message': lambda self, error: None,
                             'destroy_node': lambda self: done.append('destroyed')})()
    monkeypatch.setattr(monitor, 'init', lambda args: done.append(('init', args)))
    monkeypatch.setattr(monitor, 'BalanceMonitor', lambda: node)
    monkeypatch.setattr(monitor, 'spin', lambda spun, on_error: done.append(
        ('spin', spun, on_error)))
    monkeypatch.setattr(monitor.rclpy, 'try_shutdown', lambda: done.append('shut down'))
    monkeypatch.setattr(sys, 'setswitchinterval', lambda s: done.append(('interval', s)))
    argv = ['balance_monitor', '--ros-args', '-p', 'x:=1']
    assert main(argv) == 0
    assert done == [('init', argv), ('interval', 0.0005), ('spin', node, node.lost_message),
                    'destroyed', 'shut down']
    assert capsys.readouterr() == ('', '')
    # The process's own arguments when none are given.
    done.clear()
    monkeypatch.setattr(sys, 'argv', ['balance_monitor', '--ros-args'])
    assert main() == 0 and done[0] == ('init', ['balance_monitor', '--ros-args'])
    # Bad ROS arguments, and a node that cannot start: exit 2 and one line.
    done.clear()

    def bad_arguments(args):
        raise ValueError('unknown ROS argument -q')
    monkeypatch.setattr(monitor, 'init', bad_arguments)
    assert main(argv) == 2 and done == []
    assert capsys.readouterr() == ('', 'balance_monitor: error: bad ROS arguments: unknown ROS '
                                       'argument -q (see --help)\n')
    monkeypatch.setattr(monitor, 'init', lambda args: None)

    def refused():
        raise OSError('record_path: its folder does not exist')
    monkeypatch.setattr(monitor, 'BalanceMonitor', refused)
    assert main(argv) == 2 and done == [('interval', 0.0005), 'shut down']
    assert capsys.readouterr() == ('', 'balance_monitor: error: record_path: its folder does '
                                       'not exist\n')
