"""
Motion samples from a rotor's sensors: acceleration estimate, speed integration, checks.

Plain Python floats (no numpy): this is the live node's per-message path.
Times in s, angles in rad, speeds in rad/s, accelerations in rad/s^2.

The acceleration alpha is the slope of an exponentially weighted least-squares
line through the recent (t, omega) samples, weights exp(-age / tau). Unlike a
low-passed finite difference it has no lag on a steady ramp (a line is fitted
exactly) and its noise falls as tau^(-3/2): with omega noise sigma at sample
spacing dt, std(alpha) ~ sigma sqrt(dt) tau^(-3/2), against sigma sqrt(2) / dt
for the raw difference. The sums are kept relative to the newest sample, so
the update is O(1) and stays well conditioned for irregular sample times.
"""

import math


class AccelerationEstimator:
    """
    alpha from successive omega samples (exponentially weighted least-squares slope).

    ``time_constant`` tau (s) sets the memory: a larger tau means less noise
    and a slower response to a change of alpha.
    """

    def __init__(self, time_constant):
        """Start with no samples; ``time_constant`` in s, > 0."""
        if not time_constant > 0.0:
            raise ValueError(f'time constant must be > 0 s, got {time_constant}')
        self.time_constant = time_constant
        self.reset()

    def reset(self):
        """Forget all samples."""
        self._last_time = None
        # Weighted sums over samples, times relative to the newest sample.
        self._w = self._t = self._tt = self._y = self._ty = 0.0

    def update(self, time, omega):
        """Add the sample (time s, omega rad/s); return the alpha estimate, rad/s^2."""
        if self._last_time is not None:
            dt = time - self._last_time
            w, t, y = self._w, self._t, self._y
            # Move the time origin to the new sample, then age every weight by dt.
            decay = math.exp(-dt / self.time_constant)
            self._tt = (self._tt - 2.0 * dt * t + dt * dt * w) * decay
            self._ty = (self._ty - dt * y) * decay
            self._t = (t - dt * w) * decay
            self._w = w * decay
            self._y = y * decay
        self._last_time = time
        self._w += 1.0
        self._y += omega
        spread = self._w * self._tt - self._t * self._t
        if spread <= 1e-12 * self._w * self._tt or spread <= 0.0:
            return 0.0
        return (self._w * self._ty - self._t * self._y) / spread


class AngleIntegrator:
    """
    Rotor angle q from speed-only input, integrated over receive times (trapezoid rule).

    Less accurate than an encoder: q starts at 0 (the phase is unknown) and
    drifts with speed errors and receive-time jitter.
    """

    def __init__(self):
        """Start at q = 0 with no sample."""
        self.angle = 0.0
        self._last = None

    def update(self, time, omega):
        """Add the sample (receive time s, omega rad/s); return q, rad, within (-pi, pi]."""
        if self._last is not None:
            last_time, last_omega = self._last
            self.angle += 0.5 * (omega + last_omega) * (time - last_time)
            self.angle = math.remainder(self.angle, 2.0 * math.pi)
        self._last = (time, omega)
        return self.angle


def sample_problem(time, last_time, angle, omega, max_speed):
    """Say what is wrong with a motion sample, or return None when it can be used."""
    if not (math.isfinite(angle) and math.isfinite(omega)):
        return f'not finite (angle {angle}, speed {omega})'
    if abs(omega) > max_speed:
        return f'speed {omega:.6g} rad/s beyond max_speed {max_speed:g} rad/s'
    if last_time is not None and time <= last_time:
        return f'stamp {time:.9f} s not after the previous {last_time:.9f} s'
    return None
