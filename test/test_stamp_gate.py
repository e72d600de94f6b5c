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
