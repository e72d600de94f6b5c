"""
Replay's output bag, message by message, against the mcap library and rosbags (issue 29).

A short input bag (200 JointState samples of a spin-up, serialised by rosbags, and the
gantry's layout) is replayed; its output is read back by the ``mcap`` library (every
message, counted per topic) and decoded by rosbags: one message per accepted sample on
each output topic, with the input's stamps and log times, and the unbalance force
S omega^2 with S = sum m r e^(i angle) of the layout's components by hand.
"""

import cmath
import math
from pathlib import Path
import time

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.mcap_reader import Bag, BagError
from cvc_balance.bag.replay import layout_events, replay
from independent import ramp, write_input_bag

ROOT = Path(__file__).resolve().parents[1]
GANTRY_FILE = ROOT / 'config' / 'ct_gantry.yaml'
GANTRY = yaml.safe_load(GANTRY_FILE.read_text())
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
WRENCH = 'geometry_msgs/msg/WrenchStamped'


@pytest.fixture(scope='module')
def replayed(tmp_path_factory):
    """(input stamps, output messages {topic: [(log time, message)]}, summary)."""
    folder = tmp_path_factory.mktemp('replay')
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=1.0)
    bag = write_input_bag(folder / 'in.mcap', stamps, angle, omega,
                          [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    summary = replay(bag, folder / 'out.mcap')
    out = {}
    with open(folder / 'out.mcap', 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append(
                (message.log_time, channel.schema_id, bytes(message.data)))
    return stamps, omega, out, summary


def test_one_output_message_per_accepted_sample(replayed):
    """Each output topic: 200 messages, the input's stamps (header) and log times, in order."""
    stamps, _, out, summary = replayed
    supports = [f"/supports/{s['name']}/load" for s in GANTRY['supports']]
    assert summary.accepted == len(stamps) == 200
    assert sorted(out) == sorted(['/bearing_load', '/unbalance', '/drive_torque', '/layout']
                                 + supports)
    assert len(out['/layout']) == 1
    for topic in set(out) - {'/layout'}:
        messages = [(log, TYPESTORE.deserialize_cdr(data, WRENCH)) for log, _, data in
                    out[topic]]
        assert [log for log, _ in messages] == [int(s) for s in stamps], topic
        assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in messages] == \
            [int(s) for s in stamps], topic


def test_the_unbalance_force_is_the_layouts_mass_moment_by_hand_times_omega_squared(replayed):
    """
    /unbalance (rotor frame): force x + i y = S omega^2, S = sum m r e^(i angle) by hand.

    Every component of config/ct_gantry.yaml is at its radius and angle: S in kg m; the
    relative error measured 1e-16 (rounding), held to 1e-12.
    """
    _, omega, out, _ = replayed
    s = sum(c['mass'] * c['radius'] * cmath.exp(1j * math.radians(c['angle_deg']))
            for c in GANTRY['components'])
    forces = np.array([[m.wrench.force.x, m.wrench.force.y] for m in (
        TYPESTORE.deserialize_cdr(data, WRENCH) for _, _, data in out['/unbalance'])])
    expected = np.array([[(s * w * w).real, (s * w * w).imag] for w in omega])
    assert abs(s) > 0.01
    np.testing.assert_allclose(forces, expected, rtol=1e-12, atol=1e-12 * abs(s))


def test_layout_events_of_a_layout_file_and_of_no_usable_layout(tmp_path):
    """
    A layout file holds for the whole run (from the earliest time); no usable layout: one line.

    The line names the bag's path, the topic and type looked for, and the two options.
    """
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=0.1)
    path = write_input_bag(tmp_path / 'in.mcap', stamps, angle, omega,
                           [(stamps[0], 'components: [')])
    bag = Bag(path)
    events, problems = layout_events(bag, [], GANTRY_FILE)
    (start, layout), = events
    assert start == np.iinfo(np.int64).min and problems == []
    assert [c.name for c in layout.components] == [c['name'] for c in GANTRY['components']]
    with pytest.raises(BagError) as refused:
        layout_events(bag, [(int(stamps[0]), 'components: [')])
    assert str(refused.value) == (
        f'{path}: no usable layout in the bag (topic layout, std_msgs/msg/String); name its '
        'topic with --layout-topic or give a layout file with --layout-file')


def test_the_peak_support_loads_of_a_light_rotor_are_pinocchios(tmp_path):
    """
    Each support's peak |force| over a segment, by Pinocchio's RNEA at every sample.

    The gantry with every mass a millionth (loads of milli-newtons, every one under 1 N), at
    a steady 3 rad/s (the estimated acceleration 0): the summary's peaks are the largest
    of Pinocchio's per-sample loads split over the supports by statics (relative error
    measured 1e-15, held to 1e-9).
    """
    from independent import PinocchioRotor
    light = yaml.safe_load(GANTRY_FILE.read_text())
    for c in light['components']:
        c['mass'] *= 1e-6
    stamps, angle, omega = ramp(3.0, 0.0, rate=200.0, seconds=1.0)
    bag = write_input_bag(tmp_path / 'light.mcap', stamps, angle, omega,
                          [(stamps[0] - 1000, yaml.safe_dump(light))])
    (segment,) = replay(bag).segments
    rotor = PinocchioRotor(light)
    peaks = {}
    for q, w in zip(angle, omega):
        for name, (force, _) in rotor.loads(q, w, 0.0)['supports'].items():
            peaks[name] = max(peaks.get(name, 0.0), float(np.linalg.norm(force)))
    assert set(segment.peak_support) == set(peaks) and 0.0 < max(peaks.values()) < 1.0
    for name, peak in peaks.items():
        assert segment.peak_support[name] == pytest.approx(peak, rel=1e-9), name


def test_rejected_layout_messages_are_said_one_by_one_up_to_five(tmp_path, monkeypatch):
    """
    Five rejected: five lines and no count; a parser's own failure is said as internal.

    A layout text that makes the parser itself fail (put in by hand) is said with its
    exception's type and text, and the previous layout stays in force.
    """
    import importlib
    module = importlib.import_module('cvc_balance.bag.replay')
    parse = module.layout_from_text

    def failing(text, **kwargs):
        if text == 'boom':
            raise RuntimeError('the parser failed')
        return parse(text, **kwargs)
    monkeypatch.setattr(module, 'layout_from_text', failing)
    good = yaml.safe_dump(GANTRY)
    messages = [(10**9, good)] + [(k * 10**9, 'components: [') for k in range(2, 6)] + \
        [(6 * 10**9, 'boom')]
    events, problems = module.layouts_in_force(None, messages)
    assert len(events) == 1 and len(problems) == 5
    assert problems[4] == ('layout at 6.000 s rejected (previous stays in force): internal '
                           'error: RuntimeError: the parser failed')
    assert all(p.startswith(f'layout at {k}.000 s rejected (previous stays in force): ')
               for k, p in zip(range(2, 6), problems))


def test_a_keyphasor_named_on_its_own_topic_is_the_motion(tmp_path):
    """
    read_inputs with the keyphasor named (``--keyphasor /tach``): that topic's marks.

    Twelve TimeReference marks 0.25 s apart on /tach (4 revolutions a second), and a decoy
    /keyphasor (the default name) whose marks are 0.5 s apart: every sample's speed is
    8 pi rad/s and its angle 2 pi times the revolutions since the last mark, by hand
    (held to 1e-9).
    """
    from cvc_balance.bag.inputs import InputTopics
    from cvc_balance.bag.replay import read_inputs
    path = tach_bag(tmp_path / 'tach.mcap')
    start = 3 * 10**9
    motion, layouts = read_inputs(Bag(path), 'gantry_joint', InputTopics(keyphasor='/tach'))
    assert layouts == [] and len(motion.stamp) >= 11 * 8
    turns = (motion.stamp - start) / 250_000_000
    assert turns.min() >= 0.0 and turns.max() <= 11.0
    np.testing.assert_allclose(motion.omega, 8 * math.pi, rtol=1e-9)
    wrapped = np.angle(np.exp(2j * math.pi * turns))
    assert np.abs(np.angle(np.exp(1j * (motion.angle - wrapped)))).max() <= 1e-9


def test_a_joint_state_topic_without_messages_gives_no_samples(tmp_path):
    """No JointState at all: no sample and no complaint about the joint's name."""
    from cvc_balance.bag.replay import read_inputs
    path = write_input_bag(tmp_path / 'none.mcap', [], [], [], [(1, yaml.safe_dump(GANTRY))])
    motion, layouts = read_inputs(Bag(path), 'gantry_joint')
    assert len(motion.stamp) == 0 and motion.skipped == 0 and motion.joint_topic == \
        '/joint_states'
    assert [log for log, _ in layouts] == [1]


def test_every_output_wrench_is_pinocchios(replayed):
    """
    Every output wrench is pinocchios.

    Each output topic's six numbers at every sample, by Pinocchio's RNEA at the input's
    angle and speed and the ramp's acceleration (2 rad/s^2; the estimate's slope is
    exact on a ramp from the second sample on): the bearing load and each support's (force
    and moment, stator frame), the unbalance (rotor frame: U omega^2 and the couple) and
    the drive torque. Held to 1e-9 of each topic's largest value (measured 1e-13).
    """
    from independent import PinocchioRotor
    stamps, omega, out, _ = replayed
    rotor = PinocchioRotor(GANTRY)
    angle = np.remainder(1.0 * (stamps - stamps[0]) * 1e-9 + (stamps - stamps[0])**2 * 1e-18
                         + math.pi, 2 * math.pi) - math.pi
    expected = {topic: [] for topic in out if topic != '/layout'}
    for q, w in zip(angle[1:], omega[1:]):
        ref = rotor.loads(float(q), float(w), 2.0)
        expected['/bearing_load'].append(np.concatenate([ref['force'], ref['moment']]))
        for name, (force, moment) in ref['supports'].items():
            expected[f'/supports/{name}/load'].append(np.concatenate([force, moment]))
        expected['/unbalance'].append(np.concatenate(rotor.unbalance(float(w))))
        expected['/drive_torque'].append([0, 0, 0, 0, 0, ref['drive_torque']])
    for topic, rows in expected.items():
        got = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
                         m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z]
                        for m in (TYPESTORE.deserialize_cdr(data, WRENCH)
                                  for _, _, data in out[topic][1:])])
        rows = np.array(rows, float)
        assert np.abs(got - rows).max() <= 1e-9 * np.abs(rows).max(), topic


def test_the_default_time_constant_forgets_a_ramp_in_a_tenth_of_a_second(tmp_path):
    """
    The default time constant forgets a ramp in a tenth of a second.

    A ramp (3 rad/s^2 for 1 s), then a steady 4 rad/s for 2 s: 20 default time constants
    (0.1 s) after the corner the drive torque is Pinocchio's at alpha 0, to 1e-6 of the
    ramp's own torque I_zz 3 rad/s^2 (measured 1e-7; a time constant of 1.1 s leaves a
    tenth of the ramp's acceleration there).
    """
    from independent import PinocchioRotor
    rate = 200.0
    t = np.arange(int(3.0 * rate)) / rate
    omega = np.where(t < 1.0, 1.0 + 3.0 * t, 4.0)
    theta = np.where(t < 1.0, t + 1.5 * t * t, 2.5 + 4.0 * (t - 1.0))
    angle = np.remainder(theta + math.pi, 2 * math.pi) - math.pi
    stamps = 5 * 10**9 + np.round(t * 1e9).astype(np.int64)
    bag = write_input_bag(tmp_path / 'corner.mcap', stamps, angle, omega,
                          [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    replay(bag, tmp_path / 'out.mcap')
    with open(tmp_path / 'out.mcap', 'rb') as stream:
        torques = [TYPESTORE.deserialize_cdr(m.data, WRENCH).wrench.torque.z
                   for _, c, m in make_reader(stream).iter_messages(log_time_order=False)
                   if c.topic == '/drive_torque']
    rotor = PinocchioRotor(GANTRY)
    expected = [rotor.loads(float(q), float(w), 0.0)['drive_torque']
                for q, w in zip(angle, omega)]
    ramp_torque = abs(rotor.loads(0.0, 4.0, 3.0)['drive_torque'] -
                      rotor.loads(0.0, 4.0, 0.0)['drive_torque'])
    assert len(torques) == len(t) and ramp_torque > 100.0
    assert max(abs(a - b) for a, b in zip(torques[-10:], expected[-10:])) <= 1e-6 * ramp_torque


def joint_bag(path, stamps, messages, header_stamps=None):
    """
    Return a bag of /joint_states: messages [(names, position, velocity)] rosbags serialises.

    Logged at ``stamps`` (ns), their headers stamped the same or ``header_stamps`` [(sec,
    nanosec)].
    """
    from cvc_balance.bag.mcap_writer import BagWriter
    joint = 'sensor_msgs/msg/JointState'
    types = TYPESTORE.types
    with BagWriter(path) as writer:
        layout = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        writer.write(layout, int(stamps[0]) - 1000, TYPESTORE.serialize_cdr(
            types['std_msgs/msg/String'](data=yaml.safe_dump(GANTRY)),
            'std_msgs/msg/String').tobytes())
        channel = writer.add_channel('/joint_states', joint)
        header_stamps = header_stamps or [divmod(int(ns), 10**9) for ns in stamps]
        for ns, (sec, nanosec), (names, position, velocity) in zip(stamps, header_stamps,
                                                                   messages):
            msg = types[joint](header=types['std_msgs/msg/Header'](
                stamp=types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
                frame_id=''), name=list(names), position=np.array(position, float),
                velocity=np.array(velocity, float), effort=np.zeros(0))
            writer.write(channel, int(ns), TYPESTORE.serialize_cdr(msg, joint).tobytes())
    return path


def test_joint_states_without_the_joint_are_counted_and_named(tmp_path):
    """
    Joint states without the joint are counted and named.

    Of 12 JointStates: 8 of the joint, 3 naming two other joints, 1 of the joint without a
    velocity: 12 samples, 8 accepted, 3 skipped (said with the joints they name, in
    order), 1 rejected. Only other joints: refused, naming them.
    """
    stamps = 5 * 10**9 + 5_000_000 * np.arange(12)
    messages = [(['gantry_joint'], [0.01 * k], [2.0]) for k in range(12)]
    for k in (3, 6, 9):
        messages[k] = (['wheel', 'arm'], [0.0, 1.0], [0.0, 0.0])
    messages[10] = (['gantry_joint'], [0.1], [])
    bag = joint_bag(tmp_path / 'mixed.mcap', stamps, messages)
    summary = replay(bag)
    assert (summary.samples, summary.accepted, summary.skipped, summary.rejected) == \
        (12, 8, 3, 1)
    assert summary.skipped_reason == ("3 JointState messages without joint 'gantry_joint' "
                                      '(they name: arm, wheel)')
    others = joint_bag(tmp_path / 'others.mcap', stamps[:2], messages[3:4] * 2)
    with pytest.raises(BagError) as refused:
        replay(others)
    assert str(refused.value) == (f"{others}: no /joint_states message carries joint "
                                  "'gantry_joint' (they name: arm, wheel); choose the joint "
                                  'with --joint-name')


def tach_bag(path, missed=()):
    """Return TimeReference marks on /tach every 0.25 s and on /keyphasor every 0.5 s (12 each)."""
    from cvc_balance.bag.mcap_writer import BagWriter
    from tach_bags import time_reference
    start = 3 * 10**9
    with BagWriter(path) as writer:
        for topic, period in (('/tach', 250_000_000), ('/keyphasor', 500_000_000)):
            channel = writer.add_channel(topic, 'sensor_msgs/msg/TimeReference')
            for k in range(12):
                if topic == '/tach' and k in missed:
                    continue
                ns = start + k * period
                writer.write(channel, ns + 1_000_000, time_reference(ns, ns + 1_000_000))
    return path


def test_replay_reads_the_topics_it_is_given(tmp_path):
    """
    Replay reads the topics it is given.

    replay(names=...): the keyphasor on /tach (4 rev/s), not the default /keyphasor (2);
    a mark missed on /tach is put back and said among the replay's problems.
    """
    from cvc_balance.bag.inputs import InputTopics
    path = tach_bag(tmp_path / 'tach.mcap', missed=(6,))
    summary = replay(path, layout_file=GANTRY_FILE, names=InputTopics(keyphasor='/tach'))
    (segment,) = summary.segments
    assert segment.max_speed == pytest.approx(8 * math.pi, rel=1e-9)
    said = [p for p in summary.problems if p.startswith('keyphasor /tach: ')]
    assert len(said) == 1 and ' 1 missed (put back), 0 doubled (dropped)' in said[0]


def test_stamps_ahead_of_the_log_times_by_more_than_max_stamp_jump(tmp_path):
    """
    Stamps ahead of the log times by more than max stamp jump.

    From the 100th sample on the stamps run 0.5 s ahead of the log times: within the
    default max_stamp_jump (1 s) every sample is taken; with 0.25 s the replay takes
    what the stamp gate takes of those stamps and log times (in s), fewer.
    """
    from cvc_balance.physics.motion import gate_samples
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=1.0)
    log_times = stamps.copy()
    stamps[100:] += 500_000_000
    bag = write_input_bag(tmp_path / 'ahead.mcap', stamps, angle, omega,
                          [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    from cvc_balance.bag.mcap_writer import BagWriter
    relogged = tmp_path / 'relogged.mcap'
    source = Bag(bag)
    with BagWriter(relogged) as writer:       # the same messages at the earlier log times
        for channel in source.channels.values():
            out = writer.add_channel(channel.topic, channel.msg_type)
            for k, (log_time, data) in enumerate(source.messages(channel)):
                writer.write(out, int(log_times[k]) if channel.topic == '/joint_states'
                             else log_time, data)
    assert replay(relogged).accepted == 200
    accepted, _ = gate_samples(stamps * 1e-9, angle, omega, 1000.0, 0.25, log_times * 1e-9)
    strict = replay(relogged, max_stamp_jump=0.25)
    assert strict.accepted == int(accepted.sum()) < 200
    assert strict.rejected == 200 - strict.accepted


def test_the_observer_sees_each_layout_and_every_sample(tmp_path):
    """
    The observer sees each layout and every sample.

    observer.layout(first stamp, model, segment_start_ns) for each layout (one logged
    before the samples, one after the first 50: its first stamp the 51st; one after the
    last sample: its own log time), samples(...)
    with every accepted sample's stamp, angle and speed as read and the ramp's
    acceleration; a segment's first and last log time (none for a layout no sample used);
    the replay's seconds within those the test measured around it.
    """
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=0.5)
    unused, first = int(stamps[0]) - 2000, int(stamps[0]) - 1000
    later = dict(GANTRY, name='later')
    bag = write_input_bag(tmp_path / 'in.mcap', stamps, angle, omega,
                          [(unused, yaml.safe_dump(dict(GANTRY, name='unused'))),
                           (first, yaml.safe_dump(GANTRY)),
                           (int(stamps[50]) - 1, yaml.safe_dump(later)),
                           (int(stamps[-1]) + 1000, yaml.safe_dump(dict(GANTRY, name='after')))])

    class Observer:
        def __init__(self):
            self.layouts, self.blocks = [], []

        def layout(self, stamp, model, segment_start_ns):
            self.layouts.append((stamp, model.layout.name, segment_start_ns))

        def samples(self, stamp, angle, omega, alpha, result):
            self.blocks.append((stamp, angle, omega, alpha))
    observer = Observer()
    started = time.perf_counter()
    summary = replay(bag, observer=observer)
    assert 0.0 < summary.seconds <= time.perf_counter() - started
    assert observer.layouts == [(int(stamps[0]), 'unused', unused),
                                (int(stamps[0]), GANTRY['name'], first),
                                (int(stamps[50]), 'later', int(stamps[50]) - 1),
                                (int(stamps[-1]) + 1000, 'after', int(stamps[-1]) + 1000)]
    got = [np.concatenate([s[k] for s in observer.blocks]) for k in range(4)]
    assert got[0].tolist() == stamps.tolist()
    assert np.array_equal(got[1], angle) and np.array_equal(got[2], omega)
    # the ramp's 2 rad/s^2: the estimate's slope, exact from the second sample on
    np.testing.assert_allclose(got[3][1:], 2.0, rtol=1e-9)
    assert [(s.first_ns, s.last_ns, s.samples) for s in summary.segments] == \
        [(None, None, 0), (int(stamps[0]), int(stamps[49]), 50),
         (int(stamps[50]), int(stamps[-1]), 50), (None, None, 0)]


def test_the_output_chunks_are_zstd_at_replays_level(replayed, tmp_path):
    """Each chunk of the output: zstandard's compression of its records at level -7."""
    import zstandard
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    stamps, _, _, _ = replayed
    out = tmp_path / 'out.mcap'
    bag = write_input_bag(tmp_path / 'in.mcap', stamps, *ramp(1.0, 2.0, rate=200.0,
                                                              seconds=1.0)[1:],
                          [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    replay(bag, out)
    with open(out, 'rb') as stream:
        chunks = [r for r in StreamReader(stream, emit_chunks=True).records
                  if isinstance(r, Chunk)]
    assert chunks and {c.compression for c in chunks} == {'zstd'}
    for chunk in chunks:
        records = zstandard.ZstdDecompressor().decompress(
            chunk.data, max_output_size=chunk.uncompressed_size)
        assert chunk.data == zstandard.ZstdCompressor(level=-7).compress(records)
        assert chunk.data != zstandard.ZstdCompressor(level=1).compress(records)


def test_stamps_whose_nanoseconds_are_not_below_a_second_are_rejected(tmp_path):
    """
    Reject a JointState whose stamp's nanosec is 10^9 or more, as any stamp not set.

    builtin_interfaces/msg/Time: nanosec is below 10^9. Of 12 JointStates 5 ms apart (log
    times as their stamps), the first stamped (4 s, 10^9 ns) (which read as a sum is the
    second's 5 s) and the seventh (5 s, 2^32 - 1 ns): 12 samples, 10 accepted, 2 rejected.
    """
    stamps = 5 * 10**9 + 5_000_000 * np.arange(12)
    header_stamps = [divmod(int(ns), 10**9) for ns in stamps]
    header_stamps[0], header_stamps[6] = (4, 10**9), (5, 2**32 - 1)
    messages = [(['gantry_joint'], [0.01 * k], [2.0]) for k in range(12)]
    bag = joint_bag(tmp_path / 'stamps.mcap', stamps, messages, header_stamps)
    summary = replay(bag)
    assert (summary.samples, summary.accepted, summary.rejected) == (12, 10, 2)


def test_the_observer_of_a_what_if_layout_sees_it_from_before_the_bag(tmp_path):
    """
    Give the observer a layout file's layout as in force from before the bag (0).

    With samples: the first sample's stamp and 0; with no sample at all: 0 and 0.
    """
    class Observer:
        def __init__(self):
            self.layouts = []

        def layout(self, stamp, model, segment_start_ns):
            self.layouts.append((stamp, model.layout.name, segment_start_ns))

        def samples(self, *_):
            pass
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=0.1)
    layout = [(int(stamps[0]) - 1000, yaml.safe_dump(dict(GANTRY, name='in the bag')))]
    for path, first in ((write_input_bag(tmp_path / 'in.mcap', stamps, angle, omega, layout),
                         int(stamps[0])),
                        (write_input_bag(tmp_path / 'none.mcap', [], [], [], layout), 0)):
        observer = Observer()
        replay(path, layout_file=GANTRY_FILE, observer=observer)
        assert observer.layouts == [(first, GANTRY['name'], 0)], path.name


def test_the_output_chunks_hold_up_to_4_mib(tmp_path):
    """
    Hold 2000 samples' outputs (over 1 MiB) in one chunk: replay's chunks are 4 MiB.

    Five WrenchStamped a sample (the bearing, two supports, the unbalance, the drive
    torque), each record 9 + 22 + 76 bytes by hand (CDR: encapsulation 4, stamp 8, frame
    4 + 'stator' or 'rotor' with its NUL, padded to 8, six float64): 535 bytes a sample,
    1,070,000 bytes in all, which the mcap library finds in one chunk.
    """
    stamps, angle, omega = ramp(1.0, 0.5, rate=200.0, seconds=10.0)
    bag = write_input_bag(tmp_path / 'in.mcap', stamps, angle, omega,
                          [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    replay(bag, tmp_path / 'out.mcap', compression='')       # not compressed: faster
    types = TYPESTORE.types
    for frame in ('stator', 'rotor'):
        empty = types[WRENCH](header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=0, nanosec=0), frame_id=frame),
            wrench=types['geometry_msgs/msg/Wrench'](
                force=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
                torque=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)))
        assert len(TYPESTORE.serialize_cdr(empty, WRENCH)) == 76
    with open(tmp_path / 'out.mcap', 'rb') as stream:
        summary = make_reader(stream).get_summary()
    assert len(stamps) == 2000 and summary.statistics.message_count == 5 * 2000 + 1
    assert 5 * 2000 * (9 + 22 + 76) == 1_070_000 > 1 << 20
    assert max(i.uncompressed_size for i in summary.chunk_indexes) >= 1_070_000


def test_rejected_layout_messages_beyond_five_are_counted():
    """Say seven rejected layout messages: the first five one by one, then all seven counted."""
    from cvc_balance.bag.replay import layouts_in_force
    messages = [(10**9, yaml.safe_dump(GANTRY))] + \
        [(k * 10**9, 'components: [') for k in range(2, 9)]
    events, problems = layouts_in_force(None, messages)
    assert len(events) == 1 and len(problems) == 6
    assert all(p.startswith(f'layout at {k}.000 s rejected (previous stays in force): ')
               for k, p in zip(range(2, 7), problems))
    assert problems[5] == '7 layout messages rejected in all (the first 5 said above)'
