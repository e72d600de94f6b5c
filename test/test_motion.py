"""The acceleration estimator and the speed integrator, against exact motions and noise."""

import math
import random

import pytest

from cvc_balance.physics.motion import AccelerationEstimator, AngleIntegrator, sample_problem


def test_ramp_is_followed_without_lag():
    """On omega = omega0 + alpha t the least-squares slope is exact from the 2nd sample."""
    estimator = AccelerationEstimator(0.1)
    alpha = 2.5
    estimates = [estimator.update(k * 1e-3, 3.0 + alpha * k * 1e-3) for k in range(500)]
    assert estimates[0] == 0.0
    # Measured: 3.4e-13 relative at most (the sums' rounding, as old samples fade).
    assert all(e == pytest.approx(alpha, rel=2e-12) for e in estimates[1:])


def test_irregular_sample_times():
    rng = random.Random(4)
    estimator = AccelerationEstimator(0.05)
    t = 0.0
    for _ in range(2000):
        t += rng.uniform(2e-4, 3e-3)
        estimate = estimator.update(t, -1.0 - 0.7 * t)
    assert estimate == pytest.approx(-0.7, rel=5e-13)            # measured 5.6e-14


def test_noise_is_suppressed_against_the_raw_difference():
    """Speed noise 0.01 rad/s at 1 kHz: raw differences ~14 rad/s^2, the estimate << 1."""
    rng = random.Random(1)
    sigma, dt, tau = 0.01, 1e-3, 0.1
    estimator = AccelerationEstimator(tau)
    previous = None
    raw, smooth = [], []
    for k in range(20_000):
        omega = 25.0 + rng.gauss(0.0, sigma)
        estimate = estimator.update(k * dt, omega)
        if previous is not None:
            raw.append((omega - previous) / dt)
        if k > 5 * tau / dt:
            smooth.append(estimate)
        previous = omega
    rms_raw = math.sqrt(sum(a * a for a in raw) / len(raw))
    rms_smooth = math.sqrt(sum(a * a for a in smooth) / len(smooth))
    # An rms over 2e4 samples scatters by 1 / sqrt(2 N) = 0.5 %: measured 0.55 % off.
    assert rms_raw == pytest.approx(sigma * math.sqrt(2) / dt, rel=0.02)
    # Weighted least squares: var(slope) = sigma^2 / sum(w (t - mean)^2) ~ 4 sigma^2 dt / tau^3
    # for the steady state of exponential weights; allow the estimate's own scatter.
    expected = sigma * math.sqrt(4 * dt / tau**3)
    assert rms_smooth < 1.5 * expected
    assert rms_smooth < 2e-3 * rms_raw


def test_step_in_alpha_is_reached_within_eight_time_constants():
    estimator = AccelerationEstimator(0.05)
    dt, omega = 1e-3, 10.0
    for k in range(500):   # steady, then a step to alpha = 4 at t = 0.1 s: 8 tau after
        alpha = 0.0 if k < 100 else 4.0
        omega += alpha * dt
        estimate = estimator.update(k * dt, omega)
    # What is left of the step after 8 tau: measured 1.6e-3 relative.
    assert estimate == pytest.approx(4.0, rel=4e-3)


def test_speed_is_integrated_to_an_angle():
    integrator = AngleIntegrator()
    for k in range(1001):   # omega = 2 t over 1 s: q = t^2 = 1 rad (trapezoid: exact)
        q = integrator.update(k * 1e-3, 2.0 * k * 1e-3)
    assert q == pytest.approx(1.0, rel=1e-14)                    # measured 3.3e-16


@pytest.mark.parametrize('time, last, angle, omega, word', [
    (1.0, None, math.nan, 1.0, 'finite'), (1.0, None, 0.0, math.inf, 'finite'),
    (1.0, None, 0.0, 2000.0, 'max_speed'), (1.0, 1.0, 0.0, 1.0, 'not after'),
    (0.5, 1.0, 0.0, 1.0, 'not after')])
def test_bad_samples_are_named(time, last, angle, omega, word):
    assert word in sample_problem(time, last, angle, omega, max_speed=1000.0)


def test_good_sample_passes():
    assert sample_problem(1.0, 0.999, 3.0, -20.0, max_speed=1000.0) is None
