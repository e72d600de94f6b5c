"""
ROS 2 node ``balance_monitor``: live bearing loads, drive torque and unbalance.

A thin adapter: it turns ``joint_states`` (or ``speed``, or a tach:
:mod:`cvc_balance.ros.keyphasor_input`) samples and the ``layout`` into engine calls
and publishes the results from the input callback, with no timer in between. The
per-message path is plain Python floats (:func:`cvc_balance.physics.engine.sample_loads`),
O(1) in the number of components; layout aggregates are computed once per layout.

Topics: :data:`TOPICS` (what ``--help`` lists). The motion and cell inputs are read as
raw CDR bytes (:mod:`cvc_balance.messages.cdr`): rclpy's message objects cost 15-20 us
each, and a load-cell flood cost motion samples. Stamps go through a
:class:`~cvc_balance.physics.motion.StampGate` on the monotonic receive clock. Layouts
are parsed on a worker thread, one at a time; of those that come meanwhile the newest
waits, the others are dropped (logged). ``/diagnostics`` every period and at
each layout change: the verdict of record first (one definition,
:func:`cvc_balance.identify.evidence.verdict_of_record`: the ISO 21940-11 verdict of the
rotor the load cells measure once they can tell, else the layout's, labelled; a rotor
that is not what its layout says is a WARN at least), what the layout expects, the
layout's plausibility warnings, the node's counts; STALE when no motion sample came for
``stale_after`` seconds (naming the resolved topics); the load cells' measurement; the
input checks (:mod:`cvc_balance.ros.input_checks`: units, senses, the cells' supports);
the bearings' life used, where the layout describes them (:mod:`cvc_balance.ros.bearing_life`:
since start and, when the node records, in all, from a state file beside the recording).
Statuses are named after the node's fully qualified name, ``hardware_id`` is
``machine_id``. Changes of the level are logged once each (WARN and STALE as warnings,
ERROR as an error, back to OK as info).
"""

from concurrent.futures import ThreadPoolExecutor
import math
import struct
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

from cvc_balance.identify.evidence import RESIDUAL_WARN, verdict_of_record
from cvc_balance.identify.mistakes import static_loads
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import (ENCAPSULATION_LE, joint_state_names, JointStateReader,
                                      string_message, WrenchStampedEncoder)
from cvc_balance.physics import assessment, limits
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.frames import degrees_360, g_mm, g_mm2, ROTOR_FRAME, STATOR_FRAME
from cvc_balance.physics.layout import LayoutError, one_line
from cvc_balance.physics.layout_file import (collector_paused, layout_from_text,
                                             MAX_TEXT_BYTES)
from cvc_balance.physics.motion import (AccelerationEstimator, AngleIntegrator,
                                        MAX_STAMP_JUMP, sample_problem, stamp_problem,
                                        stamp_seconds, StampGate)
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance, unbalance_wrench
from cvc_balance.ros.bearing_life import BearingLife, state_path
from cvc_balance.ros.executor import init, spin
from cvc_balance.ros.input_checks import InputChecks
from cvc_balance.ros.keyphasor_input import KeyphasorInput
from cvc_balance.ros.load_cells import LoadCells
from cvc_balance.ros.qos import input_qos, LAYOUT_QOS, OUTPUT_QOS
from cvc_balance.ros.recorder import BagRecorder

THROTTLE_S = 1.0
STATUS_CHARACTERS = 560
"""A status message longer than this is cut (the values hold every part in full)."""
LEVELS = {assessment.OK: DiagnosticStatus.OK, assessment.NOT_JUDGED: DiagnosticStatus.OK,
          assessment.WARN: DiagnosticStatus.WARN, assessment.ERROR: DiagnosticStatus.ERROR}
LEVEL_NAMES = {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
               DiagnosticStatus.ERROR: 'ERROR', DiagnosticStatus.STALE: 'STALE'}


PARAMETERS = (
    # name, default, description, (min, max) for numbers
    ('joint_name', 'gantry_joint', 'JointState joint whose position (rad) and velocity '
     '(rad/s) are the rotor angle q and speed omega', None),
    ('keyphasor_topic', '', 'a once-per-revolution tach instead of an encoder: '
     'std_msgs/Float64 (a sampled tach signal, each sample at its receive time) or '
     'sensor_msgs/TimeReference (one message a mark, time_ref its time), the type taken '
     'from its publishers; the angle is 0 at each mark, missed and doubled marks are '
     'repaired or dropped and counted; empty: off', None),
    ('keyphasor_edge', 'rising', "the crossing of a sampled tach's threshold that is the "
     'mark: rising or falling', None),
    ('keyphasor_threshold', math.nan, "a sampled tach's threshold, in its unit; nan: "
     "midway between the signal's low and high levels (learnt from its first 256 samples, "
     'then its last 4096)', None),
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
    ('max_stamp_jump', MAX_STAMP_JUMP, 'a motion sample whose stamp runs more than this (s) '
     'ahead of the receive clock (since the previous sample, or against the time line) is '
     'rejected; after this long without an accepted sample, a new time line is followed '
     'when two samples agree', (1e-3, 1e6)),
    ('identify_window_revs', 10, 'revolutions over which the load cells fit the measured '
     'unbalance (supports/<name>/measured_load)', (1, 100000)),
    ('residual_warn', RESIDUAL_WARN, 'WARN when a plane\'s residual (measured - layout) '
     'exceeds this '
     'fraction of its permissible unbalance (and its 95 % radius)', (0.01, 100.0)),
    ('diagnostics_period', 1.0, 'period (s) of /diagnostics', (0.01, 60.0)),
    ('stale_after', 2.0, '/diagnostics says STALE when no motion sample was accepted for '
     'this long (s)', (0.01, 3600.0)),
    ('input_depth', 1000, 'history depth of the best-effort joint_states, speed and load cell '
     'subscriptions', (1, 10000)),
    ('record_path', '', 'record inputs, outputs and diagnostics to this MCAP bag; empty: '
     'no recording', None),
    ('machine_id', '', 'the machine monitored (serial number, asset tag): the hardware_id '
     'of the /diagnostics statuses, and written into the recording (MCAP metadata, '
     "metadata.yaml custom_data) for cvc-balance fleet; empty: none (hardware_id: the node's "
     'name)', None),
    ('record_run', '', 'what run of a field-balancing visit the recording is (baseline, '
     'trial, check or trim), written into it for cvc-balance calibrate; empty: unlabelled',
     None),
    ('record_trial', '', 'with record_run trial: the trial weight on the rotor, '
     'PLANE:MASS_KG@ANGLE_DEG,RADIUS_M (e.g. I:0.2@0,0.68)', None),
    ('rerun', '', 'rerun view of the run: save (to rerun_target, an .rrd), connect (to the '
     'viewer at rerun_target) or spawn (a viewer); empty: off', None),
    ('rerun_target', '', '.rrd path (save) or viewer URL (connect)', None),
    ('rerun_every', 20, 'log every n-th sample to rerun (the viewer need not draw 1 kHz)',
     (1, 100000)),
)


TOPICS = (
    # name (relative: namespaces and remapping apply), type, in/out, what it carries
    (topics.JOINT_STATES, topics.JOINT_STATE_TYPE, 'in', 'best effort: the joint joint_name, '
     "position = rotor angle q (rad), velocity = omega (rad/s); the header stamp is the "
     "sample's time"),
    (topics.SPEED, topics.FLOAT64_TYPE, 'in', 'best effort: omega (rad/s) when no joint_states '
     'come; q is integrated over the receive times'),
    ('<keyphasor_topic>', topics.FLOAT64_TYPE, 'in', 'best effort, when keyphasor_topic is '
     'set: a sampled tach signal; each sample is a motion sample, the angle since the last '
     'mark and the speed extrapolated along the last 8 revolutions'),
    ('<keyphasor_topic>', topics.TIME_REFERENCE_TYPE, 'in', 'or one message a mark '
     '(time_ref): each revolution is given as 64 motion samples interpolated between its '
     'marks, one revolution late'),
    (topics.LAYOUT, topics.STRING_TYPE, 'in', 'reliable, transient local: the layout (YAML or '
     'JSON); one is parsed at a time and of those that come meanwhile the newest wins'),
    (topics.measured_load('<name>'), topics.WRENCH_TYPE, 'in', 'best effort: a load cell under '
     "support <name> (stator frame, N; a single support's tilting moment, N m)"),
    (topics.BEARING_LOAD, topics.WRENCH_TYPE, 'out', 'the load on the stator (stator frame, N '
     "and N m about O); stamp: the motion sample's"),
    (topics.support_load('<name>'), topics.WRENCH_TYPE, 'out', "each support's load (stator "
     'frame)'),
    (topics.UNBALANCE, topics.WRENCH_TYPE, 'out', "the layout's unbalance (rotor frame: force "
     'U omega^2, torque the couple moment)'),
    (topics.DRIVE_TORQUE, topics.WRENCH_TYPE, 'out', 'the drive torque (rotor frame, torque.z)'),
    (topics.IDENTIFIED_UNBALANCE, topics.WRENCH_TYPE, 'out', 'the unbalance the load cells '
     'measure, at each revolution (as unbalance)'),
    (topics.UNBALANCE_RESIDUAL, topics.WRENCH_TYPE, 'out', 'measured - layout unbalance, at '
     'each revolution'),
    (topics.DIAGNOSTICS, topics.DIAGNOSTIC_ARRAY_TYPE, 'out', 'every diagnostics_period: the '
     "verdict of record, the load cells' measurement, the input checks, the bearings' life "
     "used (where the layout's supports describe their bearing; kept across restarts in "
     'bearing_life_<machine>.json beside record_path when the node records)'),
)
"""The node's topics: what --help lists, and what the node subscribes and publishes."""


class PreparedLayout:
    """
    A layout parsed and aggregated, ready to be put in force: all its costly work, done once.

    Made on the node's layout worker thread (:func:`prepare_layout`), so that parsing and
    aggregating 10^6 components does not hold up the input callbacks.
    """

    def __init__(self, text, source):
        """Parse ``text`` (YAML/JSON) and aggregate it; raises LayoutError."""
        self.text, self.source = text, source
        with collector_paused():         # 10^6 components: objects made, none garbage
            self.layout = layout_from_text(text, source=source)
            self.model = RotorModel.from_layout(self.layout)
            self.digest = self.layout.digest()
            self.static = static_unbalance(self.model)
            self.couple = couple_unbalance(self.model)
            self.warnings = layout_warnings(self.layout)
            self.shares = static_loads(self.model)


def prepare_layout(text, source):
    """Return a PreparedLayout, or the one-line reason it cannot be used (any failure)."""
    try:
        return PreparedLayout(text, source)
    except LayoutError as error:
        return str(error)
    except Exception as error:     # a bug must not take the node down: the layout is refused
        return f'{source}: {type(error).__name__}: {one_line(error)}'


def recording_label(kind, trial):
    """
    Return the RunLabel of the record_run and record_trial parameters (None: unlabelled).

    ValueError names the parameter that is wrong (the node then refuses to start).
    """
    from cvc_balance.bag.run_label import run_label
    try:
        if not kind:
            if trial:
                raise ValueError('--trial goes with --run trial (say what run this is)')
            return None
        return run_label(kind, trial or None)
    except ValueError as error:
        said = str(error).replace('--run', 'record_run').replace('--trial', 'record_trial')
        raise ValueError(f'parameters record_run/record_trial: {said}') from None


class ActiveLayout:
    """A layout in force: its prepared values and the per-support publishers and cells."""

    def __init__(self, prepared, node):
        """Make the per-support publishers and the load cells' subscriptions."""
        self.text, self.source, self.layout = prepared.text, prepared.source, prepared.layout
        self.model, self.digest, self.warnings = prepared.model, prepared.digest, \
            prepared.warnings
        self.static, self.couple, self.shares = prepared.static, prepared.couple, \
            prepared.shares
        self.supports = tuple(
            (s.name, node.publisher(topics.support_load(s.name)))
            for s in self.layout.supports)
        self.cells = LoadCells(node, self.model, node.params['identify_window_revs'],
                               input_qos(node.params['input_depth']), node.emit_rotor)


class BalanceMonitor(Node):
    """Wires joint_states / speed / layout to the engine and the outputs to topics."""

    def __init__(self, **kwargs):
        """Declare parameters, topics and the diagnostics timer; load layout_file if set."""
        super().__init__('balance_monitor', **kwargs)
        self.params = self._declare_parameters()
        # The machine monitored, else this node: what aggregators group the statuses by.
        self._hardware_id = self.params['machine_id'] or self.get_fully_qualified_name()
        # Where the inputs are looked for, after namespace and remapping: said in refusals.
        self._resolved = {name: self.resolve_topic_name(name)
                          for name in (topics.JOINT_STATES, topics.SPEED, topics.LAYOUT)}
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
        self._layouts_dropped = 0       # layouts not parsed: a newer one came meanwhile
        self._period_accepted = 0
        self._period_start = monotonic()
        self._started = self._period_start
        self._last_input = None     # monotonic s of the last accepted motion sample
        self._top_speed = 0.0       # top |omega| accepted under the layout in force
        self._reported_level = None
        self._peak_load = 0.0
        self._last_rejection = ''
        self._last_logged = {}          # throttled log messages: key -> monotonic time
        self._period_rejected = 0
        self._internal_errors = 0
        self._reported_measured = None
        self._layout_error = ''
        self._gate = StampGate(self.params['max_stamp_jump'])
        self._joints = JointStateReader(self.params['joint_name'])
        self._checks = InputChecks()
        self._keyphasor = None          # the tach, when keyphasor_topic is set
        # Layouts are parsed and aggregated on their own thread, one at a time, and put in
        # force here; of those that come meanwhile only the newest waits (it wins).
        self._layout_worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='layout')
        self._preparing = None          # the future of the layout being prepared
        self._waiting = None            # the newest layout text come meanwhile
        self._layout_poll = None
        self._rerun = None
        if self.params['rerun']:
            from cvc_balance.view.rerun_log import open_recording, RunLogger
            self._rerun = RunLogger(open_recording(self.params['rerun'],
                                                   self.params['rerun_target'],
                                                   name=self.get_fully_qualified_name()),
                                    every=self.params['rerun_every'])
        self._recorder = None
        self._record = {}
        # The bearings' life: kept across restarts beside the recording, when it records.
        self._life = BearingLife(state_path(self.params['record_path'], self._hardware_id)
                                 if self.params['record_path'] else None, self._log_at)
        self._life_counting = None      # the LifeCounters of the layout in force, if any
        label = recording_label(self.params['record_run'], self.params['record_trial'])
        if self.params['record_path']:
            # Inputs and diagnostics through raw subscriptions; the outputs are written as
            # they are published (no second trip through DDS).
            self._recorder = BagRecorder(self, self.params['record_path'],
                                         (topics.JOINT_STATES, topics.SPEED, topics.LAYOUT,
                                          topics.measured_load('*'), topics.DIAGNOSTICS),
                                         machine_id=self.params['machine_id'] or None,
                                         label=label)
            for topic in topics.OUTPUTS:
                self._record[topic] = self._recorder.add(topic, topics.WRENCH_TYPE)
        elif label is not None:
            raise ValueError('record_run and record_trial label a recording: set record_path')
        if self.params['layout_file']:
            self._apply_layout_file(self.params['layout_file'])
        sensor_qos = input_qos(self.params['input_depth'])
        # Raw: the node reads the CDR bytes itself (1.5 us, against rclpy's 15 us to make
        # a JointState).
        self.create_subscription(JointState, topics.JOINT_STATES,
                                 self._guarded(self._on_joint_states), sensor_qos, raw=True)
        self.create_subscription(Float64, topics.SPEED, self._guarded(self._on_speed), sensor_qos,
                                 raw=True)
        self.create_subscription(String, topics.LAYOUT, self._guarded(self._on_layout),
                                 LAYOUT_QOS)
        if self.params['keyphasor_topic']:
            threshold = self.params['keyphasor_threshold']
            self._keyphasor = KeyphasorInput(
                self, self.params['keyphasor_topic'], self.params['keyphasor_edge'],
                None if math.isnan(threshold) else threshold, sensor_qos)
        self.create_timer(self.params['diagnostics_period'],
                          self._guarded(self._publish_diagnostics))

    def destroy_node(self):
        """Finalise the recording, if any, then destroy the node."""
        # print: rosout is gone once a signal has shut the context down.
        print('balance_monitor: motion samples: ' + ', '.join(
            f'{count} {name}' for name, count in self._counts.items()), flush=True)
        if getattr(self, '_keyphasor', None) is not None:
            print(f'balance_monitor: {self._keyphasor.summary()}', flush=True)
        if self._active is not None and any(self._active.cells.readings.values()):
            cells = self._active.cells
            print('balance_monitor: load cell readings (layout in force): ' + ', '.join(
                f'{count} {name}' for name, count in cells.readings.items()) +
                f', {cells.fit.dropped} dropped', flush=True)
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        self._life.save()
        if self._rerun is not None:
            self._rerun.finish()
            self._rerun = None
        self._layout_worker.shutdown(wait=False, cancel_futures=True)
        return super().destroy_node()

    def lost_message(self, error):
        """Count a message rclpy could not hand over (the spin loop's ``on_error``)."""
        self._internal_errors += 1
        self._last_rejection = f'a message rclpy could not convert: {one_line(error, 200)}'
        self._log_throttled('lost', 'error', self._last_rejection)

    def _guarded(self, callback):
        """
        Wrap a callback so that no failure escapes it: the node must never die of an input.

        Layouts and messages are checked where they come in; this is for a bug that the
        checks missed: counted, logged (once a second) and shown in the diagnostics.
        """
        def guarded(*args):
            try:
                callback(*args)
            except Exception as error:      # any: the previous good state stays in force
                self._internal_errors += 1
                self._last_rejection = (f'internal error in {callback.__name__}: '
                                        f'{type(error).__name__}: {one_line(error, 200)}')
                self._log_throttled('internal', 'error', self._last_rejection)
        return guarded

    def emit_rotor(self, topic, sec, nanosec, force, torque):
        """Publish (and record) a rotor-frame wrench on ``topic``, made by the node."""
        data = self._rotor_cdr.encode(sec, nanosec, force, torque)
        self.publisher(topic).publish(data)
        if self._recorder is not None:
            if topic not in self._record:
                self._record[topic] = self._recorder.add(topic, topics.WRENCH_TYPE)
            self._record[topic](self.get_clock().now().nanoseconds, data)

    def publisher(self, topic):
        """Return the WrenchStamped publisher of ``topic``, made on first use."""
        publishers = self._wrench_publishers
        if topic not in publishers:
            publishers[topic] = self.create_publisher(WrenchStamped, topic, OUTPUT_QOS)
        return publishers[topic]

    # -- inputs ----------------------------------------------------------------------

    def _on_joint_states(self, data):
        """Take a JointState's CDR bytes: the sample of joint_name, or a rejection."""
        try:
            sample = self._joints.read(data)
        except (ValueError, struct.error, UnicodeDecodeError) as error:
            self._reject(f'joint_states message not readable as JointState: '
                         f'{one_line(error, 100)}')
            return
        if sample is None:
            self._reject(self._without_joint(data))
            return
        if self._process(*sample):
            self._checks.sample(self._last_time, sample[2], sample[3])

    def _without_joint(self, data):
        """Say what a JointState without a usable joint_name sample has instead."""
        joint, topic = self.params['joint_name'], self._resolved[topics.JOINT_STATES]
        names = joint_state_names(data)[0]
        if joint in names:
            return f"{topic}: joint '{joint}' has no position or velocity"
        shown = one_line(', '.join(repr(name) for name in names), 60) or 'no joint'
        return f"{topic} without joint '{joint}' (it names {shown}): set joint_name"

    def _motion_topics(self):
        """Name where motion samples are awaited, and where JointState is, if not there."""
        joint, speed = self._resolved[topics.JOINT_STATES], self._resolved[topics.SPEED]
        text = f'{joint} or {speed}'
        if self._keyphasor is not None:
            text = f'{joint}, {speed} or the keyphasor {self._keyphasor.topic}'
            if self.count_publishers(self._keyphasor.topic):
                return text
        if self.count_publishers(joint) or self.count_publishers(speed):
            return text
        elsewhere = sorted(name for name, types in self.get_topic_names_and_types()
                           if topics.JOINT_STATE_TYPE in types and name != joint)
        text += ', where nothing publishes'
        if elsewhere:
            text += (f"; JointState is published on {', '.join(elsewhere[:3])}: remap with "
                     f'-r {topics.JOINT_STATES}:={elsewhere[0]}')
        return text

    def _on_speed(self, data):
        """Take a Float64's CDR bytes: omega, rad/s, stamped with the receive time."""
        if len(data) < 12 or data[:4] != ENCAPSULATION_LE:
            self._reject('speed message not readable as Float64')
            return
        (omega,) = struct.unpack_from('<d', data, 4)
        sec, nanosec = divmod(self.get_clock().now().nanoseconds, 1_000_000_000)
        time = stamp_seconds(sec, nanosec)
        problem = sample_problem(time, None, 0.0, omega, self.params['max_speed'])
        if problem:
            self._reject(f'speed: {problem}')
            return
        self._process(sec, nanosec, self._integrator.update(time, omega), omega)

    def _process(self, sec, nanosec, angle, omega, received=None):
        """
        Compute and publish the outputs of one motion sample; return whether it was used.

        ``received``: the sample's monotonic receive time (s; default now).
        """
        if self._preparing is not None:
            self._take_prepared()       # a new layout takes effect between two samples
        active = self._active
        if active is None:
            self._counts['dropped'] += 1
            self._log_throttled('dropped', 'warning', 'no layout yet: motion samples dropped')
            return False
        time = stamp_seconds(sec, nanosec)
        if received is None:
            received = monotonic()
        problem = stamp_problem(sec, nanosec) or \
            sample_problem(time, None, angle, omega, self.params['max_speed']) or \
            self._gate.check(time, received)
        if problem:
            self._reject(f'motion sample: {problem}')
            return False
        if self._gate.restarted:         # a new time line: the old slope means nothing
            self._alpha.reset()
            self._checks.restart()
            self._life.restart()
            self.get_logger().warning(f'motion samples moved to a new time line at {time:.9f} '
                                      's (confirmed by two samples)')
        self._last_time = time
        alpha = self._alpha.update(time, omega)
        result = sample_loads(active.model, angle, omega, alpha)
        if self._life_counting is not None:
            self._life_counting.add_sample(time, angle, omega, result.supports)
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
        active.cells.motion(sec, nanosec, angle, omega, alpha)
        self._omega = omega
        speed = omega if omega >= 0.0 else -omega
        if speed > self._top_speed:
            self._top_speed = speed
        self._last_input = received
        self._counts['accepted'] += 1
        self._period_accepted += 1
        return True

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
        self._period_rejected += 1
        # Cut: the reason goes into the status headline, which must stay one readable line.
        self._last_rejection = reason if len(reason) <= 150 else one_line(reason, 150)
        self._log_throttled('rejected', 'warning', f'rejected {reason}')

    def _log_throttled(self, key, severity, message):
        """
        Log ``message`` at ``severity`` at most once every THROTTLE_S seconds per ``key``.

        Not rclpy's ``throttle_duration_sec``: that walks the caller's frames on every call,
        logged or not, and under the events executor the node's native memory grew with it
        (78 -> 88 MB in 30 s of 5 kHz rejected samples; flat with this clock check).
        """
        now = monotonic()
        if now - self._last_logged.get(key, -math.inf) >= THROTTLE_S:
            self._last_logged[key] = now
            self._log_at(severity, message)

    # -- layout ----------------------------------------------------------------------

    def _on_layout(self, msg):
        """Hand the layout text to the worker thread, or let it wait there (newest only)."""
        self.get_logger().info(f'layout received on the layout topic ({len(msg.data)} '
                               'characters): ' + ('parsing' if self._preparing is None else
                                                  'waits for the one being parsed'))
        if self._preparing is None:
            self._preparing = self._layout_worker.submit(prepare_layout, msg.data,
                                                         'layout topic')
        else:
            if self._waiting is not None:
                self._drop_waiting()
            self._waiting = msg.data
        if self._layout_poll is None:    # without samples flowing, a timer takes it
            self._layout_poll = self.create_timer(0.01, self._guarded(self._take_prepared))

    def _drop_waiting(self):
        self._layouts_dropped += 1
        self.get_logger().warning(
            f'layout dropped unparsed ({len(self._waiting)} characters from the layout '
            'topic): a newer one came while another was being parsed; the newest wins')

    def _take_prepared(self):
        """Put in force (or refuse) the layout prepared; start on the one waiting, if any."""
        if self._preparing is not None and self._preparing.done():
            prepared = self._preparing.result()
            self._preparing = None
            if isinstance(prepared, str):
                self._refuse_layout(prepared)
            else:
                self._apply(prepared)
            if self._waiting is not None:
                self._preparing = self._layout_worker.submit(prepare_layout, self._waiting,
                                                             'layout topic')
                self._waiting = None
        if self._preparing is None and self._layout_poll is not None:
            self.destroy_timer(self._layout_poll)
            self._layout_poll = None

    def _apply_layout_file(self, path):
        """Put the layout_file in force at start (before any sample: no need to wait)."""
        try:
            with open(path, 'rb') as stream:
                text = stream.read(MAX_TEXT_BYTES + 1).decode('utf-8', errors='replace')
        except OSError as error:
            self._refuse_layout(f'{path}: cannot read layout file: {error.strerror}')
            return
        prepared = prepare_layout(text, str(path))
        if isinstance(prepared, str):
            self._refuse_layout(prepared)
        else:
            self._apply(prepared)
            if self._recorder is not None:    # the bag carries the layout in force
                self._recorder.write(topics.LAYOUT, self.get_clock().now().nanoseconds,
                                     string_message(text))

    def _apply(self, prepared):
        source, layout = prepared.source, prepared.layout
        try:
            active = ActiveLayout(prepared, self)
        except Exception as error:  # e.g. rclpy refusing a topic or subscription
            self._refuse_layout(f'{source}: {type(error).__name__}: {one_line(error)}')
            return
        if self._active is not None:
            self._active.cells.close()
        self._life.layout(layout.supports)
        self._active = active  # one reference swap: takes effect between two samples
        self._life_counting = self._life.counting
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
        status = DiagnosticStatus(name=self._status_name('rotor balance'),
                                  hardware_id=self._hardware_id)
        values = {'accepted': self._counts['accepted'], 'rejected': self._counts['rejected'],
                  'dropped': self._counts['dropped'],
                  'input rate [Hz]': self._period_accepted / max(now - self._period_start, 1e-9),
                  'peak bearing load [N]': math.sqrt(self._peak_load),
                  'rejected in the last period': self._period_rejected,
                  'internal errors': self._internal_errors,
                  'last rejected input': self._last_rejection,
                  'last rejected layout': self._layout_error}
        if self._keyphasor is not None:
            values.update(self._keyphasor.values())
        period, rejected = now - self._period_start, self._period_rejected
        self._period_accepted, self._peak_load, self._period_start = 0, 0.0, now
        self._period_rejected = 0
        active = self._active
        statuses = [status]
        if active is None:
            level, message = DiagnosticStatus.WARN, 'no layout (waiting for one on ' \
                f'{self._resolved[topics.LAYOUT]}, or set layout_file)'
        else:
            level, message, balance, of_record = self._judge(active)
            values.update(balance)
            if rejected:        # the verdict stands, but the input is not all well
                level = max(level, DiagnosticStatus.WARN)
                message += (f'; {rejected} motion samples rejected in the last {period:.2g} s '
                            f'(last: {self._last_rejection})')
            statuses += self._measured_status(active, of_record)
            statuses.append(self._input_status(active))
            statuses += self._life_status()
            if self._rerun is not None and self._last_time is not None:
                self._rerun.evidence(int(self._last_time * 1e9), of_record)
            quiet = now - (self._last_input if self._last_input is not None else self._started)
            values['last motion sample [s ago]'] = quiet if self._last_input is not None else ''
            if quiet > self.params['stale_after']:
                waited = 'no motion sample yet' if self._last_input is None else \
                    f'no motion sample for {quiet:.1f} s'
                level, message = DiagnosticStatus.STALE, \
                    f"{waited} on {self._motion_topics()} (stale after " \
                    f"{self.params['stale_after']:g} s); {message}"
        if self._layout_error:
            # In full under 'last rejected layout'; the headline stays one readable line.
            message += f'; last layout rejected: {one_line(self._layout_error, 150)}'
        # One readable line: every part in full is in the values (STATUS_CHARACTERS).
        status.level, status.message = level, one_line(message, STATUS_CHARACTERS)
        status.values = [KeyValue(key=k, value=_text(v)) for k, v in values.items()]
        array = DiagnosticArray(status=statuses)
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics_pub.publish(array)
        self._log_transition(level, message)

    def _measured_status(self, active, of_record):
        """Return the load cells' status (a second DiagnosticStatus) once cells have read."""
        diagnosis = active.cells.diagnose(of_record)
        if diagnosis is None:
            return []
        level, message, values = diagnosis
        if level != self._reported_measured:    # a change of what the cells say: once
            self._reported_measured = level
            self._log_at({assessment.ERROR: 'error', assessment.WARN: 'warning'}.get(
                level, 'info'), f'load cells {level}: {message}')
        status = DiagnosticStatus(name=self._status_name('measured unbalance'),
                                  hardware_id=self._hardware_id,
                                  level=LEVELS[level], message=message)
        status.values = [KeyValue(key=k, value=_text(v)) for k, v in values.items()]
        return [status]

    def _life_status(self):
        """Return the bearings' life status (and save their count), if any bearing is described."""
        found = self._life.status(self._top_speed)
        self._life.save()
        if found is None:
            return []
        level, message, values = found
        status = DiagnosticStatus(name=self._status_name('bearing life'),
                                  hardware_id=self._hardware_id,
                                  level=LEVELS[level], message=message)
        status.values = [KeyValue(key=k, value=_text(v)) for k, v in values.items()]
        return [status]

    def _input_status(self, active):
        """Return the status of the inputs' own checks (units, senses, cells' supports)."""
        level, message, values = self._checks.status(active)
        values['layouts dropped unparsed'] = self._layouts_dropped
        for severity, text in self._checks.news():
            self._log_at(severity, text)
        status = DiagnosticStatus(name=self._status_name('input checks'),
                                  hardware_id=self._hardware_id,
                                  level=LEVELS[level], message=message)
        status.values = [KeyValue(key=k, value=_text(v)) for k, v in values.items()]
        return status

    def _status_name(self, what):
        """Name a diagnostic status after the node: '/gantry1/balance_monitor: what'."""
        return f'{self.get_fully_qualified_name()}: {what}'

    def _log_transition(self, level, message):
        """Log a change of the diagnostics level, once (not every period)."""
        if level == self._reported_level:
            return
        self._reported_level = level
        self._log_at('error' if level == DiagnosticStatus.ERROR else 'warning' if level in (
            DiagnosticStatus.WARN, DiagnosticStatus.STALE) else 'info',
            f'balance {LEVEL_NAMES.get(level, level)}: {message}')

    def _log_at(self, severity, text):
        """
        Log ``text`` at ``severity`` ('error', 'warning' or 'info').

        Every log call of varying severity goes through here, one call line per
        severity: rclpy's logger raises ValueError when one line of code logs at two
        severities ("Logger severity cannot be changed between calls"). That once cost
        the diagnostics of the period in which the load cells' verdict went from WARN to
        ERROR (found by test_fuzz), and made the guard itself raise on the first internal
        error after a rejected sample (the throttled log was one line for both).
        """
        logger = self.get_logger()
        if severity == 'error':
            logger.error(text)
        elif severity == 'warning':
            logger.warning(text)
        else:
            logger.info(text)

    def _judge(self, active):
        """
        Diagnostics level, message and values of the layout in force, and its verdict of record.

        The verdict of record (:func:`cvc_balance.identify.evidence.verdict_of_record`) is the
        measured rotor's once the load cells can tell, else the layout's, labelled; the
        layout's assessment follows in the values as what the layout expects.
        """
        layout = active.layout
        grade = self.params['balance_grade'] or layout.balancing.grade
        of_record = verdict_of_record(active.model, active.cells.estimate, self._top_speed,
                                      grade, self.params['warn_fraction'],
                                      self.params['residual_warn'])
        verdict = of_record.layout
        values = {'layout': layout.name, 'layout digest': active.digest,
                  'speed [rad/s]': abs(self._omega), 'top speed seen [rad/s]': self._top_speed,
                  'grade [mm/s]': grade, 'verdict level': of_record.level,
                  'verdict': of_record.statement,
                  'verdict source': of_record.source,
                  **{f'not as the layout says: {d.plane}': d.describe()
                     for d in of_record.disagreements},
                  'what would explain it': of_record.explanation or '',
                  'achieved grade [mm/s]': of_record.equivalent_grade
                  if of_record.equivalent_grade is not None else '',
                  'layout verdict level': verdict.level, 'layout verdict': verdict.text}
        judged = verdict.assessment
        if judged is not None:
            values.update({'judged at [rad/s]': judged.omega,
                           'judged at': verdict.speed_source,
                           'layout achieved grade [mm/s]': judged.equivalent_grade,
                           'static unbalance [g mm]': g_mm(judged.static_amount),
                           'static unbalance angle [deg]': degrees_360(judged.static_angle),
                           'couple unbalance [g mm^2]': g_mm2(judged.couple_amount),
                           'couple unbalance angle [deg]': degrees_360(judged.couple_angle),
                           'permissible [g mm]': g_mm(judged.permissible)})
            for label, plane, allowed, fraction in zip(('I', 'II'), judged.planes,
                                                       judged.plane_permissible,
                                                       judged.fractions):
                values.update({f'plane {label} z [m]': plane.z,
                               f'plane {label} unbalance [g mm]': g_mm(plane.amount),
                               f'plane {label} angle [deg]': degrees_360(plane.angle),
                               f'plane {label} permissible [g mm]': g_mm(allowed),
                               f'plane {label} unbalance / permissible': fraction,
                               f'plane {label} correction mass [g]':
                                   'none (no correction radius)' if plane.correction_mass is None
                                   else plane.correction_mass * 1e3,
                               f'plane {label} correction angle [deg]':
                                   degrees_360(plane.correction_angle)})
        level, message = LEVELS[of_record.level], of_record.text
        if of_record.source == 'measured':
            message += f'; {of_record.layout_text}'
        values['layout warnings'] = ' | '.join(active.warnings)
        if active.warnings:
            message += f'; layout implausible? {len(active.warnings)} warning(s): ' \
                f'{active.warnings[0]}'
            level = max(level, DiagnosticStatus.WARN)
        return level, message, values, of_record

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
            if name == 'balance_grade' and values[name] != 0.0:
                # 0: the layout's; else a grade as a layout's (a 1e-300 grade divides to inf).
                limits.check(values[name], limits.GRADE, 'parameter balance_grade')
            if name == 'keyphasor_edge' and values[name] not in ('rising', 'falling'):
                raise ValueError(f'parameter keyphasor_edge must be rising or falling, got '
                                 f'{values[name]!r}')
            if name in ('joint_name', 'stator_frame', 'rotor_frame') and \
                    not (isinstance(values[name], str) and values[name].strip()):
                raise ValueError(f'parameter {name} must be a non-empty string, got '
                                 f'{values[name]!r}')
        return values


def _text(value):
    return f'{value:.6g}' if isinstance(value, float) else str(value)


def usage():
    """Return the node's --help: what it does, its topics and parameters (their declarations)."""
    lines = ['usage: balance-monitor [-h] [--ros-args [-p NAME:=VALUE] [--params-file FILE] '
             '[-r FROM:=TO] ...]',
             '',
             'ROS 2 node balance_monitor: bearing loads, drive torque and unbalance of a rotor',
             'from its encoder (joint_states or speed) or tach (keyphasor_topic) and its',
             'component layout, with the ISO 21940-11 verdict on /diagnostics. Runs until',
             'SIGINT or SIGTERM. Topic names are relative: -r __ns:=/gantry1 puts them under',
             '/gantry1, -r joint_states:=/x remaps one. <name>: each support of the layout in',
             'force.',
             '']
    for direction, heading in (('in', 'inputs'), ('out', 'outputs')):
        lines.append(f'{heading}:')
        for name, kind, way, description in TOPICS:
            if way == direction:
                lines.append(f'  {name} ({kind}): {description}')
    lines += ['', 'parameters (-p NAME:=VALUE after --ros-args, or --params-file FILE: '
              'config/balance_monitor.yaml, keyed /** for any name and namespace):']
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
        init(args=argv)
    except Exception as error:      # rclpy's UnknownROSArgsError, RCLError: bad ROS arguments
        print(f'balance_monitor: error: bad ROS arguments: {error} (see --help)',
              file=sys.stderr)
        return 2
    # The layout thread runs Python for seconds on a big layout: hand the GIL back to the
    # input callbacks every 0.5 ms instead of 5 ms, so their queue does not overflow.
    sys.setswitchinterval(0.0005)
    try:
        node = BalanceMonitor()
    # ValueError: e.g. the rerun mode, an empty joint_name; OSError: record_path's folder.
    except (ParameterException, ValueError, OSError) as error:
        print(f'balance_monitor: error: {error}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin(node, on_error=node.lost_message)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
