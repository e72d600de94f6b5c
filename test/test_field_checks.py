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

from cvc_balance.field import calibrate, Trial

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
