"""
The time line of a motion stream: stamps checked against the receive clock.

A JointState stamped 2147483647 s used to be accepted, after which every valid sample
was "not after the previous" while /diagnostics said OK; then far-future stamps sent in
pairs that agreed took the gate over (0 of 20,000 good samples answered, outputs stamped
11.6 days ahead), and every pause longer than max_stamp_jump cost the sample after it.
The gate now follows the receive clock as well as the stamps (issue 24, issue 30). The
vectorised gate (replay, with the bag's log times as receive times) must decide exactly as
the live one.
"""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from cvc_balance.physics.motion import (_follows, accepted_motion, accepted_samples,
                                        AccelerationEstimator, gate_samples, LINE_SLEW,
                                        stamp_problem, stamp_seconds, StampGate)

DAYS_11_6 = 11.6 * 86400.0


def decide(samples, max_jump):
    """Return [(accepted, restarted)] of (stamp, receive time) pairs through one gate."""
    gate = StampGate(max_jump)
    out = []
    for stamp, receive in samples:
        out.append((gate.check(stamp, receive) is None, gate.restarted))
    return out


def accepted(samples, max_jump=1.0):
    return [ok for ok, _ in decide(samples, max_jump)]


def test_far_future_pairs_cannot_take_over_a_stream_that_goes_on():
    """
    The hostile review's attack: far-future pairs among 20,000 good samples.

    20,000 good samples at 1 kHz, and after every 10th a pair of samples stamped 11.6
    days ahead that agree with each other (1 ms apart, as a second publisher would send
    them). Every good sample is accepted, no poisoned one.
    """
    good = [(1000.0 + 0.001 * k, 5.0 + 0.001 * k + 0.0002) for k in range(20_000)]
    stream, poisoned = [], 0
    for k, (stamp, receive) in enumerate(good):
        stream.append((stamp, receive))
        if k % 10 == 9:
            stream += [(stamp + DAYS_11_6, receive + 0.0001),
                       (stamp + DAYS_11_6 + 0.001, receive + 0.0002)]
            poisoned += 2
    decisions = accepted(stream)
    is_good = [abs(s - 1000.0) < 100.0 for s, _ in stream]
    assert sum(ok for ok, g in zip(decisions, is_good) if g) == 20_000
    assert sum(ok for ok, g in zip(decisions, is_good) if not g) == 0
    assert poisoned == 4000


def test_no_run_of_agreeing_stamps_creeps_ahead_of_the_receive_clock():
    """
    A run of stamps creeping ahead is stopped at max_stamp_jump from the line.

    Every sample runs 0.9 s further ahead than the receive clock advanced (each step
    plausible against the one before). By hand: the second sample leads the first's line
    (offset 0) by 0.9 s less the 1 % slew of 0.01 s, accepted; the third by 1.8 s less
    twice that, refused; the rest jump from the second: refused.
    """
    samples = [(10.0 + k * 0.91, 10.0 + k * 0.01) for k in range(50)]
    assert accepted(samples) == [True, True] + [False] * 48
    gate = StampGate(1.0)
    for stamp, receive in samples[:2]:
        assert gate.check(stamp, receive) is None
    assert gate.check(*samples[2]) == (
        'stamp 11.820000000 s runs 1.8 s ahead of the receive clock (max_stamp_jump 1 s; '
        'stamps faster than real time?)')


def test_the_gates_words_name_what_was_seen():
    """Each refusal, by hand: the stamps and times in its words."""
    gate = StampGate(1.0)
    assert gate.check(2.0, 100.0) is None                          # the line: offset -98 s
    assert gate.check(1.5, 100.5) == 'stamp 1.500000000 s not after the previous 2.000000000 s'
    assert gate.check(2.0, 100.5) == 'stamp 2.000000000 s not after the previous 2.000000000 s'
    assert gate.check(6.0, 100.5) == (
        'stamp 6.000000000 s jumps 4 s past the previous, received 0.5 s after it '
        '(max_stamp_jump 1 s)')
    # 0.75 s ahead at 101 s: the line's offset moves up by 1 % of the 1 s elapsed, to
    # -97.99 s; 4.6 s at 101.5 s is then 1.09 - 0.005 s ahead.
    assert gate.check(3.75, 101.0) is None
    assert gate.offset == pytest.approx(-97.99, abs=1e-12)
    assert gate.check(4.6, 101.5) == (
        'stamp 4.600000000 s runs 1.08 s ahead of the receive clock (max_stamp_jump 1 s; '
        'stamps faster than real time?)')
    assert gate.check(0.0, 102.0) == 'stamp 0.000000000 s: unset (0) or before 0'
    assert StampGate().max_jump == math.inf
    with pytest.raises(ValueError, match=r'^max_jump must be > 0 s, got 0$'):
        StampGate(0)


def test_stamps_unset_or_beyond_a_second_of_nanoseconds_are_refused():
    assert stamp_problem(0, 0) == 'stamp 0.000000000 s: unset (0) or before 0'
    assert stamp_problem(17, 4294967295) == 'stamp nanosec 4294967295 not below 10^9 (sec 17)'
    assert stamp_problem(17, 1_000_000_000) == \
        'stamp nanosec 1000000000 not below 10^9 (sec 17)'
    assert stamp_problem(-1, 5) == 'stamp -1.000000005 s: unset (0) or before 0'
    assert stamp_problem(0, 1) is None and stamp_problem(17, 999_999_999) is None
    assert accepted([(0.0, 1.0), (0.001, 1.001), (0.002, 1.002)]) == [False, True, True]
    # The vectorised gate too: these stamps agree with one another and with the receive
    # clock (one line, no jump), so only the rule itself refuses the first.
    ok, restarted = gate_samples(np.array([0.0, 0.001, 0.002]), np.zeros(3), np.ones(3), 10.0,
                                 1.0, np.array([1.0, 1.001, 1.002]))
    assert ok.tolist() == [False, True, True] and restarted.tolist() == [False] * 3


def test_a_sample_after_a_pause_is_not_lost():
    """
    A pause longer than max_stamp_jump costs no sample.

    A 1 kHz stream pauses 5 s (stamps and receive clock both advance 5 s, received
    30 ms late) and again 100 s: every sample is accepted on the one time line.
    """
    samples = [(50.0 + k * 0.001, 7.0 + k * 0.001) for k in range(100)]
    samples += [(55.1 + k * 0.001, 12.13 + k * 0.001) for k in range(100)]
    samples += [(155.2 + k * 0.001, 112.2 + k * 0.001) for k in range(100)]
    assert decide(samples, 1.0) == [(True, False)] * 300


def test_a_clock_step_is_followed_once_the_old_line_is_silent():
    """
    A new time line, after the old one has gone silent for max_stamp_jump.

    A driver restarted with a clock 500 s on (stamps jump, the receive clock does not):
    its samples are rejected while the old line could still be alive (1 s: max_jump);
    the first after that is remembered and the next, agreeing, starts the new line.
    Likewise a clock stepped back.
    """
    old = [(1.0 + k * 0.01, 20.0 + k * 0.01) for k in range(10)]       # up to 20.09 s
    new = [(500.0 + k * 0.01, 20.105 + k * 0.01) for k in range(120)]
    decisions = decide(old + new, 1.0)
    # Silent after 21.09 s: the sample received at 21.095 s (k = 99) is remembered, the
    # one at 21.105 s starts the line.
    expected = [(True, False)] * 10 + [(False, False)] * 100 + [(True, True)] + \
        [(True, False)] * 19
    assert decisions == expected
    back = [(500.0 + k * 0.01, 20.0 + k * 0.01) for k in range(10)] + \
        [(2.0 + k * 0.01, 20.105 + k * 0.01) for k in range(120)]
    assert decide(back, 1.0) == expected


def test_stamps_slower_or_drifting_are_followed_faster_ones_are_not():
    """
    Slower or drifting clocks are followed; one at twice real time is not.

    A simulation clock at half real time, and a clock 100 ppm fast over 10 h (1 Hz):
    every sample on the line. One at twice real time: 1 % of slew cannot follow it,
    so from the sample that leads by more than 1 s (by hand: the offset grows by 1 s per
    s of receive time, less 1 % of it) it is rejected.
    """
    slow = [(10.0 + 0.005 * k, 3.0 + 0.01 * k) for k in range(1000)]
    assert all(accepted(slow))
    drift = [(1e5 + k * (1.0 + 1e-4), 40.0 + k) for k in range(36_000)]
    assert all(accepted(drift))
    fast = [(10.0 + 0.02 * k, 3.0 + 0.01 * k) for k in range(150)]
    # By hand: before sample k the offset has moved up 1e-4 s per sample (1 % of 0.01 s),
    # so k leads by 0.01 k - 1e-4 k: 0.9999 s at k = 101, 1.0098 s at k = 102.
    assert accepted(fast)[:103] == [True] * 102 + [False]


def test_without_a_jump_limit_the_gate_only_keeps_order():
    stamps = [1.0, 5.0, 2.0, 3.0, 1e9, 6.0]
    expected = [True, True, False, False, True, False]
    assert accepted([(s, 0.0) for s in stamps], math.inf) == expected
    assert accepted_samples(np.array(stamps), np.zeros(6), np.ones(6), 10.0).tolist() == \
        expected
    with pytest.raises(ValueError, match='^a finite max_jump needs the receive times$'):
        gate_samples(np.array(stamps), np.zeros(6), np.ones(6), 10.0, 1.0)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.one_of(st.floats(-10.0, 10.0),
                                    st.sampled_from([0.0, 2147483647.0, 1e9, -1e9])),
                          st.sampled_from([0.0, 0.001, 0.001, 0.5, 1.5, 30.0])),
                max_size=40),
       st.sampled_from([0.5, 1.0, math.inf]))
def test_vectorised_gate_decides_as_the_live_one(steps, max_jump):
    """Random steps of stamps (some absurd, some back) and of receive times (some pauses)."""
    stamp_steps = np.array([s for s, _ in steps], float)
    stamps = 5.0 + np.cumsum(np.where(np.abs(stamp_steps) > 1e8, 0.0, stamp_steps * 0.01)) + \
        np.where(np.abs(stamp_steps) > 1e8, stamp_steps, 0.0)
    receive = 100.0 + np.cumsum([r for _, r in steps])
    angle = np.zeros(len(stamps))
    omega = np.where(np.arange(len(stamps)) % 7 == 3, math.nan, 1.0)   # some invalid
    got, restarted = gate_samples(stamps, angle, omega, 10.0, max_jump, receive)
    gate, expect_ok, expect_restart = StampGate(max_jump), [], []
    for stamp, r, w in zip(stamps.tolist(), receive.tolist(), omega.tolist()):
        if not math.isfinite(w):
            expect_ok.append(False)
            expect_restart.append(False)
            continue
        expect_ok.append(gate.check(stamp, r) is None)
        expect_restart.append(gate.restarted)
    assert got.tolist() == expect_ok and restarted.tolist() == expect_restart


def test_replay_restarts_alpha_where_the_time_line_restarts():
    """
    accepted_motion: the default max_stamp_jump (1 s), alpha afresh on the new time line.

    Two ramps, 0.5 rad/s^2 from t = 1 s and 2 rad/s^2 on a driver restarted with its clock
    1.5 s on (stamps from 4.5 s; received 1.0-2.99 s, then from 3.005 s: the receive clock
    did not jump). The old line is silent after 3.99 s: the restarted driver's samples
    received until 3.985 s are rejected, the one at 3.995 s remembered, the next starts
    the new line; each segment's alpha is the live estimator's over that segment alone.
    """
    t1, t2 = 1.0 + np.arange(0, 200) * 0.01, 4.5 + np.arange(0, 200) * 0.01
    time = np.concatenate([t1, t2])
    receive = np.concatenate([t1, 3.005 + np.arange(0, 200) * 0.01])
    omega = np.concatenate([1.0 + 0.5 * (t1 - 1.0), 3.0 + 2.0 * (t2 - 4.5)])
    angle = np.zeros_like(time)
    got, restarted = gate_samples(time, angle, omega, 100.0, 1.0, receive)
    np.testing.assert_array_equal(accepted_samples(time, angle, omega, 100.0, 1.0, receive),
                                  got)
    assert accepted_samples(time, angle, omega, 100.0).all()     # no jump limit: all in order
    assert restarted.dtype == bool and np.flatnonzero(restarted).tolist() == [300]
    assert np.flatnonzero(~got).tolist() == list(range(200, 300))
    taken, alpha = accepted_motion(time, receive, angle, omega, 100.0, 0.1)
    np.testing.assert_array_equal(taken, got)
    expected = []
    for segment in (slice(0, 200), slice(300, 400)):
        estimator = AccelerationEstimator(0.1)
        expected += [estimator.update(t, w) for t, w in zip(time[segment], omega[segment])]
    np.testing.assert_allclose(alpha, expected, rtol=1e-10, atol=1e-12)
    assert alpha[200] == 0.0 and alpha[-1] == pytest.approx(2.0, rel=1e-9)
    assert alpha[199] == pytest.approx(0.5, rel=1e-9)


def test_stamps_in_seconds_and_what_follows_by_hand():
    """A stamp is its nanoseconds times 1e-9; a sample follows when 0 < step <= gap + jump."""
    assert stamp_seconds(2, 0) == 2.0 and stamp_seconds(0, 250_000_000) == 0.25
    assert stamp_seconds(1_700_000_000, 123) == 1_700_000_000_000_000_123 * 1e-9
    assert _follows((0.0, 0.0), 0.2, 0.1, 0.1)              # a step of gap + jump exactly
    assert not _follows((0.0, 0.0), 0.3, 0.1, 0.1)          # more: 0.3 > 0.1 + 0.1
    assert not _follows((1.0, 0.0), 1.0, 0.1, 0.1)          # the same stamp again
    assert not _follows((0.0, 0.5), 0.15, 0.0, 0.1)         # received earlier: gap 0


def test_the_line_follows_the_stamps_offset_by_the_slew_at_most():
    """On the line the offset stays; off it by more than the slew it moves the slew per s."""
    gate = StampGate(max_jump=1.0)
    assert gate.check(100.0, 0.0) is None and gate.offset == 100.0
    assert gate.check(101.0, 1.0) is None and gate.offset == 100.0       # t - r = 100
    assert gate.check(101.5, 2.0) is None                                # t - r = 99.5
    assert gate.offset == 100.0 - LINE_SLEW                              # one second's slew


def test_stamps_that_creep_ahead_in_steps_each_allowed_are_refused_when_vectorised():
    """
    Check a run whose every step is allowed, but whose stamps creep ahead of the line.

    By hand, max_jump 1 s: stamps 1, 4.9, 8.8 s received at 6, 9, 12 s. The line starts
    at offset 1 - 6 = -5 s; the second stamp leads it by (4.9 - 9) + 5 = 0.9 s (taken;
    the line follows by the slew, 0.01 x 3 s, to -4.97 s); the third leads by
    (8.8 - 12) + 4.97 = 1.77 s: refused. Each step, 3.9 s, is within the 3 s received
    plus 1 s, so only the offsets' spread (1.8 s) says the fast path may not be taken.
    """
    ok, restarted = gate_samples(np.array([1.0, 4.9, 8.8]), np.zeros(3), np.ones(3), 10.0,
                                 1.0, np.array([6.0, 9.0, 12.0]))
    assert ok.tolist() == [True, True, False] and restarted.tolist() == [False] * 3
