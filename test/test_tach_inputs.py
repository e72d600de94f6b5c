"""
A rotor with a tach and no encoder, offline: replay, identify and view read the tach.

Issue 26: a bag with a keyphasor and no joint_states was refused ("no joint_states or
speed topic"). The run of test/tach_bags.py is recorded twice, with an exact encoder and
with a tach made from the scenario's exact angle (a sampled 0-5 V pick-up, or one
TimeReference a mark); the references are that angle (closed form), the encoder bag's
replay (the same stamps), and Pinocchio's RNEA at the exact motion.

Stated errors (measured in brackets):

* the tach's angle is within max|alpha| T^2 / 8 + 1e-9 rad of the true one at every
  sample it gives one (T the period the sample is in: what a straight line between the
  marks would be off by on a ramp; the cubic between them does better [0.028 rad, beside
  the changes of acceleration]), exact (1e-9 rad) where the speed is steady [1.1e-13];
* in the steady stretch, more than 5 revolutions (half the speed's span and the
  sample's period) from a speed change, the speed is exact (1e-9 rad/s) [2.8e-14]; 1 s
  later (the alpha estimate's memory) the bearing load equals the encoder bag's to 1e-9
  of its peak [1.7e-11];
* everywhere the tach gives an angle, the bearing load is within 1e-3 of its peak of the
  encoder bag's [3.6e-4: beside the changes of acceleration, where the speed fitted over
  8 revolutions spans the change];
* the TimeReference tach's bearing loads in the steady stretch are Pinocchio's at the
  exact motion to 1e-9 of the peak;
* identify: the tach bag's identified plane unbalances are the encoder bag's within 0.2
  of the larger 95 % radius of the two [0.05].
"""

import json
import math
from pathlib import Path
import re

import numpy as np
import pytest

from cvc_balance.bag.channels import keyphasor_motion
from cvc_balance.bag.inputs import InputTopics
from cvc_balance.bag.mcap_reader import Bag, wrench_samples
from cvc_balance.bag.replay import replay
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.bag.scenario import exact_motion
from independent import PinocchioRotor
from in_process import run_cli
import tach_bags

ROOT = Path(__file__).resolve().parents[1]
STEADY = (5.82 + 5 * 0.27 + 0.05, 10.82 - 5 * 0.27 - 0.05)
"""
s after the start: the steady stretch (5.82-10.82 s) less 5 revolutions at each end.

The speed at a mark is the mean over 8 revolutions centred on it; between two marks it
is interpolated: a sample sees the marks 4 revolutions before its period to 4 after.
"""
SETTLED = (STEADY[0] + 1.0, STEADY[1])
"""The loads' steady stretch: also 10 time constants (0.1 s) of the alpha estimate later."""


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """Write the run as an encoder bag, a Float64 tach bag and a TimeReference tach bag."""
    folder = tmp_path_factory.mktemp('tach')
    run, encoder, sampled = tach_bags.write_run(folder, ROOT)
    _, _, marked = tach_bags.write_run(folder, ROOT, tach='time_reference')
    return run, encoder, sampled, marked


def bearing_loads(path):
    """(stamps ns, force (n, 3)) of /bearing_load in a replay's output bag."""
    bag = Bag(path)
    channel = next(c for c in bag.channels.values() if c.topic == '/bearing_load')
    stamps, force, _ = wrench_samples(bag, channel)
    return stamps, force


def test_the_tach_angle_is_the_true_angle_within_the_chord_bound(runs):
    run, _, sampled, _ = runs
    motion = keyphasor_motion(open_bag(sampled))
    t = motion.stamp * 1e-9 - run.start
    angle, omega, _ = exact_motion(run.pieces, t)
    error = np.abs(np.angle(np.exp(1j * (motion.angle - angle))))
    marks = tach_bags.mark_times(run)
    k = np.searchsorted(marks, t)
    inside = (k > 0) & (k < len(marks))
    assert inside.all()                         # no angle before the first mark or after
    period = marks[k] - marks[k - 1]
    top_alpha = max(abs(a) for _, a in run.pieces)
    assert np.all(error <= top_alpha * period ** 2 / 8 + 1e-9)
    assert error.max() <= 0.05
    steady = (t > STEADY[0]) & (t < STEADY[1])
    assert steady.sum() > 2000
    assert error[steady].max() <= 1e-9
    assert np.abs(motion.omega[steady] - omega[steady]).max() <= 1e-9


def test_a_tach_bag_replays_as_its_encoder_bag(runs, tmp_path):
    run, encoder, sampled, _ = runs
    by_encoder = replay(encoder, tmp_path / 'encoder_out.mcap')
    by_tach = replay(sampled, tmp_path / 'tach_out.mcap')
    assert by_encoder.rejected == 0
    # The tach's samples with no angle: before the first mark, inside the periods of the
    # spin-up from rest that change by more than 20 % a turn, after the last mark.
    assert by_tach.accepted + by_tach.rejected == by_encoder.accepted
    assert by_tach.reasons == [f'{by_tach.rejected} keyphasor samples before the first '
                               'mark, after the last or inside an irregular period: no '
                               'angle there']
    stamps, force = bearing_loads(tmp_path / 'tach_out.mcap')
    encoder_stamps, encoder_force = bearing_loads(tmp_path / 'encoder_out.mcap')
    at = np.searchsorted(encoder_stamps, stamps)
    assert np.array_equal(encoder_stamps[at], stamps)        # the encoder's sample times
    peak = np.linalg.norm(encoder_force, axis=1).max()
    difference = np.linalg.norm(force - encoder_force[at], axis=1) / peak
    t = stamps * 1e-9 - run.start
    steady = (t > SETTLED[0]) & (t < SETTLED[1])
    assert difference[steady].max() <= 1e-9
    assert difference.max() <= 1e-3
    assert len(by_tach.segments) == len(by_encoder.segments) == 1


def test_a_time_reference_tach_gives_the_exact_loads_in_steady_speed(runs, tmp_path):
    run, _, _, marked = runs
    summary = replay(marked, tmp_path / 'marked_out.mcap')
    assert summary.accepted > 64 * 30
    stamps, force = bearing_loads(tmp_path / 'marked_out.mcap')
    t = stamps * 1e-9 - run.start
    steady = (t > SETTLED[0]) & (t < SETTLED[1])
    assert steady.sum() >= 64 * 4
    angle, omega, alpha = exact_motion(run.pieces, t[steady])
    rotor = PinocchioRotor(run.layouts[0][1])
    expected = np.array([rotor.loads(q, w, a)['force'] for q, w, a in zip(angle, omega, alpha)])
    peak = np.linalg.norm(expected, axis=1).max()
    assert np.linalg.norm(force[steady] - expected, axis=1).max() <= 1e-9 * peak


def test_the_replay_command_says_what_the_tach_gave(runs):
    run, _, sampled, _ = runs
    code, out, err = run_cli('replay', sampled, '--json')
    assert code == 0, err
    record = json.loads(out)
    rejected = record['rejected']
    assert record['samples'] == len(run.time) and rejected > 0
    assert record['rejected_reasons'] == [
        f'{rejected} keyphasor samples before the first mark, after the last or inside an '
        'irregular period: no angle there']
    [said] = record['problems']
    marks, irregular, revolutions = (int(n) for n in re.findall(
        r'^keyphasor /keyphasor: (\d+) marks, 0 missed \(put back\), 0 doubled \(dropped\), '
        r'(\d+) irregular periods \(no angle there\), (\d+) revolutions$', said)[0])
    assert marks == len(tach_bags.mark_times(run))
    assert revolutions + irregular == marks - 1 and 1 <= irregular <= 4
    assert record['input_checks'] == []       # a tach: no position and velocity to compare
    code, text, err = run_cli('replay', sampled)
    assert code == 0, err
    lines = text.splitlines()
    assert lines[0] == (f'bag {sampled}: {len(run.time)} motion samples, '
                        f'{len(run.time) - rejected} used, {rejected} rejected, 0 before any '
                        'layout')
    assert lines[1] == f'  rejected: {record["rejected_reasons"][0]}'
    assert lines[2] == f'  problem: {said}'


def test_identify_and_view_read_the_tach(runs, tmp_path):
    run, encoder, sampled, _ = runs
    found = {}
    for name, bag in (('encoder', encoder), ('tach', sampled)):
        code, out, err = run_cli('identify', bag, '--json')
        assert code == 0, err
        found[name] = json.loads(out)
    [said] = found['tach']['problems']
    assert said.startswith('keyphasor /keyphasor: ') and ' 0 missed (put back), ' in said
    assert found['encoder']['problems'] == []
    for tach, encoder_segment in zip(found['tach']['segments'], found['encoder']['segments']):
        for got, want in zip(tach['identified']['planes'],
                             encoder_segment['identified']['planes']):
            apart = abs(got['g_mm'] * np.exp(1j * math.radians(got['angle_deg']))
                        - want['g_mm'] * np.exp(1j * math.radians(want['angle_deg'])))
            assert apart <= 0.2 * max(got['ci95_g_mm'], want['ci95_g_mm'])
    code, out, err = run_cli('view', sampled, '-o', tmp_path / 'run.rrd')
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith(f'{tmp_path / "run.rrd"}: ') and lines[0].endswith(
        f'samples of {sampled}, 1 layouts')
    assert lines[1] == f'  problem: {said}'
    assert (tmp_path / 'run.rrd').stat().st_size > 0


def test_a_named_tach_is_the_motion_and_bad_names_are_one_line(runs, tmp_path):
    _, encoder, sampled, marked = runs
    # An encoder bag: joint_states by default; its keyphasor only when named.
    both = tmp_path / 'both.mcap'
    tach_bags.merge(both, encoder, sampled)
    assert replay(both).accepted == replay(encoder).accepted
    named = replay(both, names=InputTopics(keyphasor='/keyphasor'))
    assert named.accepted == replay(sampled).accepted
    falling = replay(sampled, names=InputTopics(keyphasor='keyphasor',
                                                keyphasor_edge='falling'))
    assert falling.accepted != named.accepted       # the marks at the strip's other edge
    for args, needle in (
            (['--keyphasor', 'tach'], 'no keyphasor topic tach (given with --keyphasor); '
             'the bag has: '),
            (['--keyphasor', 'layout'], 'keyphasor topic /layout has type '
             'std_msgs/msg/String, expected std_msgs/msg/Float64 (a sampled tach) or '
             'sensor_msgs/msg/TimeReference'),
            (['--keyphasor', 'keyphasor', '--speed-topic', 'speed'], '--keyphasor is the motion: '
             'give it without --joint-states or --speed-topic'),
            (['--keyphasor-threshold', '7'], 'keyphasor /keyphasor gives 0 marks')):
        code, out, err = run_cli('replay', sampled, *args)
        assert code == 2 and out == '', (args, err)
        assert len(err.strip().splitlines()) == 1 and needle in err, (args, err)
    code, out, err = run_cli('replay', marked, '--keyphasor-threshold', '2')
    assert code == 0, err
    assert ('keyphasor /keyphasor is sensor_msgs/msg/TimeReference (one message a mark): the '
            'threshold given applies to a sampled tach only; ignored') in out
