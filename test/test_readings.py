"""
``cvc-balance readings``: 1x readings of vibration channels against a keyphasor, from bags.

A simulated rig with no encoder: a tach and accelerometers only. The truth is the angle
theta(t) written here (30 rev/s, a ramp, 36 rev/s) and the 1x each channel was given (its
amplitude grows as the speed squared; its phase lag, the angle turned after the mark to
its positive peak); the readings are also checked against a plain least-squares fit of
c + a cos theta + b sin theta with the TRUE angle, written here (not the project's order
tracker). The messages are serialised by rosbags and read back by rosbags too.
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from cvc_balance.bag.channels import (channel_samples, keyphasor_motion, read_keyphasor,
                                      time_reference_marks, vibration_channels)
from cvc_balance.bag.mcap_writer import BagWriter
from cvc_balance.bag.readings import bag_readings
from cvc_balance.bag.rosbag2 import open_bag
from in_process import cvc

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
START_NS = 1_700_000_000 * 10 ** 9
FIRST, SECOND = 2 * math.pi * 30.0, 2 * math.pi * 36.0     # rad/s
STEADY, RAMP = 2.0, 1.0                                     # s
TACH_RATE, ACCEL_RATE = 600.0, 1000.0                       # Hz: 20 and 16.7 samples a turn
AMPLITUDE, LAG_DEG = 0.5, 70.0         # accel's 1x at FIRST (m/s^2), lag from the mark
Y_LAG_DEG = LAG_DEG + 90.0             # a y axis, a quarter turn later
NOISE = 0.1
GLITCHES = (1.0, 4.0)                  # s: a tach pulse unseen, and a spike, both steady


def theta(t):
    """Return the rotor's true angle (rad) at ``t`` (s after the start)."""
    t = np.asarray(t, float)
    alpha = (SECOND - FIRST) / RAMP
    ramp = np.clip(t - STEADY, 0.0, RAMP)
    after = np.clip(t - STEADY - RAMP, 0.0, None)
    return FIRST * np.minimum(t, STEADY) + FIRST * ramp + 0.5 * alpha * ramp ** 2 \
        + SECOND * after


def speed(t):
    """Return the rotor's true speed, rad/s."""
    return np.interp(t, [STEADY, STEADY + RAMP], [FIRST, SECOND])


def mark_times(duration):
    """Return the true marks (theta = 2 pi k) up to ``duration``, s, by bisection."""
    k = np.arange(1, int(theta(duration) / (2 * math.pi)) + 1)
    lo, hi = np.zeros(len(k)), np.full(len(k), duration)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = theta(mid) < 2 * math.pi * k
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def tach_signal(t):
    """Return an analog pick-up, 0-5 V: a linear edge over about 3 samples at each mark."""
    wrapped = np.mod(theta(t) + math.pi, 2 * math.pi) - math.pi
    edge = 3.0 * speed(t) / TACH_RATE
    volts = 5.0 * np.clip(0.5 + wrapped / edge, 0.0, 1.0)
    volts *= wrapped < 2.0                  # the strip is 1.2 rad wide
    marks = mark_times(t[-1])
    unseen = (t > marks[29] - 0.004) & (t < marks[29] + 0.02)      # t ~ 1.0 s: missed
    volts[unseen & (theta(t) > 29 * 2 * math.pi)] = 0.0
    dark = np.flatnonzero((t > GLITCHES[1]) & (wrapped > 2.6) & (wrapped < 3.0))[0]
    volts[dark] = 5.0                                 # a one-sample spike mid-turn: doubled
    return volts


def one_x(t, lag_deg):
    """Return a 1x growing as the speed squared, peaking ``lag_deg`` after the mark."""
    return AMPLITUDE * (speed(t) / FIRST) ** 2 * np.cos(theta(t) - math.radians(lag_deg))


def header(ns):
    time_type = TYPESTORE.types['builtin_interfaces/msg/Time']
    stamp = time_type(sec=int(ns) // 10 ** 9, nanosec=int(ns) % 10 ** 9)
    return TYPESTORE.types['std_msgs/msg/Header'](stamp=stamp, frame_id='bearing_front')


def serialized(msg, msg_type):
    return TYPESTORE.serialize_cdr(msg, msg_type).tobytes()


def write_rig_bag(path, seed=5):
    """
    Write the rig's run and return its path.

    /keyphasor (Float64), /marks (TimeReference), /accel (Float64), /accel3
    (Vector3Stamped) and /imu (Imu) with the same x, y, z; no joint_states.
    """
    duration = 2 * STEADY + RAMP
    rng = np.random.default_rng(seed)
    types = {name: TYPESTORE.types[name] for name in (
        'std_msgs/msg/Float64', 'geometry_msgs/msg/Vector3Stamped', 'sensor_msgs/msg/Imu',
        'sensor_msgs/msg/TimeReference', 'geometry_msgs/msg/Vector3',
        'geometry_msgs/msg/Quaternion', 'builtin_interfaces/msg/Time')}
    t_tach = np.arange(0.0, duration, 1.0 / TACH_RATE)
    t_acc = np.arange(0.0, duration, 1.0 / ACCEL_RATE) + 0.0003
    x = 0.02 + one_x(t_acc, LAG_DEG) + 0.2 * np.cos(2 * theta(t_acc) + 0.3) \
        + rng.normal(0.0, NOISE, len(t_acc))
    y = one_x(t_acc, Y_LAG_DEG) + rng.normal(0.0, NOISE, len(t_acc))
    z = 9.81 + rng.normal(0.0, NOISE, len(t_acc))
    with BagWriter(path, chunk_bytes=16384) as writer:
        tach = writer.add_channel('/keyphasor', 'std_msgs/msg/Float64', best_effort=True)
        marks = writer.add_channel('/marks', 'sensor_msgs/msg/TimeReference')
        accel = writer.add_channel('/accel', 'std_msgs/msg/Float64', best_effort=True)
        accel3 = writer.add_channel('/accel3', 'geometry_msgs/msg/Vector3Stamped')
        imu = writer.add_channel('/imu', 'sensor_msgs/msg/Imu')
        for s, v in zip(t_tach, tach_signal(t_tach)):
            writer.write(tach, START_NS + int(round(s * 1e9)), serialized(
                types['std_msgs/msg/Float64'](data=float(v)), 'std_msgs/msg/Float64'))
        for s in mark_times(duration):
            ns = START_NS + int(round(s * 1e9))
            writer.write(marks, ns + 1_000_000, serialized(types['sensor_msgs/msg/TimeReference'](
                header=header(ns + 1_000_000), time_ref=types['builtin_interfaces/msg/Time'](
                    sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), source='pick-up'),
                'sensor_msgs/msg/TimeReference'))
        vector = types['geometry_msgs/msg/Vector3']
        for s, a, b, c in zip(t_acc, x, y, z):
            ns = START_NS + int(round(s * 1e9))
            writer.write(accel, ns, serialized(types['std_msgs/msg/Float64'](data=float(a)),
                                               'std_msgs/msg/Float64'))
            writer.write(accel3, ns, serialized(types['geometry_msgs/msg/Vector3Stamped'](
                header=header(ns), vector=vector(x=float(a), y=float(b), z=float(c))),
                'geometry_msgs/msg/Vector3Stamped'))
            writer.write(imu, ns, serialized(types['sensor_msgs/msg/Imu'](
                header=header(ns), orientation=types['geometry_msgs/msg/Quaternion'](
                    x=0.1, y=0.2, z=0.3, w=0.9),
                orientation_covariance=rng.normal(size=9),
                angular_velocity=vector(x=1.5, y=-2.5, z=188.0),
                angular_velocity_covariance=rng.normal(size=9),
                linear_acceleration=vector(x=float(a), y=float(b), z=float(c)),
                linear_acceleration_covariance=rng.normal(size=9)), 'sensor_msgs/msg/Imu'))
    return path


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    return write_rig_bag(tmp_path_factory.mktemp('rig') / 'rig.mcap')


def cli(*args):
    return subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *map(str, args)],
                          capture_output=True, text=True)


def here(*args):
    return cvc(*args)        # in this process (test/in_process.py): no Python start-up


def independent_fit(times_ns, values, start, end):
    """
    Return (amplitude, lag deg) of a plain least-squares fit with the TRUE angle.

    c + a cos theta + b sin theta over [start, end) s since the epoch.
    """
    seconds = (np.asarray(times_ns) - START_NS) * 1e-9
    inside = (seconds + START_NS * 1e-9 >= start) & (seconds + START_NS * 1e-9 < end)
    q = theta(seconds[inside])
    design = np.column_stack([np.ones(inside.sum()), np.cos(q), np.sin(q)])
    (_, a, b), *_ = np.linalg.lstsq(design, values[inside], rcond=None)
    return math.hypot(a, b), math.degrees(math.atan2(b, a)) % 360.0


def rosbags_channels(path):
    """
    Return {topic: (times ns, values (n, k))} as rosbags reads them.

    Float64 at log times, the stamped ones at their header stamps, TimeReference's time_ref.
    """
    from rosbags.highlevel import AnyReader
    from pathlib import Path
    out = {}
    with AnyReader([Path(path)]) as reader:
        for connection, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.msgtype == 'std_msgs/msg/Float64':
                row = (log_time, [msg.data])
            elif connection.msgtype == 'sensor_msgs/msg/TimeReference':
                row = (msg.time_ref.sec * 10 ** 9 + msg.time_ref.nanosec, [])
            else:
                v = msg.vector if hasattr(msg, 'vector') else msg.linear_acceleration
                row = (msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec,
                       [v.x, v.y, v.z])
            out.setdefault(connection.topic, []).append(row)
    return {topic: (np.array([r[0] for r in rows]), np.array([r[1] for r in rows]))
            for topic, rows in out.items()}


def test_channels_decode_as_rosbags_reads_them(rig):
    bag = open_bag(rig)
    sources = vibration_channels(bag, {'accel': 'm/s^2'})
    assert [(s.name, s.unit) for s in sources] == [
        ('accel', 'm/s^2'), ('accel3/x', 'as recorded'), ('accel3/y', 'as recorded'),
        ('accel3/z', 'as recorded'), ('imu/x', 'm/s^2'), ('imu/y', 'm/s^2'), ('imu/z', 'm/s^2')]
    truth = rosbags_channels(rig)
    cache = {}
    for source in sources:
        got = channel_samples(bag, source, cache)
        times, values = truth['/' + source.name.split('/')[0]]
        assert got.rejected == 0
        assert np.array_equal(got.time, times)
        assert np.array_equal(got.values, values[:, source.axis or 0])
    marks, rejected = time_reference_marks(bag, bag.channel('/marks',
                                                            'sensor_msgs/msg/TimeReference'))
    assert rejected == 0 and np.array_equal(marks, truth['/marks'][0])


def test_vector3_and_imu_channels_read_as_their_float64(rig):
    readings = bag_readings(rig)
    assert len(readings.segments) == 2
    for segment in readings.segments:
        by_name = {c.name: c for c in segment.channels}
        for twin in ('accel3/x', 'imu/x'):
            assert by_name[twin].phasor == by_name['accel'].phasor
        assert by_name['accel3/y'].phasor == by_name['imu/y'].phasor
        assert by_name['accel3/z'].phasor == by_name['imu/z'].phasor


def test_readings_are_the_true_1x_and_an_independent_fit(rig):
    readings = bag_readings(rig)
    truth = rosbags_channels(rig)
    times, values = truth['/accel']
    first, second = readings.segments
    # The stretches: the two steady speeds, not the ramp between them (2-3 s).
    assert first.start - START_NS * 1e-9 < 0.05 and first.end - START_NS * 1e-9 <= STEADY + 0.15
    assert second.start - START_NS * 1e-9 >= STEADY + RAMP - 0.05   # +-1 %: 2.97 s
    assert first.revolutions >= 50 and second.revolutions >= 60
    for segment, omega in zip(readings.segments, (FIRST, SECOND)):
        turned = theta(segment.end - START_NS * 1e-9) - theta(segment.start - START_NS * 1e-9)
        assert segment.revolutions == round(turned / (2 * math.pi))
        # The mean speed over it (the second holds 0.03 s of the ramp's end, within 1 %).
        assert segment.speed == pytest.approx(turned / (segment.end - segment.start), rel=1e-6)
        assert segment.speed == pytest.approx(omega, rel=1e-4)
        by_name = {c.name: c for c in segment.channels}
        expected = AMPLITUDE * (omega / FIRST) ** 2
        # What is not 1x: the noise, and on x a 2x of 0.2 (rms 0.2 / sqrt 2).
        for name, lag, rest in (('accel', LAG_DEG, math.hypot(NOISE, 0.2 / math.sqrt(2))),
                                ('accel3/y', Y_LAG_DEG, NOISE)):
            reading = by_name[name]
            error = abs(reading.amplitude * np.exp(1j * math.radians(reading.phase_deg))
                        - expected * np.exp(1j * math.radians(lag)))
            assert error <= reading.ci95          # the truth inside the 95 % circle
            # The radius: 2.448 standard errors of a phasor from n samples, rms r each.
            assert reading.ci95 == pytest.approx(
                2.448 * rest * math.sqrt(2.0 / reading.samples), rel=0.1)
        fit_amplitude, fit_lag = independent_fit(times, values[:, 0], segment.start,
                                                 segment.end)
        assert by_name['accel'].amplitude == pytest.approx(fit_amplitude, rel=1e-5)
        # The angle is linear between marks: off a little on the ramp's end (0.0018 deg).
        assert abs((by_name['accel'].phase_deg - fit_lag + 180) % 360 - 180) <= 5e-3
        assert by_name['accel3/z'].amplitude <= by_name['accel3/z'].ci95


def test_a_time_reference_and_a_float64_keyphasor_give_the_same_readings(rig):
    signal, marks = bag_readings(rig), bag_readings(rig, keyphasor='marks', threshold=2.5)
    assert marks.problems == ['keyphasor /marks is sensor_msgs/msg/TimeReference (one message '
                              'a mark): the threshold given applies to a sampled tach only; '
                              'ignored']
    assert signal.keyphasor.marks.missed == 1 and signal.keyphasor.marks.doubled == 1
    assert marks.keyphasor.marks.missed == marks.keyphasor.marks.doubled == 0
    assert len(signal.segments) == len(marks.segments) == 2
    for a, b in zip(signal.segments, marks.segments):
        assert (a.revolutions, len(a.channels)) == (b.revolutions, len(b.channels))
        assert a.start == pytest.approx(b.start, abs=1e-6)
        for x, y in zip(a.channels, b.channels):
            assert x.name == y.name
            assert x.amplitude == pytest.approx(y.amplitude, rel=1e-5)
            assert abs((x.phase_deg - y.phase_deg + 180) % 360 - 180) <= 1e-3


def test_the_keyphasor_gives_motion_samples_as_the_encoder_does(rig):
    bag = open_bag(rig)
    motion = keyphasor_motion(bag)
    t = (motion.stamp - START_NS) * 1e-9
    error = np.angle(np.exp(1j * (motion.angle - theta(t))))
    steady = (t < STEADY) | (t > STEADY + RAMP)
    # The edge is timed exactly; the speed at a mark is fitted over 8 revolutions about it,
    # so 5 revolutions (0.17 s) from the ramp the speeds, and the angle, are exact.
    settled = (t < STEADY - 0.17) | (t > STEADY + RAMP + 0.17)
    assert np.max(np.abs(error[settled])) <= 1e-5          # rad
    assert np.max(np.abs(error)) <= 0.01       # measured 0.0041 beside the ramp's ends
    assert np.max(np.abs(motion.omega[steady] / speed(t[steady]) - 1.0)) <= 0.02
    assert 'keyphasor /keyphasor: ' in motion.problems[0] and '1 missed' in motion.problems[0]
    assert motion.reasons[0].endswith(' keyphasor samples before the first mark, after the '
                                      'last or inside an irregular period: no angle there')
    timed = keyphasor_motion(bag, 'marks', samples_per_rev=16)
    assert len(timed.stamp) == 16 * read_keyphasor(bag, 'marks').marks.revolutions + 1
    t = (timed.stamp - START_NS) * 1e-9
    assert np.max(np.abs(np.angle(np.exp(1j * (timed.angle - theta(t)))))[
        (t < STEADY - 0.17) | (t > STEADY + RAMP + 0.17)]) <= 1e-5


def test_the_command_prints_what_people_read(rig):
    done = cli('readings', rig, '--channel-unit', 'accel=m/s^2', '--channel-unit', 'accel3=g')
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == f'bag {rig}'
    # 163 crossings seen, one pulse unseen, one spike: 164 raw marks, 163 revolutions.
    assert lines[1] == ('keyphasor /keyphasor: 164 marks, 1 missed (put back), 1 doubled '
                        '(dropped), 0 irregular periods (no angle there), 163 revolutions')
    stretch = [line for line in lines if ' rad/s (' in line]
    assert len(stretch) == 2 and stretch[0].endswith('rpm), 59 revolutions')
    assert ' 188.5 rad/s (1800 rpm)' in stretch[0]
    accel = [line.split() for line in lines if line.split()[:1] == ['accel']]
    assert [float(a[1]) for a in accel] == pytest.approx([0.5, 0.72], rel=0.05)
    assert [float(a[2]) for a in accel] == pytest.approx([LAG_DEG, LAG_DEG], abs=2.0)
    assert [a[-1] for a in accel] == ['m/s^2', 'm/s^2']
    assert [line.split()[-1] for line in lines if line.startswith('  accel3/')] == ['g'] * 6
    done = here('readings', rig, '--json')
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert list(summary) == ['segments']
    assert [list(s) for s in summary['segments']] == \
        [['from', 'to', 'speed', 'revolutions', 'channels']] * 2
    assert [list(c) for c in summary['segments'][0]['channels']] == \
        [['name', 'unit', 'amplitude', 'phase_deg', 'ci95']] * 7
    assert all(0.0 <= c['phase_deg'] < 360.0 for s in summary['segments']
               for c in s['channels'])
    assert done.stderr.strip() == ('cvc-balance: warning: keyphasor /keyphasor: 164 marks, 1 '
                                   'missed (put back), 1 doubled (dropped), 0 irregular '
                                   'periods (no angle there), 163 revolutions')


@pytest.mark.parametrize('args, needles', [
    (['--keyphasor', 'tach'], ['no keyphasor topic tach (given with --keyphasor)', '/accel3']),
    (['--keyphasor', 'accel3'], ['keyphasor topic /accel3 has type geometry_msgs/msg/Vector3',
                                 'expected std_msgs/msg/Float64']),
    (['--channel-unit', 'accel'], ["--channel-unit 'accel': give TOPIC=UNIT"]),
    (['--channel-unit', 'tach=g'], ['--channel-unit names tach, no vibration channel',
                                    'accel, accel3, imu']),
    (['--keyphasor-threshold', '9'], ['keyphasor /keyphasor gives 0 marks']),
    (['--speed-tolerance', '0'], ['--speed-tolerance: must be from 0.001 to 100 % (of the '
                                  'speed), got 0 %']),
])
def test_bad_input_is_one_line_and_exit_2(rig, args, needles):
    done = here('readings', rig, *args)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in done.stderr, done.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
