"""
Influence coefficients, their 95 % radii and the trial checks, against formulas by hand.

A linear rotor with known coefficients alpha (3 sensors x 2 planes): a trial run's readings
are R_k = A + alpha u (u the trial weights on in that run). With one trial per plane the
coefficients are exact: alpha_p = (R_k - A) / u_k, each component's error variance
(s_k^2 + s_A^2) / |u_k|^2 from the readings' standard errors; with the trials kept on,
alpha_II = (R_2 - R_1) / u_2 and its variance (s_2^2 + s_1^2) / |u_2|^2 (the baseline
cancels). A 95 % radius is sqrt(chi2_2(0.95) variance), chi2_2(0.95) = -2 ln 0.05. A trial's
visibility: its largest change over that change's noise (the two runs' errors in
quadrature), and over the reading before it.
"""

import cmath
import math

import numpy as np
import pytest

from cvc_balance.field import calibrate, continuous_correction, Trial

ALPHA = np.array([[600 + 0j, 70j], [-400 + 200j, 60 - 10j], [80 + 5j, 610 - 300j]])
BASELINE = np.array([120 + 40j, -90 + 10j, 30 - 75j])
CHI2 = -2.0 * math.log(0.05)


def trial(plane, grams, degrees, radius=0.68):
    return Trial(plane, grams / 1000.0, math.radians(degrees), radius)


def test_one_trial_per_plane_by_hand():
    trials = [trial('I', 200, 30), trial('II', 50, -100)]
    u = [t.unbalance for t in trials]
    assert u[0] == pytest.approx(0.2 * 0.68 * cmath.exp(1j * math.radians(30)), rel=1e-15)
    readings = np.array([BASELINE + ALPHA[:, 0] * u[0], BASELINE + ALPHA[:, 1] * u[1]])
    s_a = np.array([1.0, 2.0, 3.0])
    s_b = np.array([[1.5, 1.0, 0.5], [2.0, 2.5, 1.0]])
    found = calibrate(BASELINE, trials, readings, ['x', 'y', 'z'], False, s_a, s_b)
    assert found.planes == ('I', 'II') and found.sensors == ('x', 'y', 'z')
    np.testing.assert_allclose(found.matrix, ALPHA, rtol=1e-12)
    for k in range(2):
        expected = np.sqrt(CHI2 * (s_b[k] ** 2 + s_a ** 2)) / abs(u[k])
        np.testing.assert_allclose(found.ci95[:, k], expected, rtol=1e-12)
    assert found.condition == pytest.approx(np.linalg.cond(ALPHA), rel=1e-12)
    for k, check in enumerate(found.checks):
        change = np.abs(ALPHA[:, k] * u[k])
        snr = change / np.sqrt(s_a ** 2 + s_b[k] ** 2)
        assert (check.run, check.plane) == (k, trials[k].plane)
        assert check.change == pytest.approx(change.max(), rel=1e-12)
        assert check.snr == pytest.approx(snr.max(), rel=1e-12)
        assert check.relative == pytest.approx((change / np.abs(BASELINE)).max(), rel=1e-12)
    # Trial II: 50 g moves sensor z by 0.034 x 680 = 23 over a noise of 3.2: weak (5-20).
    weak = found.checks[1]
    assert (weak.too_small, weak.weak) == (False, True) and 5.0 <= weak.snr < 20.0
    assert (found.checks[0].too_small, found.checks[0].weak) == (False, False)
    assert found.warnings == (
        f'trial run 2 (plane II, 0.05 at -100 deg): weak: the largest change is '
        f'{weak.snr:.3g} standard errors (under 20): the plane\'s coefficients are uncertain '
        f'by about {math.sqrt(CHI2) / weak.snr:.0%} (95 %); a trial weight about '
        f'{20.0 / weak.snr:.2g} times heavier would do',)


def test_trials_kept_on_by_hand():
    trials = [trial('I', 200, 30), trial('II', 200, 135)]
    u = [t.unbalance for t in trials]
    first = BASELINE + ALPHA[:, 0] * u[0]
    second = first + ALPHA[:, 1] * u[1]
    s_a, s_1, s_2 = np.array([1.0, 2.0, 3.0]), np.array([1.5, 1.0, 0.5]), np.array([4., 1, 2])
    found = calibrate(BASELINE, trials, [first, second], None, True, s_a, [s_1, s_2])
    assert found.sensors == ('sensor 1', 'sensor 2', 'sensor 3')
    np.testing.assert_allclose(found.matrix, ALPHA, rtol=1e-12)
    np.testing.assert_allclose(found.ci95[:, 0], np.sqrt(CHI2 * (s_1 ** 2 + s_a ** 2))
                               / abs(u[0]), rtol=1e-12)
    np.testing.assert_allclose(found.ci95[:, 1], np.sqrt(CHI2 * (s_2 ** 2 + s_1 ** 2))
                               / abs(u[1]), rtol=1e-12)
    second_check = found.checks[1]           # measured against run 1, not the baseline
    change = np.abs(second - first)
    assert second_check.change == pytest.approx(change.max(), rel=1e-12)
    assert second_check.snr == pytest.approx((change / np.hypot(s_1, s_2)).max(), rel=1e-12)
    assert second_check.relative == pytest.approx((change / np.abs(first)).max(), rel=1e-12)
    assert found.warnings == ()


def test_readings_by_hand_and_what_is_refused():
    trials = [trial('I', 200, 0), trial('II', 2, 90)]
    u = [t.unbalance for t in trials]
    readings = [BASELINE + ALPHA[:, 0] * u[0], BASELINE + ALPHA[:, 1] * u[1]]
    found = calibrate(BASELINE, trials, readings)
    assert found.ci95 is None
    small = found.checks[1]
    relative = (np.abs(ALPHA[:, 1] * u[1]) / np.abs(BASELINE)).max()
    assert small.snr is None and small.relative == pytest.approx(relative, rel=1e-12)
    assert (small.too_small, small.weak) == (True, False) and relative < 0.1
    assert found.warnings == (
        f'trial run 2 (plane II, 0.002 at 90 deg): too small to see: the readings changed by '
        f'at most {relative:.1%} (under 10%); its plane\'s coefficients and corrections are '
        f'not to be trusted: use a trial weight about {0.3 / relative:.3g} times heavier',)
    with pytest.raises(ValueError, match=r'^no trial run: give one per correction plane$'):
        calibrate(BASELINE, [], [])
    with pytest.raises(ValueError, match=r'^trial run 2 \(plane II\): the trial mass and '
                                         r'radius must be > 0$'):
        calibrate(BASELINE, [trials[0], trial('II', 2, 90, radius=0.0)], readings)
    with pytest.raises(ValueError, match=r'^each run needs 3 readings \(as the baseline\), '
                                         r'got 2$'):
        calibrate(BASELINE, trials, [r[:2] for r in readings])


def test_planes_acting_alike_are_said_to():
    alike = np.array([[600 + 0j, 603 + 1j], [-400 + 200j, -401 + 199j], [80 + 5j, 81 + 5j]])
    trials = [trial('I', 200, 0), trial('II', 200, 0)]
    readings = [BASELINE + alike[:, k] * trials[k].unbalance for k in range(2)]
    found = calibrate(BASELINE, trials, readings)
    condition = np.linalg.cond(alike)
    assert condition > 100.0 and found.condition == pytest.approx(condition, rel=1e-9)
    assert found.warnings[-1] == (
        f'the coefficients are ill-conditioned (condition number {found.condition:.3g}): the '
        'planes act nearly alike on these sensors, and reading errors are amplified up to '
        'that many times in the corrections')


def test_the_balancing_problem_and_its_residual_by_hand():
    """
    Problems from readings and from a known unbalance, the residual's measures, the limits.

    One plane, two sensors: the weighted least-squares correction is
    u = -sum w^2 conj(a) A / sum w^2 |a|^2; rms = sqrt(sum (w |r|)^2 / channels with a
    weight), total = sum w |r|, worst = max |r| / limit.
    """
    from cvc_balance.field import BalancingProblem
    from cvc_balance.field.correction import (problem_from_readings, problem_from_unbalance,
                                              with_unbalance_limits)
    trials = [trial('I', 200, 30)]
    alpha = np.array([[600 + 0j], [-400 + 200j]])
    baseline = np.array([120 + 40j, -90 + 10j])
    found = calibrate(baseline, trials, [baseline + alpha[:, 0] * trials[0].unbalance],
                      ['a', 'b'])
    weights, limits = np.array([1.0, 0.25]), np.array([50.0, 400.0])
    problem = problem_from_readings(found, baseline, weights, limits, 'g')
    assert (problem.planes, problem.channels, problem.unit) == (('I',), ('a', 'b'), 'g')
    assert problem.limits.dtype == float and problem.influence.dtype == complex
    np.testing.assert_allclose(problem.influence, alpha, rtol=1e-12)
    a, w = alpha[:, 0], weights
    u = -np.sum(w ** 2 * np.conj(a) * baseline) / np.sum(w ** 2 * abs(a) ** 2)
    assert continuous_correction(problem)[0] == pytest.approx(u, rel=1e-12)
    r = baseline + a * u
    np.testing.assert_allclose(problem.residual([u]), r, rtol=1e-12)
    left = problem.measure([u])
    assert left.rms == pytest.approx(math.sqrt(np.sum((w * abs(r)) ** 2) / 2), rel=1e-12)
    assert left.total == pytest.approx(np.sum(w * abs(r)), rel=1e-12)
    assert left.worst == pytest.approx(max(abs(r) / limits), rel=1e-12)
    assert left.within_limits == (left.worst <= 1.0)
    plain = problem_from_readings(found, baseline)
    np.testing.assert_array_equal(plain.weights, [1.0, 1.0])
    assert plain.limits is None and plain.unit == 'kg m'
    assert plain.measure([0j]).worst is None and plain.measure([0j]).within_limits is None
    with pytest.raises(ValueError, match=r'^1 readings for 2 sensors$'):
        problem_from_readings(found, baseline[:1])
    # A known unbalance per plane: the channels are the planes, weighed by 1 / U_per.
    known = problem_from_unbalance(['I', 'II'], [0.3 + 0.1j, -0.2j], [0.5, 0.25])
    assert known.planes == known.channels == ('I', 'II') and known.unit == 'kg m'
    np.testing.assert_array_equal(known.influence, np.eye(2))
    np.testing.assert_array_equal(known.weights, [2.0, 4.0])
    np.testing.assert_array_equal(known.limits, [0.5, 0.25])
    exact = continuous_correction(known)
    np.testing.assert_allclose(exact, [-0.3 - 0.1j, 0.2j], rtol=1e-14)
    assert known.measure([0j, 0j]).within_limits is True          # 0.32 / 0.5, 0.2 / 0.25
    assert known.measure([0j, -0.1j]).worst == pytest.approx(0.3 / 0.25, rel=1e-14)
    assert known.measure([0j, -0.1j]).within_limits is False
    assert known.measure([-0.8 - 0.1j, 0j]).within_limits is True     # |0.5| / 0.5: on it
    free = problem_from_unbalance(['I'], [0.3])
    np.testing.assert_array_equal(free.weights, [1.0])
    assert free.limits is None
    assert free.measure([0.1]).rms == pytest.approx(0.4, rel=1e-15)   # one channel: /1
    np.testing.assert_allclose(free.measure([0.1]).values, [0.4], rtol=1e-15)
    # Each plane's unbalance as a channel that only limits: weight 0, moved 1:1 by its plane.
    in_kg_m = BalancingProblem(('I',), ('a', 'b'), baseline, alpha, weights)
    limited = with_unbalance_limits(in_kg_m, ['I', 'II'], [0.4 + 0.3j, 0.1], [0.45, 0.2])
    assert limited.channels == ('a', 'b', 'plane I unbalance', 'plane II unbalance')
    assert limited.planes == ('I',)
    np.testing.assert_array_equal(limited.influence[2:], [[1.0], [0.0]])
    np.testing.assert_array_equal(limited.weights, [1.0, 0.25, 0.0, 0.0])
    np.testing.assert_array_equal(limited.limits, [np.inf, np.inf, 0.45, 0.2])
    np.testing.assert_array_equal(limited.baseline[2:], [0.4 + 0.3j, 0.1])
    assert limited.measure([0j]).rms == pytest.approx(
        math.sqrt(np.sum((w * abs(baseline)) ** 2) / 2), rel=1e-12)      # 2 weighted channels
    assert limited.measure([-0.1 + 0j]).worst == pytest.approx(abs(0.3 + 0.3j) / 0.45)
    twice = with_unbalance_limits(known, ['I'], [0.3 + 0.1j], [0.4])
    np.testing.assert_array_equal(twice.limits, [0.5, 0.25, 0.4])
    with pytest.raises(ValueError, match=r'^corrections in g, not kg m: no unbalance to limit$'):
        with_unbalance_limits(problem, ['I'], [0.1], [0.2])


def test_a_trial_lost_in_the_noise_and_small_readings():
    """
    A trial whose change is under one standard error; readings under 1; one sigma only.

    The change over the noise is 0.5: too small, and the advice is 20 / 0.5 = 40 times
    heavier. Readings of 1e-3 (a vibration in mm/s) are compared with themselves, not with
    1. With the baseline's standard errors but not the trials', the noise is not known.
    """
    trials = [trial('I', 200, 0), trial('II', 200, 90)]
    u = [t.unbalance for t in trials]
    small = ALPHA * 1e-6                          # readings of about 1e-3
    base = BASELINE * 1e-5
    first_run = base + small[:, 0] * u[0]
    readings = [first_run, first_run + small[:, 1] * u[1]]      # trial I stays on
    change = np.abs(small[:, 1] * u[1])
    quiet = np.full(3, 1e-12)                     # the baseline and run 1: all but exact
    sigmas = np.full(3, change.max() / 0.5)       # run 2: its largest change = 0.5 sigma
    found = calibrate(base, trials, readings, None, True, quiet, [quiet, sigmas])
    first = found.checks[0]                       # kept on: the first run against the baseline
    assert first.relative == pytest.approx(
        (np.abs(small[:, 0] * u[0]) / np.abs(base)).max(), rel=1e-12)
    lost = found.checks[1]
    assert lost.snr == pytest.approx(0.5, rel=1e-9) and (lost.too_small, lost.weak) == \
        (True, False)
    assert lost.relative == pytest.approx((change / np.abs(readings[0])).max(), rel=1e-12)
    assert len(found.warnings) == 1 and found.warnings[0] == (
        'trial run 2 (plane II, 0.2 at 90 deg): too small to see: the largest change is 0.5 '
        'standard errors of the readings (under 5), within the noise; its plane\'s '
        'coefficients and corrections are not to be trusted: use a trial weight about 40 '
        'times heavier')
    half = calibrate(base, trials, readings, None, True, quiet, None)
    assert half.ci95 is None and half.checks[1].snr is None
