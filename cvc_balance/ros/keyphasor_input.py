"""
The node's tach: a once-per-revolution mark (keyphasor) instead of an encoder.

Parameter ``keyphasor_topic`` names it; its type is taken from its publishers, looked for
every 0.2 s until one appears (a subscription needs the type): std_msgs/Float64 is a
sampled tach signal, sensor_msgs/TimeReference one message a mark. Both are read as raw
CDR bytes.

* **Float64**: each sample is stamped with its receive time (the node's clock, as
  ``speed``'s); its marks are the crossings of the threshold (``keyphasor_edge``,
  ``keyphasor_threshold``: default midway between the signal's levels), found as the
  samples come
  (:class:`cvc_balance.physics.keyphasor.LiveSignal`) and checked looking back
  (:class:`~cvc_balance.physics.keyphasor.LiveMarks`). Each sample is a motion sample: the
  angle since the newest mark and the speed extrapolated along the constant-acceleration
  fit of the last 8 revolutions. Offline, replay interpolates between the marks on both
  sides; live can only extrapolate (what it costs: ``test/test_tach_live.py``).
* **TimeReference**: when a mark completes a revolution (or, a missed mark put back,
  several), that revolution is given as :data:`SAMPLES_PER_REV` motion samples, evenly in
  time, interpolated between its two marks (the cubic of
  :func:`~cvc_balance.physics.keyphasor.cubic`) as replay makes them: one revolution late,
  stamped from ``time_ref``.

Samples without an angle (the period being learnt, no mark for 3 periods) are rejected
with the reason. The marks' check is counted in the ``rotor balance`` status's values and
logged (once a second at most) when it repairs, drops or gives up on a mark.
"""

import struct
from time import monotonic, time_ns

import numpy as np
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64

from cvc_balance.messages import topics
from cvc_balance.messages.cdr import ENCAPSULATION_LE, read_time_reference
from cvc_balance.physics.keyphasor import (cubic, cubic_motion, LiveMarks, LiveSignal,
                                           marks_summary, SAMPLES_PER_REV)

KEYPHASOR_TYPES = {topics.FLOAT64_TYPE: Float64, topics.TIME_REFERENCE_TYPE: TimeReference}
DISCOVERY_PERIOD = 0.2
"""s between looks for the keyphasor topic's publishers (until one is found)."""
NANOSECONDS = 1_000_000_000


class KeyphasorInput:
    """The keyphasor of a node (see the module's description)."""

    def __init__(self, node, topic, edge, threshold, qos):
        """
        Look for ``topic``'s publishers (``node``'s callbacks take the samples).

        ``node`` has ``_process(sec, nanosec, angle, omega, received)`` and
        ``_reject(reason)``; ``threshold`` None: midway between the signal's levels.
        Raises ValueError for an edge or threshold that cannot be.
        """
        self.node, self.qos = node, qos
        self.topic = node.resolve_topic_name(topic)
        self.signal = LiveSignal(edge, threshold)
        self.threshold = threshold
        self.marks = LiveMarks()
        self.msg_type = None
        self.problem = ''
        self.origin_ns = None           # ns of the first sample (or mark): times are after it
        self._said = (0, 0, 0)          # (missed, doubled, irregular) last logged
        self._record = None
        self._subscription = None
        self._timer = node.create_timer(DISCOVERY_PERIOD, node._guarded(self.discover))
        self._system_time = not node.get_parameter('use_sim_time').value

    def discover(self):
        """Subscribe once the topic has a publisher of one keyphasor type; say any other."""
        kinds = {info.topic_type for info in self.node.get_publishers_info_by_topic(self.topic)}
        if not kinds:
            return
        known = kinds & set(KEYPHASOR_TYPES)
        if len(kinds) != 1 or not known:
            problem = (f'{self.topic} is published as {", ".join(sorted(kinds))}: a keyphasor '
                       f'is {topics.FLOAT64_TYPE} (a sampled tach) or '
                       f'{topics.TIME_REFERENCE_TYPE} (one message a mark), one of them')
            if problem != self.problem:
                self.problem = problem
                self.node.get_logger().error(f'keyphasor: {problem}')
            return
        self.subscribe(known.pop())

    def subscribe(self, msg_type):
        """Take the keyphasor as ``msg_type`` (Float64 or TimeReference) from now on."""
        self.node.destroy_timer(self._timer)
        self.msg_type, self.problem = msg_type, ''
        callback = self._on_float64 if msg_type == topics.FLOAT64_TYPE else \
            self._on_time_reference
        self._subscription = self.node.create_subscription(
            KEYPHASOR_TYPES[msg_type], self.topic, self.node._guarded(callback), self.qos,
            raw=True)
        recorder = getattr(self.node, '_recorder', None)
        if recorder is not None:
            self._record = recorder.add(self.topic, msg_type)
        said = ''
        if msg_type == topics.TIME_REFERENCE_TYPE and self.threshold is not None:
            said = ' (keyphasor_threshold applies to a sampled tach only: ignored)'
        self.node.get_logger().info(f'keyphasor {self.topic}: {msg_type}{said}')

    def values(self):
        """Return the diagnostics values of the keyphasor: its topic, type and marks' check."""
        marks = self.marks
        return {'keyphasor': f'{self.topic} ({self.msg_type or "waiting for a publisher"})',
                'keyphasor problem': self.problem,
                'keyphasor marks': marks.found,
                'keyphasor missed (put back)': marks.missed,
                'keyphasor doubled (dropped)': marks.doubled,
                'keyphasor irregular periods': marks.irregular,
                'keyphasor revolutions': marks.revolutions,
                'keyphasor period [s]': marks.period if marks.period is not None else ''}

    def summary(self):
        """Return the marks' check as one line (as replay says it)."""
        m = self.marks
        return marks_summary(self.topic, m.found, m.missed, m.doubled, m.irregular,
                             m.revolutions)

    # -- samples ---------------------------------------------------------------------

    def _on_float64(self, data):
        # The node's clock: system time unless use_sim_time (time_ns: 0.1 us, not 2.7).
        now = time_ns() if self._system_time else self.node.get_clock().now().nanoseconds
        if self._record is not None:
            self._record(now, data)
        self.float64(data, now, monotonic())

    def _on_time_reference(self, data):
        if self._record is not None:
            self._record(self.node.get_clock().now().nanoseconds, data)
        self.time_reference(data, monotonic())

    def float64(self, data, stamp_ns, received):
        """Take a sampled tach's CDR bytes received at ``stamp_ns`` (its stamp, ns)."""
        if len(data) < 12 or data[:4] != ENCAPSULATION_LE:
            self.node._reject(f'{self.topic} message not readable as Float64')
            return
        (value,) = struct.unpack_from('<d', data, 4)
        if self.origin_ns is None:
            self.origin_ns = stamp_ns
        time = (stamp_ns - self.origin_ns) * 1e-9
        mark = self.signal.sample(time, value)
        if mark is not None:
            self.marks.mark(mark, self.signal.spacing)
            self._say()
        motion = self.marks.motion_at(time)
        if isinstance(motion, str):
            self._say()
            self.node._reject(motion)
            return
        sec, nanosec = divmod(stamp_ns, NANOSECONDS)
        self.node._process(sec, nanosec, motion[0], motion[1], received)

    def time_reference(self, data, received):
        """Take a TimeReference's CDR bytes: a mark; give the revolutions it completes."""
        try:
            sec, nanosec = read_time_reference(data)
        except (ValueError, struct.error) as error:
            self.node._reject(f'{self.topic} message not readable as TimeReference: {error}')
            return
        mark_ns = sec * NANOSECONDS + nanosec
        if self.origin_ns is None:
            self.origin_ns = mark_ns
        time = (mark_ns - self.origin_ns) * 1e-9
        done = self.marks.mark(time)
        self._say()
        if done is None:
            self.node._reject(f'{self.topic}: mark at {mark_ns * 1e-9:.9f} s not after the '
                              'previous')
            return
        share = np.arange(SAMPLES_PER_REV) / SAMPLES_PER_REV
        for start, end, start_speed, end_speed in done:
            length = end - start
            times = start + share * length
            angle, omega, _ = cubic_motion(share, cubic(length, start_speed, end_speed),
                                           1.0 / length)
            stamps = self.origin_ns + np.rint(times * 1e9).astype(np.int64)
            # As if each sample had come as long after its time as the mark did.
            late = received - (time - times)
            for stamp, q, w, at in zip(stamps.tolist(), angle.tolist(), omega.tolist(),
                                       late.tolist()):
                sec, nanosec = divmod(stamp, NANOSECONDS)
                self.node._process(sec, nanosec, q, w, at)

    def _say(self):
        """Log the marks' check when it repaired, dropped or gave up on a mark since."""
        m = self.marks
        counts = (m.missed, m.doubled, m.irregular)
        if counts != self._said:
            self._said = counts
            self.node._log_throttled('keyphasor', 'warning', self.summary())
