"""
Offline replay: a bag's motion and layouts through the vectorised engine, into a bag.

Mirrors the live node sample for sample: the same input checks, the same
alpha estimate (vectorised), the layout in force at each sample's log time,
the same outputs and frames. No ROS graph is needed.
"""

from dataclasses import dataclass, field
from functools import partial
import time

import numpy as np

from cvc_balance.bag.channels import keyphasor_motion
from cvc_balance.bag.inputs import input_channels, InputTopics
from cvc_balance.bag.mcap_reader import (BagError, float64_samples, joint_samples,
                                         MotionSamples, string_samples)
from cvc_balance.bag.rosbag2 import open_bag, open_writer
from cvc_balance.identify.mistakes import run_motion_findings
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import string_message, wrench_stamped_layout
from cvc_balance.physics.bearing_life import balanced, LifeCounters
from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.frames import ROTOR_FRAME, STATOR_FRAME, wrap_angle
from cvc_balance.physics.layout import LayoutError
from cvc_balance.physics.layout_file import layout_from_text
from cvc_balance.physics.model_choice import choose_model, Envelope
from cvc_balance.physics.motion import accepted_motion, MAX_STAMP_JUMP
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance, unbalance_wrench

JOINT_STATE, FLOAT64 = topics.JOINT_STATE_TYPE, topics.FLOAT64_TYPE
STRING, WRENCH = topics.STRING_TYPE, topics.WRENCH_TYPE
BLOCK = 1 << 14
SAID = 5
"""Rejected layout messages described one by one (the others counted)."""
"""Samples computed at once (the engine's work arrays stay in cache)."""
LEVELS = {'zstd': -7, 'lz4': -1}
CHUNK_BYTES = 4 << 20
"""
Compression level and chunk size (uncompressed) of the output: compressing is most of
replay's work. Chosen by measurement (``benchmarks/replay_throughput.py --tune`` prints the
tables): on a replay's WrenchStamped chunks, one thread of the 2-core development machine,
zstd -7 compresses 1.5-1.6 GB/s to a ratio of 4.09, faster and smaller than -5 (1.4-1.5
GB/s, 3.82), -3 (1.2 GB/s, 4.1) or 1 (0.8 GB/s, 4.45); the chunk size changes neither by
more than the noise between 1 and 8 MiB, and 4 MiB chunks took the least CPU time per
replay; lz4 0 1.11 GB/s (3.10), -1 1.30 GB/s (3.28).
"""


@dataclass
class Segment:
    """Samples computed with one layout: its name, digest and what they gave."""

    layout: object
    start_ns: int
    samples: int = 0
    peak_support: dict = field(default_factory=dict)
    peak_total: float = 0.0
    max_speed: float = 0.0
    choice: object = None      # model_choice.ModelChoice when a tolerance was given
    first_ns: int = None       # log times of its first and last sample (None: no sample)
    last_ns: int = None
    model: object = None       # the full RotorModel of the layout (the verdict's)
    life: object = None        # LifeCounters of its bearings (None: the layout has none)
    balanced_life: object = None   # the same run's of the rotor balanced


@dataclass(frozen=True)
class InputCheck:
    """
    A mistake the inputs show (:mod:`cvc_balance.identify.mistakes`), as the node says it.

    ``input``: the topic (or 'load cells'); ``segment``: the layout segment (1 = the
    first) for the cells, None for the motion; ``finding``: the Finding; ``seen``: in
    how many of the ``judged`` windows (the motion's; 1 of 1 for a segment's cells).
    """

    input: str
    segment: int
    finding: object
    seen: int = 1
    judged: int = 1


@dataclass
class ReplaySummary:
    """What a replay read, computed and wrote."""

    bag: str
    samples: int = 0
    accepted: int = 0
    rejected: int = 0
    dropped: int = 0
    skipped: int = 0           # JointState messages without the joint
    skipped_reason: str = ''
    reasons: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    input_checks: list = field(default_factory=list)    # [InputCheck]
    segments: list = field(default_factory=list)
    seconds: float = 0.0
    output: str = ''


def read_inputs(bag, joint_name, names=None):
    """
    Motion samples and layout messages of a bag: (MotionSamples, [(log time, text)]).

    joint_states (sensor_msgs/JointState) is used if present, else speed
    (std_msgs/Float64, angle integrated over log times as the node does over
    receive times), else a keyphasor (:func:`cvc_balance.bag.channels.keyphasor_motion`:
    the angle 0 at each mark, its marks' check in the samples' ``problems``);
    ``names`` (:class:`cvc_balance.bag.inputs.InputTopics`) names other topics, or
    the keyphasor. Raises BagError when the bag has none, or when no JointState
    carries the joint.
    """
    names = names or InputTopics()
    channels = input_channels(bag, names)
    if channels.keyphasor is not None:
        motion = keyphasor_motion(bag, channels.keyphasor.topic, names.keyphasor_edge,
                                  names.keyphasor_threshold)
    elif channels.joint_states is not None:
        motion = joint_samples(bag, channels.joint_states, joint_name)
        motion.joint_topic = channels.joint_states.topic
        if not len(motion.stamp) and motion.skipped:
            raise BagError(f'{bag.path}: no {channels.joint_states.topic} message carries '
                           f"joint '{joint_name}' ({_joints_named(motion)}); "
                           'choose the joint with --joint-name')
    else:
        log_time, omega = float64_samples(bag, channels.speed)
        t = log_time * 1e-9
        steps = np.concatenate([[0.0], 0.5 * (omega[1:] + omega[:-1]) * np.diff(t)])
        angle = wrap_angle(np.cumsum(steps))
        motion = MotionSamples(log_time, log_time, angle, omega)
    layouts = string_samples(bag, channels.layout) if channels.layout is not None else []
    return motion, layouts


def layout_events(bag, layout_messages, layout_file=None):
    """
    Return ([(log time ns, Layout)], problems): the layouts in force, from their log times.

    ``layout_file`` (what if) replaces the bag's layouts for the whole run. A layout
    message that does not parse costs only itself: it is reported (the first
    :data:`SAID` of them one by one, then their count) and the previous one stays in
    force (before the first good one: none). Raises BagError when no layout is usable.
    """
    events, problems = layouts_in_force(bag, layout_messages, layout_file)
    return [(log_time, layout) for log_time, layout, _ in events], problems


def layouts_in_force(bag, layout_messages, layout_file=None):
    """
    Return ([(log time ns, Layout, its text)], problems): :func:`layout_events` with texts.

    Each layout keeps the text it was parsed from (the file's for ``layout_file``), so
    the output bag repeats that text even when several layout messages share a log time.
    """
    problems = []
    if layout_file is not None:
        from cvc_balance.physics.layout_file import load_layout
        with open(layout_file, encoding='utf-8') as stream:
            text = stream.read()
        events = [(np.iinfo(np.int64).min, load_layout(layout_file), text)]
    else:
        events, rejected = [], 0
        for log_time, text in layout_messages:
            try:
                events.append((log_time, layout_from_text(text, source='layout message'),
                               text))
                continue
            except LayoutError as error:
                why = str(error)
            except Exception as error:   # a bug on a hostile text: this message's alone
                why = f'internal error: {type(error).__name__}: {error}'
            rejected += 1
            if rejected <= SAID:
                problems.append(f'layout at {log_time * 1e-9:.3f} s rejected (previous stays '
                                f'in force): {why}')
        if rejected > SAID:
            problems.append(f'{rejected} layout messages rejected in all (the first {SAID} '
                            'said above)')
    if not events:
        raise BagError(f'{bag.path}: no usable layout in the bag (topic layout, {STRING}); '
                       'name its topic with --layout-topic or give a layout file with '
                       '--layout-file')
    return events, problems


def _joints_named(motion):
    """Say which joints the skipped JointState messages name (none: they name none)."""
    seen = motion.joints_seen
    return f"they name: {', '.join(seen)}" if seen else 'they name no joint'


def replay(bag_path, output=None, layout_file=None, joint_name='gantry_joint',
           time_constant=0.1, max_speed=1000.0, compression='zstd', progress=None,
           observer=None, tolerance=None, names=None, max_stamp_jump=MAX_STAMP_JUMP):
    """
    Replay ``bag_path``; write outputs to ``output`` (if given); return a ReplaySummary.

    ``bag_path`` is a bag file or a rosbag2 directory, ``output`` a .mcap file or
    a rosbag2 directory (:mod:`cvc_balance.bag.rosbag2`); ``names``
    (:class:`cvc_balance.bag.inputs.InputTopics`) the input topics if not the
    node's own.

    ``observer`` (e.g. a rerun RunLogger) gets ``layout(first stamp ns, model,
    segment_start_ns=log time it came into force, 0 if before the bag)`` for each layout
    and ``samples(stamp_ns, angle, omega, alpha, result)`` for each block.
    ``tolerance`` (a :class:`cvc_balance.physics.model_choice.Tolerance`): each layout is
    computed with the smallest model within it over the speeds and accelerations of
    its own samples, and the segment says which.
    """
    started = time.perf_counter()
    bag = open_bag(bag_path)
    summary = ReplaySummary(str(bag_path))
    motion, layout_messages = read_inputs(bag, joint_name, names)
    summary.samples = len(motion.stamp) + motion.rejected + motion.skipped
    summary.reasons = list(motion.reasons)
    summary.problems = list(motion.problems)
    summary.skipped = motion.skipped
    if motion.skipped:
        summary.skipped_reason = (f"{motion.skipped} JointState messages without joint "
                                  f"'{joint_name}' ({_joints_named(motion)})")
    in_force, layout_problems = layouts_in_force(bag, layout_messages, layout_file)
    summary.problems += layout_problems
    events = [(log_time, layout) for log_time, layout, _ in in_force]
    t = motion.stamp * 1e-9
    accepted, accepted_alpha = accepted_motion(t, motion.log_time * 1e-9, motion.angle,
                                               motion.omega, max_speed, time_constant,
                                               max_stamp_jump)
    summary.rejected = motion.rejected + int((~accepted).sum())
    if (~accepted).any() and len(summary.reasons) < 5:
        summary.reasons.append('motion samples not finite, beyond max_speed, not after the '
                               'previous stamp or jumping more than max_stamp_jump')
    first_layout = events[0][0]
    in_time = motion.log_time >= first_layout
    summary.dropped = int((accepted & ~in_time).sum())
    use = accepted & in_time
    stamp, log_time, angle, omega = _where(use, motion.stamp, motion.log_time, motion.angle,
                                           motion.omega)
    # alpha runs over every accepted sample (also those before a layout).
    alpha, = _where(in_time[accepted], accepted_alpha)
    summary.accepted = int(use.sum())
    if motion.joint_topic is not None:     # the position and velocity as sent: their units
        summary.input_checks = [
            InputCheck(motion.joint_topic, None, finding, seen, judged)
            for finding, seen, judged in run_motion_findings(stamp * 1e-9, angle, omega)]
    writer = open_writer(output, compression=compression, level=LEVELS.get(compression),
                         chunk_bytes=CHUNK_BYTES) if output else None
    channels = _output_channels(writer) if writer else None
    if writer:
        for log, _, text in in_force:
            writer.write(channels['layout'], max(int(log), 0), string_message(text))
    bounds = [e[0] for e in events[1:]] + [np.iinfo(np.int64).max]
    done = 0
    for (start_ns, layout), end_ns in zip(events, bounds):
        lo, hi = np.searchsorted(log_time, [start_ns, end_ns])
        segment = Segment(layout, int(start_ns))
        if hi > lo:
            segment.first_ns, segment.last_ns = int(log_time[lo]), int(log_time[hi - 1])
        if tolerance is None:
            model = segment.model = RotorModel.from_layout(layout)
        else:
            envelope = Envelope(float(np.abs(omega[lo:hi]).max(initial=0.0)),
                                float(np.abs(alpha[lo:hi]).max(initial=0.0)))
            segment.choice = choose_model(layout, tolerance, envelope)
            model = segment.choice.model
        summary.segments.append(segment)
        life = LifeCounters(layout.supports)
        if life:        # the bearings' life: of this run, and of the rotor balanced
            segment.life, segment.balanced_life = life, LifeCounters(layout.supports)
            quiet = balanced(model)
        blocks = OutputBlocks(writer, channels, model) if writer else None
        if observer is not None:
            first = np.searchsorted(log_time, start_ns)
            observer.layout(int(stamp[first]) if first < len(stamp) else max(int(start_ns), 0),
                            model, segment_start_ns=int(max(start_ns, 0)))
        for a in range(lo, hi, BLOCK):
            b = min(a + BLOCK, hi)
            result = loads(model, angle[a:b], omega[a:b], alpha[a:b])
            _account(segment, model, result, omega[a:b])
            if segment.life is not None:
                seconds = stamp[a:b] * 1e-9
                segment.life.add(seconds, angle[a:b], omega[a:b], result.support_force)
                segment.balanced_life.add(seconds, angle[a:b], omega[a:b], loads(
                    quiet, angle[a:b], omega[a:b], alpha[a:b]).support_force)
            if blocks:
                blocks.write(result, stamp[a:b], log_time[a:b], omega[a:b])
            if observer is not None:
                observer.samples(stamp[a:b], angle[a:b], omega[a:b], alpha[a:b], result)
            done += b - a
            if progress:
                progress(done, len(stamp))
    if writer:
        writer.close()
        summary.output = str(output)
    summary.problems = bag.problems + summary.problems
    summary.seconds = time.perf_counter() - started
    return summary


def _where(mask, *arrays):
    """Return the elements of ``arrays`` where ``mask`` holds (the arrays if it always does)."""
    if mask.all():
        return arrays
    return tuple(a[mask] for a in arrays)


def _output_channels(writer):
    channels = {topic: writer.add_channel(f'/{topic}', WRENCH) for topic in topics.OUTPUTS}
    channels.update(layout=writer.add_channel(f'/{topics.LAYOUT}', STRING, latched=True),
                    supports={})
    return channels


class OutputBlocks:
    """The message block of one layout's outputs: one chunk's samples, refilled."""

    def __init__(self, writer, channels, model):
        """Register the support channels and lay out the block for ``model``'s supports."""
        supports = channels['supports']
        for s in model.supports:
            if s.name not in supports:
                supports[s.name] = writer.add_channel(f'/{topics.support_load(s.name)}', WRENCH)
        stator, rotor = wrench_stamped_layout(STATOR_FRAME), wrench_stamped_layout(ROTOR_FRAME)
        parts = [(channels[topics.BEARING_LOAD], stator)]
        parts += [(supports[s.name], stator) for s in model.supports]
        parts += [(channels[topics.UNBALANCE], rotor), (channels[topics.DRIVE_TORQUE], rotor)]
        self.writer, self.model = writer, model
        self.block = writer.block(parts)
        every = range(len(parts))
        self.names = {'stamp': [f'{g}.sec' for g in every],
                      'force': [[f'{g}.force_{axis}' for axis in 'xyz'] for g in every],
                      'torque': [[f'{g}.torque_{axis}' for axis in 'xyz'] for g in every]}
        self.static, self.couple = static_unbalance(model), couple_unbalance(model)

    def write(self, result, stamp, log_time, omega):
        """Write the outputs of a computed block of samples, a chunk at a time."""
        block = self.block
        wrenches = [(result.force_stator, result.moment_stator)]
        wrenches += [(result.support_force[s.name], result.support_moment[s.name])
                     for s in self.model.supports]
        # builtin_interfaces/Time (sec int32, nanosec uint32) of all parts as one '<u8'.
        sec, nanosec = np.divmod(stamp, 1_000_000_000)
        stamps = ((sec & 0xFFFFFFFF) | (nanosec << 32)).astype(np.uint64)
        for a in range(0, len(stamp), block.n):
            b = min(a + block.n, len(stamp))
            # Filled on the writer's threads, several chunks at once.
            self.writer.write_block(block, log_time[a:b], b - a, partial(
                self._fill, wrenches=wrenches, drive_torque=result.drive_torque,
                stamps=stamps, omega=omega, a=a, b=b))

    def _fill(self, buffer, wrenches, drive_torque, stamps, omega, a, b):
        n, names = b - a, self.names
        buffer.put(names['stamp'], stamps[a:b], n, '<u8')
        for g, (f, m) in enumerate(wrenches):       # (n, 3) arrays: rows are .T
            buffer.put(names['force'][g], f[a:b].T, n)
            buffer.put(names['torque'][g], m[a:b].T, n)
        f, m = unbalance_wrench(self.static, self.couple, omega[a:b])   # U omega^2, couple
        unbalance, drive = len(wrenches), len(wrenches) + 1
        buffer.put(names['force'][unbalance][:2], f[:2], n)
        buffer.put(names['torque'][unbalance][:2], m[:2], n)
        buffer.put(names['torque'][drive][2:], drive_torque[a:b], n)


def _account(segment, model, result, omega):
    segment.samples += len(omega)
    if len(omega):
        segment.max_speed = max(segment.max_speed, float(np.abs(omega).max()))
        segment.peak_total = max(segment.peak_total,
                                 float(np.linalg.norm(result.force_stator, axis=1).max()))
    for s in model.supports:
        peak = float(np.linalg.norm(result.support_force[s.name], axis=1).max()) \
            if len(omega) else 0.0
        segment.peak_support[s.name] = max(segment.peak_support.get(s.name, 0.0), peak)
