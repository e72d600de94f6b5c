"""
ROS 2 node ``balance_monitor``: live bearing loads, drive torque and unbalance.

A thin adapter: it turns ``joint_states`` (or ``speed``) samples and the
``layout`` into engine calls and publishes the results from the input
callback, with no timer in between. The per-message path is plain Python
floats (:func:`cvc_balance.physics.engine.sample_loads`), O(1) in the number of
components; layout aggregates are computed once per layout.

Subscriptions (relative names): ``joint_states`` (sensor_msgs/JointState,
sensor-data QoS), ``speed`` (std_msgs/Float64, rad/s; q integrated from
receive times), ``layout`` (std_msgs/String, YAML or JSON, transient local).
Publications (geometry_msgs/WrenchStamped, stamp = input sample's stamp):
``bearing_load`` and ``supports/<name>/load`` (stator frame, N and N m),
``unbalance`` (rotor frame: force = U omega^2, torque = couple moment),
``drive_torque`` (rotor frame, torque.z). ``/diagnostics`` every period and at
each layout change: the ISO 21940-11 verdict (one definition,
:func:`cvc_balance.physics.assessment.judge_balance`: at the layout's service
speed, or the top speed seen), the layout's plausibility warnings, the node's
counts; STALE when no motion sample came for ``stale_after`` seconds. Changes
of that level are logged once each (WARN and STALE as warnings, ERROR as an
error, back to OK as info).
"""

import math
import sys
from time import monotonic

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import ParameterType
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from cvc_balance.messages import topics
from cvc_balance.messages.cdr import WrenchStampedEncoder
from cvc_balance.physics import assessment
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.frames import degrees, g_mm, g_mm2, ROTOR_FRAME, STATOR_FRAME
from cvc_balance.physics.layout import LayoutError
from cvc_balance.physics.layout_file import layout_from_text, load_layout
from cvc_balance.physics.motion import AccelerationEstimator, AngleIntegrator, sample_problem
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance, unbalance_wrench
from cvc_balance.ros.executor import spin
from cvc_balance.ros.qos import input_qos, LAYOUT_QOS, OUTPUT_QOS
from cvc_balance.ros.recorder import BagRecorder

THROTTLE_S = 1.0
LEVELS = {assessment.OK: DiagnosticStatus.OK, assessment.NOT_JUDGED: DiagnosticStatus.OK,
          assessment.WARN: DiagnosticStatus.WARN, assessment.ERROR: DiagnosticStatus.ERROR}
LEVEL_NAMES = {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
               DiagnosticStatus.ERROR: 'ERROR', DiagnosticStatus.STALE: 'STALE'}


PARAMETERS = (
    # name, default, description, (min, max) for numbers
    ('joint_name', 'gantry_joint', 'JointState joint whose position (rad) and velocity '
     '(rad/s) are the rotor angle q and speed omega', None),
    ('layout_file', '', 'layout file (YAML/JSON) to start with; empty: wait for one on '
     'the layout topic', None),
    ('stator_frame', STATOR_FRAME, 'frame_id of stator-frame outputs', None),
    ('rotor_frame', ROTOR_FRAME, 'frame_id of rotor-frame outputs', None),
    ('alpha_time_constant', 0.1, 'time constant (s) of the least-squares slope that '
     'estimates alpha from omega', (1e-4, 100.0)),
    ('balance_grade', 0.0, "ISO 21940-11 grade G (mm/s) for the diagnostics; 0: the "
     "layout's balancing.grade", (0.0, 4000.0)),
    ('warn_fraction', assessment.WARN_FRACTION, 'WARN when the achieved grade exceeds this '
     'fraction of the grade (ERROR beyond the grade)', (0.01, 1.0)),
    ('max_speed', 1000.0, 'absolute speeds above this (rad/s) are rejected as absurd',
     (1e-3, 1e5)),
    ('diagnostics_period', 1.0, 'period (s) of /diagnostics', (0.01, 60.0)),
    ('stale_after', 2.0, '/diagnostics says STALE when no motion sample was accepted for '
     'this long (s)', (0.01, 3600.0)),
    ('input_depth', 200, 'history depth of the best-effort joint_states and speed '
     'subscriptions', (1, 10000)),
    ('record_path', '', 'record inputs, outputs and diagnostics to this MCAP bag; empty: '
     'no recording', None),
    ('machine_id', '', 'the machine monitored (serial number, asset tag), written into the '
     "recording (MCAP metadata, metadata.yaml custom_data) for cvc-balance fleet; empty: "
     'none', None),
    ('rerun', '', 'rerun view of the run: save (to rerun_target, an .rrd), connect (to the '
     'viewer at rerun_target) or spawn (a viewer); empty: off', None),
    ('rerun_target', '', '.rrd path (save) or viewer URL (connect)', None),
    ('rerun_every', 20, 'log every n-th sample to rerun (the viewer need not draw 1 kHz)',
     (1, 100000)),
)


class ActiveLayout:
    """A layout in force: its engine model and what the outputs need of it, made once."""

    def __init__(self, layout, node):
        """Aggregate ``layout`` and make the per-support publishers (raises on bad names)."""
        self.layout = layout
        self.model = RotorModel.from_layout(layout)
        self.digest = layout.digest()
        self.static = static_unbalance(self.model)
        self.couple = couple_unbalance(self.model)
        self.warnings = layout_warnings(layout)
        self.supports = tuple(
            (s.name, node.publisher(topics.support_load(s.name))) for s in layout.supports)


class BalanceMonitor(Node):
    """Wires joint_states / speed / layout to the engine and the outputs to topics."""

    def __init__(self, **kwargs):
        """Declare parameters, topics and the diagnostics timer; load layout_file if set."""
        super().__init__('balance_monitor', **kwargs)
        self.params = self._declare_parameters()
        self._wrench_publishers = {}
        self._bearing_pub = self.publisher(topics.BEARING_LOAD)
        self._unbalance_pub = self.publisher(topics.UNBALANCE)
        self._torque_pub = self.publisher(topics.DRIVE_TORQUE)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        # Outputs go out as CDR bytes: 3 us a message instead of rclpy's 11 us.
        self._stator_cdr = WrenchStampedEncoder(self.params['stator_frame'])
        self._rotor_cdr = WrenchStampedEncoder(self.params['rotor_frame'])
        self._alpha = AccelerationEstimator(self.params['alpha_time_constant'])
        self._integrator = AngleIntegrator()
        self._active = None
        self._last_time = None
        self._omega = 0.0
        self._counts = {'accepted': 0, 'rejected': 0, 'dropped': 0}
        self._period_accepted = 0
        self._period_start = monotonic()
        self._started = self._period_start
        self._last_input = None     # monotonic s of the last accepted motion sample
        self._top_speed = 0.0       # top |omega| accepted under the layout in force
        self._reported_level = None
        self._peak_load = 0.0
        self._last_rejection = ''
        self._layout_error = ''
        if self.params['layout_file']:
            self._apply_layout_file(self.params['layout_file'])
        sensor_qos = input_qos(self.params['input_depth'])
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_states,
                                 sensor_qos)
        self.create_subscription(Float64, topics.SPEED, self._on_speed, sensor_qos)
        self.create_subscription(String, topics.LAYOUT, self._on_layout, LAYOUT_QOS)
        self.create_timer(self.params['diagnostics_period'], self._publish_diagnostics)
        self._rerun = None
        if self.params['rerun']:
            from cvc_balance.view.rerun_log import open_recording, RunLogger
            self._rerun = RunLogger(open_recording(self.params['rerun'],
                                                   self.params['rerun_target'],
                                                   name=self.get_fully_qualified_name()),
                                    every=self.params['rerun_every'])
            if self._active is not None:
                self._rerun.layout(None, self._active.model)   # at the first sample
        self._recorder = None
        self._record = {}
        if self.params['record_path']:
            # Inputs and diagnostics through raw subscriptions; the outputs are written as
            # they are published (no second trip through DDS).
            self._recorder = BagRecorder(self, self.params['record_path'],
                                         (topics.JOINT_STATES, topics.SPEED, topics.LAYOUT,
                                          topics.DIAGNOSTICS),
                                         machine_id=self.params['machine_id'] or None)
            for topic in topics.OUTPUTS:
                self._record[topic] = self._recorder.add(topic, topics.WRENCH_TYPE)

    def destroy_node(self):
        """Finalise the recording, if any, then destroy the node."""
        # print: rosout is gone once a signal has shut the context down.
        print('balance_monitor: motion samples: ' + ', '.join(
            f'{count} {name}' for name, count in self._counts.items()), flush=True)
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        if self._rerun is not None:
            self._rerun.finish()
            self._rerun = None
        return super().destroy_node()

    def publisher(self, topic):
        """Return the WrenchStamped publisher of ``topic``, made on first use."""
        publishers = self._wrench_publishers
        if topic not in publishers:
            publishers[topic] = self.create_publisher(WrenchStamped, topic, OUTPUT_QOS)
        return publishers[topic]

    # -- inputs ----------------------------------------------------------------------

    def _on_joint_states(self, msg):
        try:
            i = msg.name.index(self.params['joint_name'])
            angle, omega = msg.position[i], msg.velocity[i]
        except (ValueError, IndexError):
            self._reject(f"joint_states without joint '{self.params['joint_name']}' "
                         'or without its position and velocity')
            return
        stamp = msg.header.stamp
        self._process(stamp.sec, stamp.nanosec, angle, omega)

    def _on_speed(self, msg):
        omega = msg.data
        sec, nanosec = divmod(self.get_clock().now().nanoseconds, 1_000_000_000)
        time = sec + nanosec * 1e-9
        problem = sample_problem(time, self._last_time, 0.0, omega, self.params['max_speed'])
        if problem:
            self._reject(f'speed: {problem}')
            return
        self._process(sec, nanosec, self._integrator.update(time, omega), omega)

    def _process(self, sec, nanosec, angle, omega):
        """Compute and publish the outputs of one motion sample (plain floats)."""
        active = self._active
        if active is None:
            self._counts['dropped'] += 1
            self.get_logger().warning('no layout yet: motion samples dropped',
                                      throttle_duration_sec=THROTTLE_S)
            return
        time = sec + nanosec * 1e-9
        problem = sample_problem(time, self._last_time, angle, omega, self.params['max_speed'])
        if problem:
            self._reject(f'motion sample: {problem}')
            return
        self._last_time = time
        alpha = self._alpha.update(time, omega)
        result = sample_loads(active.model, angle, omega, alpha)
        stator, rotor = self._stator_cdr.encode, self._rotor_cdr.encode
        # The total load first: it is the output latency is measured on.
        bearing = stator(sec, nanosec, result.force_stator, result.moment_stator)
        self._bearing_pub.publish(bearing)
        peak = self._peak_load
        supports = []
        for name, pub in active.supports:
            force, moment = result.supports[name]
            data = stator(sec, nanosec, force, moment)
            pub.publish(data)
            supports.append((name, data))
            size = force[0] * force[0] + force[1] * force[1] + force[2] * force[2]
            if size > peak:
                peak = size
        self._peak_load = peak
        unbalance = rotor(sec, nanosec, *unbalance_wrench(active.static, active.couple, omega))
        self._unbalance_pub.publish(unbalance)
        torque = rotor(sec, nanosec, (0.0, 0.0, 0.0), (0.0, 0.0, result.drive_torque))
        self._torque_pub.publish(torque)
        if self._record:
            self._record_outputs(bearing, supports, unbalance, torque)
        if self._rerun is not None:
            self._rerun.sample(sec * 1_000_000_000 + nanosec, angle, omega, alpha, result)
        self._omega = omega
        speed = omega if omega >= 0.0 else -omega
        if speed > self._top_speed:
            self._top_speed = speed
        self._last_input = monotonic()
        self._counts['accepted'] += 1
        self._period_accepted += 1

    def _record_outputs(self, bearing, supports, unbalance, torque):
        now = self.get_clock().now().nanoseconds
        record = self._record
        record[topics.BEARING_LOAD](now, bearing)
        for name, data in supports:
            topic = topics.support_load(name)
            if topic not in record:
                record[topic] = self._recorder.add(topic, topics.WRENCH_TYPE)
            record[topic](now, data)
        record[topics.UNBALANCE](now, unbalance)
        record[topics.DRIVE_TORQUE](now, torque)

    def _reject(self, reason):
        self._counts['rejected'] += 1
        self._last_rejection = reason
        self.get_logger().warning(f'rejected {reason}', throttle_duration_sec=THROTTLE_S)

    # -- layout ----------------------------------------------------------------------

    def _on_layout(self, msg):
        try:
            layout = layout_from_text(msg.data, source='layout topic')
        except LayoutError as error:
            self._refuse_layout(str(error))
            return
        self._apply(layout, 'layout topic')

    def _apply_layout_file(self, path):
        try:
            layout = load_layout(path)
        except LayoutError as error:
            self._refuse_layout(str(error))
            return
        self._apply(layout, path)

    def _apply(self, layout, source):
        try:
            active = ActiveLayout(layout, self)
        except Exception as error:  # e.g. a support name that is no valid topic name
            self._refuse_layout(f'{source}: {error}')
            return
        self._active = active  # one reference swap: takes effect between two samples
        self._top_speed = 0.0
        if self._last_input is None:    # STALE counts from the first layout, not the start
            self._started = monotonic()
        self._layout_error = ''
        if getattr(self, '_rerun', None) is not None:
            # On the samples' time line: from the last sample on.
            self._rerun.layout(None if self._last_time is None
                               else int(self._last_time * 1e9), active.model)
        self.get_logger().info(f"layout '{layout.name}' ({active.digest}) from {source}: "
                               f'{len(layout.components)} components, '
                               f'{active.model.mass:.3f} kg')
        for warning in active.warnings:
            self.get_logger().warning(f"layout '{layout.name}': implausible? {warning}")
        if getattr(self, '_diagnostics_pub', None) is not None and \
                self.context.ok():
            self._publish_diagnostics()   # the new verdict at once, not a period later

    def _refuse_layout(self, reason):
        self._layout_error = reason
        kept = (f"'{self._active.layout.name}' stays in force" if self._active
                else 'no layout in force')
        self.get_logger().error(f'layout rejected ({kept}): {reason}')

    # -- diagnostics -----------------------------------------------------------------

    def _publish_diagnostics(self):
        now = monotonic()
        status = DiagnosticStatus(name='balance_monitor: rotor balance',
                                  hardware_id=self.get_fully_qualified_name())
        values = {'accepted': self._counts['accepted'], 'rejected': self._counts['rejected'],
                  'dropped': self._counts['dropped'],
                  'input rate [Hz]': self._period_accepted / max(now - self._period_start, 1e-9),
                  'peak bearing load [N]': math.sqrt(self._peak_load),
                  'last rejected input': self._last_rejection,
                  'last rejected layout': self._layout_error}
        self._period_accepted, self._peak_load, self._period_start = 0, 0.0, now
        active = self._active
        if active is None:
            level, message = DiagnosticStatus.WARN, 'no layout (waiting for one on the ' \
                f'{topics.LAYOUT} topic)'
        else:
            level, message, balance = self._judge(active)
            values.update(balance)
            quiet = now - (self._last_input if self._last_input is not None else self._started)
            values['last motion sample [s ago]'] = quiet if self._last_input is not None else ''
            if quiet > self.params['stale_after']:
                waited = 'no motion sample yet' if self._last_input is None else \
                    f'no motion sample for {quiet:.1f} s'
                level, message = DiagnosticStatus.STALE, \
                    f"{waited} on {topics.JOINT_STATES} or {topics.SPEED} (stale after " \
                    f"{self.params['stale_after']:g} s); {message}"
        if self._layout_error:
            message += f'; last layout rejected: {self._layout_error}'
        status.level, status.message = level, message
        status.values = [KeyValue(key=k, value=_text(v)) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics_pub.publish(array)
        self._log_transition(level, message)

    def _log_transition(self, level, message):
        """Log a change of the diagnostics level, once (not every period)."""
        if level == self._reported_level:
            return
        self._reported_level = level
        logger = self.get_logger()
        text = f'balance {LEVEL_NAMES.get(level, level)}: {message}'
        if level == DiagnosticStatus.ERROR:
            logger.error(text)
        elif level in (DiagnosticStatus.WARN, DiagnosticStatus.STALE):
            logger.warning(text)
        else:
            logger.info(text)

    def _judge(self, active):
        """Diagnostics level, message and values of the layout in force."""
        layout = active.layout
        grade = self.params['balance_grade'] or layout.balancing.grade
        verdict = assessment.judge_balance(active.model, self._top_speed, grade,
                                           self.params['warn_fraction'])
        values = {'layout': layout.name, 'layout digest': active.digest,
                  'speed [rad/s]': abs(self._omega), 'top speed seen [rad/s]': self._top_speed,
                  'grade [mm/s]': grade, 'verdict level': verdict.level,
                  'verdict': verdict.text}
        judged = verdict.assessment
        if judged is not None:
            values.update({'judged at [rad/s]': judged.omega,
                           'judged at': verdict.speed_source,
                           'achieved grade [mm/s]': judged.equivalent_grade,
                           'static unbalance [g mm]': g_mm(judged.static_amount),
                           'static unbalance angle [deg]': degrees(judged.static_angle),
                           'couple unbalance [g mm^2]': g_mm2(judged.couple_amount),
                           'couple unbalance angle [deg]': degrees(judged.couple_angle),
                           'permissible [g mm]': g_mm(judged.permissible)})
            for label, plane, allowed, fraction in zip(('I', 'II'), judged.planes,
                                                       judged.plane_permissible,
                                                       judged.fractions):
                values.update({f'plane {label} z [m]': plane.z,
                               f'plane {label} unbalance [g mm]': g_mm(plane.amount),
                               f'plane {label} angle [deg]': degrees(plane.angle),
                               f'plane {label} permissible [g mm]': g_mm(allowed),
                               f'plane {label} unbalance / permissible': fraction,
                               f'plane {label} correction mass [g]':
                                   'none (no correction radius)' if plane.correction_mass is None
                                   else plane.correction_mass * 1e3,
                               f'plane {label} correction angle [deg]':
                                   degrees(plane.correction_angle)})
        level, message = LEVELS[verdict.level], verdict.text
        values['layout warnings'] = ' | '.join(active.warnings)
        if active.warnings:
            message += f'; layout implausible? {len(active.warnings)} warning(s): ' \
                f'{active.warnings[0]}'
            level = max(level, DiagnosticStatus.WARN)
        return level, message, values

    def _declare_parameters(self):
        values = {}
        for name, default, description, bounds in PARAMETERS:
            descriptor = ParameterDescriptor(description=description, read_only=True)
            if isinstance(default, int):
                descriptor.type = ParameterType.PARAMETER_INTEGER
                descriptor.integer_range = [
                    IntegerRange(from_value=bounds[0], to_value=bounds[1], step=1)]
            elif bounds is not None:
                descriptor.type = ParameterType.PARAMETER_DOUBLE
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=bounds[0], to_value=bounds[1])]
            values[name] = self.declare_parameter(name, default, descriptor).value
        return values


def _text(value):
    return f'{value:.6g}' if isinstance(value, float) else str(value)


def usage():
    """Return the node's --help: what it does, its topics and parameters."""
    lines = ['usage: balance-monitor [-h] [--ros-args [-p NAME:=VALUE] [--params-file FILE] '
             '[-r FROM:=TO] ...]',
             '',
             'ROS 2 node balance_monitor: bearing loads, drive torque and unbalance of a rotor',
             'from its encoder (joint_states or speed) and its component layout, with the',
             'ISO 21940-11 verdict on /diagnostics. Runs until SIGINT or SIGTERM.',
             '',
             f'inputs: {topics.JOINT_STATES} (sensor_msgs/JointState), {topics.SPEED} '
             f'(std_msgs/Float64), {topics.LAYOUT} (std_msgs/String, latched)',
             f'outputs: {topics.BEARING_LOAD}, supports/<name>/load, {topics.UNBALANCE}, '
             f'{topics.DRIVE_TORQUE} (geometry_msgs/WrenchStamped), {topics.DIAGNOSTICS}',
             '',
             'parameters (-p NAME:=VALUE after --ros-args; config/balance_monitor.yaml):']
    for name, default, description, bounds in PARAMETERS:
        limits = f', {bounds[0]:g} to {bounds[1]:g}' if bounds else ''
        lines.append(f'  {name} (default {default!r}{limits}): {description}')
    return '\n'.join(lines)


def main(args=None):
    """
    Run the node until SIGINT or SIGTERM; returns the exit code.

    ``-h``/``--help`` print :func:`usage` and return 0 without starting ROS; an
    argument before ``--ros-args`` that is not one of those is bad input (2), as is a
    bad parameter.
    """
    argv = list(sys.argv if args is None else args)
    own = argv[1:argv.index('--ros-args')] if '--ros-args' in argv else argv[1:]
    if '-h' in argv[1:] or '--help' in argv[1:]:      # also after --ros-args
        print(usage())
        return 0
    if own:
        print(f'balance_monitor: error: unexpected argument {own[0]!r} (ROS arguments go '
              'after --ros-args; see --help)', file=sys.stderr)
        return 2
    try:
        rclpy.init(args=argv)
    except Exception as error:      # rclpy's UnknownROSArgsError, RCLError: bad ROS arguments
        print(f'balance_monitor: error: bad ROS arguments: {error} (see --help)',
              file=sys.stderr)
        return 2
    try:
        node = BalanceMonitor()
    except (ParameterException, ValueError) as error:   # ValueError: e.g. the rerun mode
        print(f'balance_monitor: error: {error}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin(node)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
