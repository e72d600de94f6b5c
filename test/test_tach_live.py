"""
The node on a tach (parameter keyphasor_topic) against offline replay of the same bag.

Issue 26: the node took an encoder (joint_states) or a speed only. Live, a tach's marks
can only be checked looking back (a missed mark is a period about twice the expected
one, a doubled one two periods that make one) and the angle between marks can only be
extrapolated from the marks before; replay interpolates between marks on both sides. The
run of test/tach_bags.py (its angle known in closed form) is fed to the node in this
process, each sample at its bag time (as its receive time: no DDS jitter), and to the
node as its own process by ``cvc-balance play``.

What live extrapolation costs (measured in brackets, the stated bounds asserted):

* a sampled tach with an exact edge: where the speed is steady or changes at a constant
  acceleration the live angle and speed are those of the marks, exact (1e-5 rad,
  1e-4 rad/s: an edge linear in angle timed linearly in time on a ramp) [4.5e-6];
  in the revolutions after a change of acceleration the fit of the last revolutions
  extrapolates the old one: the angle is off by up to 0.3 rad, 0.05 rad rms over the run
  [0.226, 0.035], where replay's interpolation is off by 0.028 rad, 0.0063 rms;
* the node's bearing loads equal replay's to 1e-8 of the peak in the steady stretch
  (8 revolutions and 1 s after the spin-up) [5.4e-9, the alpha estimate forgetting the
  spin-up's differences], to 2e-3 of it everywhere both give one [1.4e-3]; a
  TimeReference tach's (one revolution late, interpolated as replay does) to 1e-3
  [4.7e-4], every replay sample's stamp given live too;
* a coarse 0/1 tach (18 samples a revolution) read live: the marks are replay's, the
  angle 30 deg at worst, 7 deg rms [28, 5.9] where replay's is 10.2 and 4.8.
"""

import math
from pathlib import Path
import re
import signal
import subprocess
import sys
from unittest import mock

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
import yaml

from cvc_balance.bag.channels import keyphasor_motion
from cvc_balance.bag.mcap_reader import Bag, wrench_samples
from cvc_balance.bag.replay import replay
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.bag.scenario import exact_motion
from cvc_balance.messages.cdr import read_wrench_stamped
from cvc_balance.physics.keyphasor import (checked_marks, LEVEL_FIRST, LiveMarks, LiveSignal,
                                           signal_marks)
from cvc_balance.ros.balance_monitor import BalanceMonitor
from ros_harness import DOMAIN_ID, NodeProcess, ros_environment
import tach_bags

ROOT = Path(__file__).resolve().parents[1]
SETTLED = (5.82 + 8 * 0.27 + 1.0, 10.82 - 5 * 0.27 - 0.05)
"""
s after the start: the steady stretch, 8 revolutions (the live fit's) and 1 s (the alpha
estimate's memory) after the spin-up ends, 5 revolutions (replay's) before it ends.
"""


# -- the marks, live ------------------------------------------------------------------

RATE, SPEED, ALPHA = 952.0, 2 * math.pi * 52.3, 3.0       # test_keyphasor's coarse tach


def theta(t):
    """Return the rotor's true angle (rad) at ``t`` s."""
    return SPEED * t + 0.5 * ALPHA * t * t


def true_marks(duration):
    """Return the times (s) where theta = 2 pi k, k >= 1, solved by hand."""
    k = np.arange(1, int(theta(duration) / (2 * math.pi)) + 1)
    return (-SPEED + np.sqrt(SPEED * SPEED + 4 * math.pi * ALPHA * k)) / ALPHA


def live(marks_in):
    """Feed mark times to LiveMarks; return it and the good periods it gave."""
    marks, periods = LiveMarks(), []
    for t in marks_in:
        periods += marks.mark(t) or []
    return marks, periods


def test_missed_and_doubled_marks_are_counted_live_as_replay_counts_them():
    truth = true_marks(4.0)
    taken = np.delete(truth, [60, 130, 131])         # one mark missed, then two in a row
    period = np.diff(truth)
    extra = [truth[90] + 0.45 * period[90], truth[170] + 0.3 * period[170]]   # doubled
    given = np.sort(np.concatenate([taken, extra]))
    marks, periods = live(given)
    batch = checked_marks(given)
    assert (marks.found, marks.missed, marks.doubled, marks.irregular) == \
        (len(given), 3, 2, 0) == (batch.found, batch.missed, batch.doubled, batch.irregular)
    # The good periods given are the true ones, the extra marks dropped, the missed ones
    # put back evenly: on this ramp off by the bow of the angle over the gap P, by hand
    # alpha P^2 / (8 omega) for two periods, less than alpha P^2 / (4 omega) for three
    # (7.4e-6 s; measured 3.1e-6).
    ends = np.array([p[1] for p in periods])
    assert len(ends) == len(truth) - 1 == marks.revolutions
    gap = truth[132] - truth[129]
    assert np.max(np.abs(ends - truth[1:])) <= ALPHA * gap ** 2 / (4 * SPEED)
    assert np.max(np.abs(np.delete(ends - truth[1:], [59, 129, 130]))) <= 1e-12
    # The speed at each mark: the constant-acceleration fit, exact on this ramp once the
    # run holds three marks (the first period's is its mean speed) and away from the
    # marks put back (the 8 revolutions after them).
    speeds = np.array([p[3] for p in periods])
    exact = SPEED + ALPHA * ends
    away = np.ones(len(ends), bool)
    away[:2] = away[59:68] = away[129:139] = False
    assert np.max(np.abs(speeds - exact)[away]) <= 1e-6


def test_an_irregular_period_restarts_the_marks_and_a_silence_is_said():
    truth = true_marks(2.0)
    moved = truth.copy()
    moved[40] += 0.4 * (truth[41] - truth[40])       # 40 % late: neither x2 nor /2
    marks = LiveMarks()
    for t in moved[:41]:
        marks.mark(t)
    assert marks.irregular == 1 and not marks.ready
    assert marks.motion_at(moved[40] + 1e-3) == 'keyphasor: learning the period (1 marks of 4)'
    for t in moved[41:45]:
        marks.mark(t)
    assert marks.ready and marks.irregular == 2       # 40 -> 41 short: learnt from 41 on
    angle, omega = marks.motion_at(moved[44] + 0.005)
    assert angle == pytest.approx(theta(moved[44] + 0.005) - theta(moved[44]), abs=1e-6)
    assert omega == pytest.approx(SPEED + ALPHA * (moved[44] + 0.005), abs=1e-5)
    silent = moved[44] + 3.3 * (truth[44] - truth[43])
    assert marks.motion_at(silent) == f'keyphasor: no mark for {silent - moved[44]:.3g} s ' \
        '(the rotor stopped?)'
    assert not marks.ready and marks.irregular == 3


@pytest.mark.parametrize('kind', ['binary', 'edge'])
def test_a_coarse_tach_live_gives_replays_marks(kind):
    t = np.arange(0.0, 6.0, 1.0 / RATE)
    if kind == 'binary':
        values = (np.mod(theta(t), 2 * math.pi) < math.pi / 3).astype(float)
    else:
        wrapped = np.mod(theta(t) + math.pi, 2 * math.pi) - math.pi
        values = 5.0 * np.clip(0.5 + wrapped / (3 * SPEED / RATE), 0.0, 1.0)
    tach, marks, found = LiveSignal(), LiveMarks(), []
    angle = np.full(len(t), np.nan)
    for k, (time, value) in enumerate(zip(t, values)):
        mark = tach.sample(time, value)
        if mark is not None:
            found.append(mark)
            marks.mark(mark, tach.spacing)
        motion = marks.motion_at(time)
        if not isinstance(motion, str):
            angle[k] = motion[0]
    batch = signal_marks(t, values)
    # The same crossings, once the levels are known (the first LEVEL_FIRST samples).
    assert np.array_equal(np.array(found), batch[batch > t[LEVEL_FIRST - 1]])
    offline = checked_marks(batch).motion(t)[0]
    ok = np.isfinite(angle)
    error = np.degrees(np.abs(np.angle(np.exp(1j * (angle[ok] - theta(t[ok]))))))
    offline_error = np.degrees(np.abs(np.angle(np.exp(1j * (offline - theta(t))))))
    offline_error = offline_error[np.isfinite(offline_error)]
    if kind == 'edge':
        assert error.max() <= 1e-3 and offline_error.max() <= 1e-3
    else:
        assert error.max() <= 30.0 and np.sqrt(np.mean(error ** 2)) <= 7.0
        assert offline_error.max() <= 10.5 and np.sqrt(np.mean(offline_error ** 2)) <= 5.0


# -- the node in this process -----------------------------------------------------------

@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """Write the run with a sampled tach and with a TimeReference tach; replay both."""
    folder = tmp_path_factory.mktemp('tach_live')
    run, _, sampled = tach_bags.write_run(folder, ROOT)
    _, _, marked = tach_bags.write_run(folder, ROOT, tach='time_reference')
    layout = folder / 'layout.yaml'
    layout.write_text(yaml.safe_dump(run.layouts[0][1]))
    offline = {}
    for name, bag in (('float64', sampled), ('time_reference', marked)):
        replay(bag, folder / f'{name}_offline.mcap')
        offline[name] = bearing_loads(folder / f'{name}_offline.mcap')
    return run, layout, {'float64': sampled, 'time_reference': marked}, offline


def bearing_loads(path):
    """(stamps ns, force (n, 3)) of /bearing_load in a bag."""
    bag = Bag(path)
    channel = next(c for c in bag.channels.values() if c.topic == '/bearing_load')
    stamps, force, _ = wrench_samples(bag, channel)
    return stamps, force


def node_on(bag, layout, kind):
    """
    Feed ``bag``'s /keyphasor to a node made here, each message at its log time.

    Return (bearing load stamps ns, forces, motion samples [(stamp ns, angle, omega)],
    the node's keyphasor values, its diagnostics after the run).
    """
    captured, motion = [], []
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    with mock.patch.object(Publisher, 'publish',
                           lambda self, msg: captured.append((self.topic_name, msg))):
        node = BalanceMonitor(context=context, parameter_overrides=[
            Parameter('layout_file', value=str(layout)),
            Parameter('keyphasor_topic', value='keyphasor')])
        try:
            node._keyphasor.subscribe(tach_bags.TYPES[kind])
            process = node._process

            def spy(sec, nanosec, angle, omega, received=None):
                motion.append((sec * 10 ** 9 + nanosec, angle, omega))
                return process(sec, nanosec, angle, omega, received)
            node._process = spy
            source = Bag(bag)
            channel = next(c for c in source.channels.values() if c.topic == '/keyphasor')
            for log_time, data in source.messages(channel):
                if kind == 'float64':
                    node._keyphasor.float64(data, log_time, log_time * 1e-9)
                else:
                    node._keyphasor.time_reference(data, log_time * 1e-9)
            node._publish_diagnostics()
            values = node._keyphasor.values()
            assert node._internal_errors == 0, node._last_rejection
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=context)
    loads = [read_wrench_stamped(m) for topic, m in captured if topic == '/bearing_load']
    stamps = np.array([sec * 10 ** 9 + nanosec for sec, nanosec, _, _ in loads])
    arrays = [m for topic, m in captured if topic == '/diagnostics']
    return (stamps, np.array([force for _, _, force, _ in loads]), np.array(motion), values,
            arrays[-1])


def compare(live_loads, offline_loads, run):
    """Return (relative differences at the common stamps, their times s after the start)."""
    (stamps, force), (offline_stamps, offline_force) = live_loads, offline_loads
    common, here, there = np.intersect1d(stamps, offline_stamps, return_indices=True)
    peak = np.linalg.norm(offline_force, axis=1).max()
    return (np.linalg.norm(force[here] - offline_force[there], axis=1) / peak,
            common * 1e-9 - run.start)


def test_the_node_on_a_sampled_tach_agrees_with_replay(runs):
    run, layout, bags, offline = runs
    stamps, force, motion, values, array = node_on(bags['float64'], layout, 'float64')
    difference, t = compare((stamps, force), offline['float64'], run)
    assert len(t) >= 0.8 * len(offline['float64'][0])
    settled = (t > SETTLED[0]) & (t < SETTLED[1])
    assert settled.sum() > 300
    assert difference[settled].max() <= 1e-8
    assert difference.max() <= 2e-3
    # The cost of extrapolating, against the angle in closed form, beside replay's.
    t = motion[:, 0] * 1e-9 - run.start
    angle, omega, alpha = exact_motion(run.pieces, t)
    error = np.abs(np.angle(np.exp(1j * (motion[:, 1] - angle))))
    constant = np.ones(len(t), bool)              # 8 revolutions from a change of alpha
    for change in np.cumsum([duration for duration, _ in run.pieces])[:-1]:
        constant &= (t < change) | (t > change + 8 * 0.27 + 0.3)
    assert error[constant].max() <= 1e-5
    assert np.abs(motion[constant, 2] - omega[constant]).max() <= 1e-4
    assert error.max() <= 0.3 and np.sqrt(np.mean(error ** 2)) <= 0.05
    replayed = keyphasor_motion(open_bag(bags['float64']))
    exact = exact_motion(run.pieces, replayed.stamp * 1e-9 - run.start)[0]
    error = np.abs(np.angle(np.exp(1j * (replayed.angle - exact))))
    assert error.max() <= 0.03 and np.sqrt(np.mean(error ** 2)) <= 0.007
    assert values['keyphasor'] == '/keyphasor (std_msgs/msg/Float64)'
    assert (values['keyphasor missed (put back)'], values['keyphasor doubled (dropped)']) == \
        (0, 0)
    said = {kv.key: kv.value for kv in array.status[0].values}
    assert said['keyphasor marks'] == str(len(tach_bags.mark_times(run)))


def test_the_node_on_a_time_reference_tach_gives_replays_samples(runs):
    run, layout, bags, offline = runs
    stamps, force, _, values, _ = node_on(bags['time_reference'], layout, 'time_reference')
    assert np.isin(offline['time_reference'][0], stamps).all()     # every replay sample
    difference, t = compare((stamps, force), offline['time_reference'], run)
    assert difference.max() <= 1e-3
    settled = (t > SETTLED[0]) & (t < SETTLED[1])
    assert settled.sum() >= 64 and difference[settled].max() <= 1e-9
    assert values['keyphasor'] == '/keyphasor (sensor_msgs/msg/TimeReference)'


def test_missed_and_doubled_marks_are_counted_by_the_node_as_by_replay(runs, tmp_path):
    run = runs[0]
    volts = tach_bags.tach_volts(run, run.time)
    marks = tach_bags.mark_times(run)
    lost = (run.time > marks[20] - 0.01) & (run.time < marks[20] + 0.08)
    volts[lost] = 0.0                                 # a pulse unseen: a missed mark
    angle = exact_motion(run.pieces, run.time)[0]
    middle = np.flatnonzero((run.time > marks[25]) & (np.mod(angle, 2 * math.pi) > 3.0))[0]
    volts[middle] = 5.0                               # a spike mid-turn: a doubled mark
    _, _, bag = tach_bags.write_run(tmp_path, ROOT, tach_values=volts)
    said = replay(bag).problems
    [line] = [p for p in said if p.startswith('keyphasor ')]
    assert ' 1 missed (put back), 1 doubled (dropped), ' in line
    _, _, _, values, array = node_on(bag, runs[1], 'float64')
    assert (values['keyphasor missed (put back)'], values['keyphasor doubled (dropped)']) == \
        (1, 1)
    found = int(re.search(r': (\d+) marks', line).group(1))
    assert values['keyphasor marks'] == found
    diagnostics = {kv.key: kv.value for kv in array.status[0].values}
    assert (diagnostics['keyphasor missed (put back)'],
            diagnostics['keyphasor doubled (dropped)']) == ('1', '1')


# -- play into the node's own process ---------------------------------------------------

def test_play_a_time_reference_tach_bag_into_the_node(runs, tmp_path):
    play_into_the_node(runs, 'time_reference', tmp_path)


def play_into_the_node(runs, kind, tmp_path):
    """
    Play the run's bag with a ``kind`` tach into the node's own process; check what it did.

    The sampled tach's (float64) is in test/test_node_timing.py: stamped on receipt, its
    marks come late to a node descheduled by another test, so it runs alone.
    """
    run, layout, bags, offline = runs
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', f'layout_file:={layout}', '-p', 'keyphasor_topic:=keyphasor',
                        '-p', f'record_path:={tmp_path / "node.mcap"}'],
                       tmp_path / 'node.log')
    live = tmp_path / 'live.mcap'
    played = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play', str(bags[kind]),
                             '-o', str(live), '--wait', '60'], env=ros_environment(),
                            capture_output=True, text=True, timeout=180)
    assert node.stop(signal.SIGINT) == 0
    assert played.returncode == 0, played.stderr
    log = node.log()
    assert f'keyphasor /keyphasor: {tach_bags.TYPES[kind]}' in log
    [line] = re.findall(r'balance_monitor: (keyphasor /keyphasor: .*)', log)
    assert ' 0 missed (put back), 0 doubled (dropped), ' in line
    # play reports the node's last /diagnostics: its marks' check, a period before the end.
    assert re.search(r'^      keyphasor /keyphasor: \d+ marks, 0 missed \(put back\), 0 doubled '
                     r'\(dropped\), \d+ irregular periods \(no angle there\), \d+ '
                     r'revolutions$', played.stdout, re.M), played.stdout
    recorded = Bag(tmp_path / 'node.mcap')        # the node records the tach it took
    [channel] = [c for c in recorded.channels.values() if c.topic == '/keyphasor']
    assert channel.msg_type == tach_bags.TYPES[kind]
    given = len(Bag(bags[kind]).messages(
        next(c for c in Bag(bags[kind]).channels.values() if c.topic == '/keyphasor')))
    assert 0.95 * given <= len(recorded.messages(channel)) <= given
    stamps, force = bearing_loads(live)
    if kind == 'time_reference':        # stamped from time_ref: replay's samples, late
        assert np.isin(offline[kind][0], stamps).all()
        difference, _ = compare((stamps, force), offline[kind], run)
        assert difference.max() <= 1e-3
    else:                               # stamped on receipt: as many samples as replay's
        assert len(stamps) >= 0.8 * len(offline[kind][0])


def test_a_bad_keyphasor_parameter_is_one_line_and_exit_2():
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.ros.balance_monitor',
                          '--ros-args', '-p', 'keyphasor_topic:=tach', '-p',
                          'keyphasor_edge:=up'], env=ros_environment(), capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 2
    assert run.stderr.strip() == ("balance_monitor: error: parameter keyphasor_edge must be "
                                  "rising or falling, got 'up'")
