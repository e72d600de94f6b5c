"""
Stamp poisoning: one absurd stamp must not make the node reject every later sample.

A JointState stamped 2147483647 s used to be accepted, after which every valid sample
was "not after the previous" while /diagnostics said OK. The gate rejects a stamp more
than max_jump from the time line and follows a new time line only when the next sample
agrees with it. The vectorised gate (replay) must decide exactly as the live one.
"""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from cvc_balance.physics.motion import gate_samples, StampGate


def decide(stamps, max_jump):
    gate = StampGate(max_jump)
    out = []
    for stamp in stamps:
        out.append((gate.check(stamp) is None, gate.restarted))
    return out


def test_one_absurd_stamp_costs_one_sample():
    stamps = [1.000, 1.001, 2147483647.0, 1.002, 1.003, 1.004]
    assert [ok for ok, _ in decide(stamps, 1.0)] == [True, True, False, True, True, True]


def test_a_real_clock_step_is_followed_after_one_sample():
    stamps = [1.000, 1.001, 500.0, 500.001, 500.002]          # a driver restarted later
    assert decide(stamps, 1.0) == [(True, False), (True, False), (False, False),
                                   (True, True), (True, False)]
    back = [500.0, 500.001, 2.0, 2.001, 2.002]                 # a clock stepped back
    assert [ok for ok, _ in decide(back, 1.0)] == [True, True, False, True, True]


def test_late_samples_are_rejected_without_restarting():
    stamps = [1.000, 1.002, 1.001, 1.0015, 1.003]              # reordered in transit
    assert decide(stamps, 1.0) == [(True, False), (True, False), (False, False),
                                   (False, False), (True, False)]


def test_without_a_jump_limit_the_gate_only_keeps_order():
    stamps = [1.0, 5.0, 2.0, 3.0, 1e9, 6.0]
    expected = [True, True, False, False, True, False]
    assert [ok for ok, _ in decide(stamps, math.inf)] == expected
    with pytest.raises(ValueError):
        StampGate(0.0)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-10.0, 10.0), st.sampled_from([0.0, 2147483647.0, 1e9])),
                max_size=40),
       st.sampled_from([0.5, 1.0, math.inf]))
def test_vectorised_gate_decides_as_the_live_one(steps, max_jump):
    stamps = np.cumsum(np.abs(np.asarray(steps, float)) * 0.01) + np.where(
        np.asarray(steps) > 1e8, np.asarray(steps), 0.0) if steps else np.zeros(0)
    angle = np.zeros(len(stamps))
    omega = np.where(np.arange(len(stamps)) % 7 == 3, math.nan, 1.0)   # some invalid
    accepted, restarted = gate_samples(stamps, angle, omega, 10.0, max_jump)
    gate, expect_ok, expect_restart = StampGate(max_jump), [], []
    for stamp, w in zip(stamps.tolist(), omega.tolist()):
        if not math.isfinite(w):
            expect_ok.append(False)
            expect_restart.append(False)
            continue
        expect_ok.append(gate.check(stamp) is None)
        expect_restart.append(gate.restarted)
    assert accepted.tolist() == expect_ok and restarted.tolist() == expect_restart


def test_the_gates_boundaries_and_words():
    """
    Each boundary as the docstring states it, with stamps exact in binary.

    A step of exactly max_jump is plausible; a repeated stamp is not after the previous;
    a stamp late by exactly max_jump is only late (no new time line); a glitch repeated
    is no time line; a new time line stepping exactly max_jump is followed.
    """
    assert decide([0.5, 1.0], 0.5) == [(True, False), (True, False)]
    gate = StampGate(1.0)
    assert gate.check(2.0) is None
    assert gate.check(1.5) == 'stamp 1.500000000 s not after the previous 2.000000000 s'
    assert gate.check(2.0) == 'stamp 2.000000000 s not after the previous 2.000000000 s'
    assert gate.check(6.0) == ('stamp 6.000000000 s jumps 4 s past the previous (more than '
                               'max_stamp_jump 1 s)')
    assert [ok for ok, _ in decide([10.0, 9.0, 9.5], 1.0)] == [True, False, False]
    assert decide([0.0, 100.0, 100.0, 0.5], 1.0) == [
        (True, False), (False, False), (False, False), (True, False)]
    assert decide([0.0, 100.0, 101.0], 1.0) == [(True, False), (False, False), (True, True)]
    assert [ok for ok, _ in decide([0.0, 1e9], math.inf)] == [True, True]
    assert StampGate().max_jump == math.inf
    with pytest.raises(ValueError, match=r'^max_jump must be > 0 s, got 0$'):
        StampGate(0)


def test_replay_restarts_alpha_where_the_time_line_restarts():
    """
    accepted_motion: the default max_stamp_jump (1 s), alpha afresh on the new time line.

    Two ramps, 0.5 rad/s^2 from t = 0 and 2 rad/s^2 from t = 3.5 s (a driver restarted
    1.5 s on): the first sample after the step is rejected (a jump), the next follows the
    new line; each segment's alpha is the live estimator's over that segment alone (the
    first segment's samples, 15 time constants old, would move its first alpha by 0.66).
    """
    from cvc_balance.physics.motion import (accepted_motion, accepted_samples,
                                            AccelerationEstimator)
    t1, t2 = np.arange(0, 200) * 0.01, 3.5 + np.arange(0, 200) * 0.01
    time = np.concatenate([t1, t2])
    omega = np.concatenate([1.0 + 0.5 * t1, 3.0 + 2.0 * (t2 - 3.5)])
    angle = np.zeros_like(time)
    accepted, restarted = gate_samples(time, angle, omega, 100.0, 1.0)
    np.testing.assert_array_equal(accepted_samples(time, angle, omega, 100.0, 1.0), accepted)
    assert accepted_samples(time, angle, omega, 100.0).all()     # no jump limit: all in order
    assert restarted.dtype == bool and np.flatnonzero(restarted).tolist() == [201]
    assert np.flatnonzero(~accepted).tolist() == [200]
    taken, alpha = accepted_motion(time, angle, omega, 100.0, 0.1)
    np.testing.assert_array_equal(taken, accepted)
    expected = []
    for segment in (slice(0, 200), slice(201, 400)):
        estimator = AccelerationEstimator(0.1)
        expected += [estimator.update(t, w) for t, w in zip(time[segment], omega[segment])]
    np.testing.assert_allclose(alpha, expected, rtol=1e-10, atol=1e-12)
    assert alpha[200] == 0.0 and alpha[-1] == pytest.approx(2.0, rel=1e-9)
    assert alpha[199] == pytest.approx(0.5, rel=1e-9)
