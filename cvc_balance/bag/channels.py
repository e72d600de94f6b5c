"""
A rotor's own sensors in a bag: a keyphasor (tach) and vibration channels. No rclpy.

**Keyphasor** (one mark a revolution; :mod:`cvc_balance.physics.keyphasor` makes the angle
and speed of it): a std_msgs/Float64 topic is a sampled tach signal, each sample at its log
time, its marks at the crossings of a threshold; a sensor_msgs/TimeReference topic is one
message per mark, ``time_ref`` the mark's time. By default the topic ``keyphasor`` (at the
root or under one namespace); ``--keyphasor TOPIC`` names another.

**Vibration channels**: every std_msgs/Float64 topic (but the keyphasor, and any topic
named ``keyphasor`` or ``speed``) is
one channel named by its topic, at its log times; geometry_msgs/Vector3Stamped (``x``,
``y``, ``z``) and sensor_msgs/Imu (its linear acceleration) three, ``TOPIC/x`` ...,
at their header stamps. Units are as the user names them per topic (``--channel-unit
TOPIC=m/s^2``; raw counts are a unit too); an Imu's is m/s^2 by its message definition,
the others' ``as recorded`` unless named.

Messages are decoded as :mod:`cvc_balance.bag.mcap_reader` decodes its own: every message
of a chunk at once with numpy, each field at its place after the header's frame_id (CDR,
little endian, alignment counted from the end of the encapsulation header). A message
that is too short or not little-endian CDR is left out and counted.
"""

from dataclasses import dataclass, field

import numpy as np

from cvc_balance.bag.mcap_reader import (BagError, column, describe_topics, float64_samples,
                                         gather, MESSAGE_HEADER, MotionSamples)
from cvc_balance.messages import topics
from cvc_balance.physics.frames import wrap_angle
from cvc_balance.physics.keyphasor import (checked_marks, EDGES, marks_summary,
                                           SAMPLES_PER_REV, signal_marks)

FLOAT64, VECTOR3_STAMPED = topics.FLOAT64_TYPE, topics.VECTOR3_STAMPED_TYPE
IMU, TIME_REFERENCE = topics.IMU_TYPE, topics.TIME_REFERENCE_TYPE
KEYPHASOR_TYPES = (FLOAT64, TIME_REFERENCE)
AS_RECORDED = 'as recorded'
"""The unit of a channel whose unit was not named."""
DEFAULT_UNITS = {IMU: 'm/s^2'}
"""Units fixed by a message's definition (sensor_msgs/Imu: REP-145, m/s^2)."""
AXES = ('x', 'y', 'z')
IMU_LINEAR_ACCELERATION = 200
"""Bytes after an Imu's header (8-aligned) to linear_acceleration: orientation (4 float64),
its covariance (9), angular_velocity (3) and its covariance (9)."""
CDR_LE = 0x0100
"""The encapsulation header's first two bytes (00 01: CDR, little endian) read as <u2."""


@dataclass(frozen=True)
class ChannelSource:
    """
    A vibration channel of a bag.

    ``name`` (topic, without its leading '/', and the axis), ``unit``, the bag
    ``channel`` and ``axis`` (0-2, None for a Float64).
    """

    name: str
    unit: str
    channel: object
    axis: int = None


@dataclass
class Samples:
    """A channel's samples: ``time`` ns (int64, increasing) and ``values``; ``rejected``."""

    time: np.ndarray
    values: np.ndarray
    rejected: int = 0


@dataclass
class Keyphasor:
    """
    A bag's keyphasor.

    Its bag ``channel``, checked ``marks`` (times s after ``origin_ns``), for a sampled
    tach its samples' ``time_ns`` (log times), and ``problems``.
    """

    channel: object
    origin_ns: int
    marks: object
    time_ns: np.ndarray = None
    problems: list = field(default_factory=list)

    def seconds(self, time_ns):
        """Return ``time_ns`` (ns since the epoch) as s after this keyphasor's origin."""
        return (np.asarray(time_ns, np.int64) - self.origin_ns) * 1e-9

    def summary(self):
        """Return one line saying what the marks' check found."""
        m = self.marks
        return marks_summary(self.channel.topic, m.found, m.missed, m.doubled, m.irregular,
                             m.revolutions)


def parse_units(pairs):
    """Return {topic without leading '/': unit} of ``TOPIC=UNIT`` strings; ValueError if bad."""
    units = {}
    for pair in pairs or ():
        topic, sep, unit = pair.partition('=')
        topic, unit = topic.strip().strip('/'), unit.strip()
        if not sep or not topic or not unit or not unit.isprintable() or len(unit) > 40:
            raise ValueError(f'--channel-unit {pair!r}: give TOPIC=UNIT, e.g. accel=m/s^2 '
                             '(a unit of 1-40 printable characters)')
        if topic in units and units[topic] != unit:
            raise ValueError(f'--channel-unit: {topic} given two units, {units[topic]!r} and '
                             f'{unit!r}')
        units[topic] = unit
    return units


def vibration_channels(bag, units=None, exclude=()):
    """
    Return the :class:`ChannelSource` s of ``bag`` (see the module's description), by name.

    ``units`` {topic: unit} (:func:`parse_units`); ``exclude``: topics that are no
    vibration channel (the keyphasor). Raises BagError for a unit given to a topic that is
    no channel.
    """
    units = dict(units or {})
    skip = {t.strip('/') for t in exclude}
    sources, named = [], set()
    for channel in sorted(bag.channels.values(), key=lambda c: c.topic):
        topic = channel.topic.strip('/')
        if topic in skip or topic.split('/')[-1] in (topics.SPEED, topics.KEYPHASOR):
            continue
        if channel.msg_type not in (FLOAT64, VECTOR3_STAMPED, IMU):
            continue
        unit = units.get(topic, DEFAULT_UNITS.get(channel.msg_type, AS_RECORDED))
        named.add(topic)
        if channel.msg_type == FLOAT64:
            sources.append(ChannelSource(topic, unit, channel))
        else:
            sources += [ChannelSource(f'{topic}/{a}', unit, channel, k)
                        for k, a in enumerate(AXES)]
    unknown = sorted(set(units) - named)
    if unknown:
        raise BagError(f'{bag.path}: --channel-unit names {", ".join(unknown)}, no vibration '
                       f'channel; the channels are the topics of {FLOAT64}, {VECTOR3_STAMPED} '
                       f'and {IMU}: {", ".join(sorted(named)) or "none"}')
    return sources


def channel_samples(bag, source, cache=None):
    """
    Return the :class:`Samples` of a :class:`ChannelSource` (times ns: log or header stamps).

    ``cache`` (a dict) keeps each bag channel's decoded messages for its other axes.
    """
    cache = {} if cache is None else cache
    key = source.channel.id
    if key not in cache:
        kind = source.channel.msg_type
        if kind == FLOAT64:
            times, values = float64_samples(bag, source.channel)
            cache[key] = Samples(times, values)
        else:
            offset = 0 if kind == VECTOR3_STAMPED else IMU_LINEAR_ACCELERATION
            stamps, fields, rejected = stamped_fields(
                bag, source.channel, 8, [(offset + 8 * k, '<f8') for k in range(3)])
            cache[key] = Samples(stamps, np.stack(fields, axis=1), rejected)
    found = cache[key]
    values = found.values if source.axis is None else found.values[:, source.axis]
    return Samples(found.time, values, found.rejected)


def stamped_fields(bag, channel, align, fields):
    """
    Return (stamp ns, [field arrays], rejected) of messages that begin with a std_msgs/Header.

    ``fields``: [(offset, dtype)], each offset counted from the first byte after the
    header's frame_id aligned to ``align`` (the header is followed by the message's own
    fields). Sorted by stamp; messages too short or not little-endian CDR are rejected.
    """
    stamps, columns, rejected = [], [[] for _ in fields], 0
    need = max(offset + np.dtype(dtype).itemsize for offset, dtype in fields)
    for buffer, offsets in bag.message_offsets(channel):
        size = column(buffer, offsets + 1, '<u8').astype(np.int64) - (MESSAGE_HEADER - 9)
        ok = size >= 16
        ok[ok] = gather(buffer, offsets[ok], 0, '<u2') == CDR_LE
        frame = np.zeros(len(offsets), np.int64)
        frame[ok] = gather(buffer, offsets[ok], 12, '<u4')
        body = 16 + frame
        body += (-(body - 4)) % align
        ok &= body + need <= size
        rejected += int((~ok).sum())
        offsets, body = offsets[ok], body[ok]
        sec = gather(buffer, offsets, 4, '<i4').astype(np.int64)
        stamps.append(sec * 1_000_000_000 + gather(buffer, offsets, 8, '<u4'))
        at = offsets + MESSAGE_HEADER + body
        for (offset, dtype), out in zip(fields, columns):
            out.append(column(buffer, at + offset, dtype))
    if not stamps:
        return np.zeros(0, np.int64), [np.zeros(0, d) for _, d in fields], rejected
    stamp = np.concatenate(stamps)
    order = np.argsort(stamp, kind='stable')
    return stamp[order], [np.concatenate(c)[order] for c in columns], rejected


def time_reference_marks(bag, channel):
    """Return (``time_ref`` of every sensor_msgs/TimeReference, ns, sorted; rejected)."""
    stamps, (sec, nanosec), rejected = stamped_fields(bag, channel, 4, [(0, '<i4'), (4, '<u4')])
    del stamps
    return np.sort(sec.astype(np.int64) * 1_000_000_000 + nanosec), rejected


def keyphasor_channel(bag, topic=None):
    """
    Return the bag channel of the keyphasor: ``topic`` exactly, or ``keyphasor``.

    Float64 or TimeReference. Raises BagError naming the bag's topics when there is none,
    or it has another type.
    """
    wanted = (topic or topics.KEYPHASOR).strip('/')
    found = [c for c in bag.channels.values() if c.topic.strip('/') == wanted]
    if not found and topic is None:
        found = [c for c in bag.channels.values() if c.topic.endswith('/' + wanted)]
    where = ' (given with --keyphasor)' if topic else ' (name it with --keyphasor TOPIC)'
    if len({c.topic for c in found}) > 1:
        raise BagError(f'{bag.path}: several keyphasor topics: '
                       f'{", ".join(sorted({c.topic for c in found}))}; choose one with '
                       '--keyphasor')
    if not found:
        raise BagError(f'{bag.path}: no keyphasor topic {wanted}{where}; the bag has: '
                       f'{describe_topics(bag.channels.values())}')
    channel = found[0]
    if channel.msg_type not in KEYPHASOR_TYPES:
        raise BagError(f'{bag.path}: keyphasor topic {channel.topic} has type '
                       f'{channel.msg_type or "(none)"}, expected {FLOAT64} (a sampled tach) '
                       f'or {TIME_REFERENCE} (one message a mark)')
    return channel


def read_keyphasor(bag, topic=None, edge='rising', threshold=None):
    """
    Return the :class:`Keyphasor` of ``bag`` (see the module's description).

    ``edge`` and ``threshold`` (the tach signal's unit; default midway between its low
    and high levels) apply to a sampled tach. Raises BagError when it gives fewer than
    two marks.
    """
    if edge not in EDGES:
        raise ValueError(f'keyphasor edge must be rising or falling, got {edge!r}')
    channel = keyphasor_channel(bag, topic)
    problems = []
    if channel.msg_type == FLOAT64:
        time_ns, values = float64_samples(bag, channel)
        if not len(time_ns):
            raise BagError(f'{bag.path}: keyphasor {channel.topic} has no readable message')
        origin = int(time_ns[0])
        try:
            raw = signal_marks((time_ns - origin) * 1e-9, values, edge, threshold)
        except ValueError as error:
            raise BagError(f'{bag.path}: keyphasor {channel.topic}: {error}') from None
    else:
        mark_ns, rejected = time_reference_marks(bag, channel)
        if rejected:
            problems.append(f'{channel.topic}: {rejected} messages not readable as '
                            'TimeReference; left out')
        if threshold is not None:
            problems.append(f'keyphasor {channel.topic} is {TIME_REFERENCE} (one message a '
                            'mark): the threshold given applies to a sampled tach only; '
                            'ignored')
        if not len(mark_ns):
            raise BagError(f'{bag.path}: keyphasor {channel.topic} has no readable message')
        time_ns, origin = None, int(mark_ns[0])
        raw = (mark_ns - origin) * 1e-9
    marks = checked_marks(raw)
    if len(marks.time) < 2 or not marks.revolutions:
        kind = f'crossings ({edge} edge)' if channel.msg_type == FLOAT64 else 'messages'
        raise BagError(f'{bag.path}: keyphasor {channel.topic} gives {len(marks.time)} marks '
                       f'({marks.found} {kind}) and no whole revolution')
    return Keyphasor(channel, origin, marks, time_ns, problems)


def keyphasor_motion(bag, topic=None, edge='rising', threshold=None,
                     samples_per_rev=SAMPLES_PER_REV):
    """
    Return the :class:`~cvc_balance.bag.mcap_reader.MotionSamples` a keyphasor gives.

    What the encoder path gives (stamp and log time ns, angle rad within (-pi, pi],
    omega rad/s), so a tach can stand in for joint_states: at a sampled tach's sample
    times, or ``samples_per_rev`` evenly spaced in every revolution of a TimeReference
    keyphasor. Samples without an angle (before the first mark, after the last, inside an
    irregular period) are left out and counted as rejected (``reasons``); the marks'
    check goes to ``problems`` when it repaired, dropped or left out a mark.
    """
    tach = read_keyphasor(bag, topic, edge, threshold)
    marks = tach.marks
    if tach.time_ns is not None:
        time_ns = tach.time_ns
    else:
        per = np.linspace(0.0, 1.0, samples_per_rev, endpoint=False)
        start = marks.time[:-1][marks.good]
        length = np.diff(marks.time)[marks.good]
        seconds = np.concatenate([(start[:, None] + per * length[:, None]).ravel(),
                                  marks.time[-1:]])
        time_ns = tach.origin_ns + np.rint(seconds * 1e9).astype(np.int64)
    angle, omega, _ = marks.motion(tach.seconds(time_ns), acceleration=False)
    ok = np.isfinite(angle) & np.isfinite(omega)
    left_out = int((~ok).sum())
    reasons = [f'{left_out} keyphasor samples before the first mark, after the last or '
               'inside an irregular period: no angle there'] if left_out else []
    problems = ([tach.summary()] if marks.missed or marks.doubled or marks.irregular
                else []) + tach.problems
    return MotionSamples(time_ns[ok], time_ns[ok], wrap_angle(angle[ok]), omega[ok],
                         left_out, reasons, problems=problems)
