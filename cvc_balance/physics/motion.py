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

from cvc_balance.physics.frames import wrap_angle


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
            self.angle = wrap_angle(self.angle)
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


MAX_STAMP_JUMP = 1.0
"""s: the largest plausible step between two motion samples' stamps (the node's default)."""


class StampGate:
    """
    Stamps of a motion stream: in order, and no implausible jump lets one sample poison it.

    A stamp is accepted when it is after the last accepted one by at most ``max_jump``
    seconds. A late one (reordered in transit) is rejected. One more than ``max_jump`` away
    (a clock glitch, a sample stamped 2147483647 s, a clock stepped back) is rejected and
    remembered: if the next stamp follows it plausibly, the stream has really moved to a new
    time line (a restarted driver, a clock step), which is then followed from that next
    sample on; otherwise the old time line goes on and the glitch is forgotten. So a single
    bad stamp costs one sample, not every later one. With ``max_jump`` inf the gate only
    keeps the order.
    """

    def __init__(self, max_jump=math.inf):
        """Start with no stamp; ``max_jump`` s (> 0) is the largest plausible step."""
        if not max_jump > 0.0:
            raise ValueError(f'max_jump must be > 0 s, got {max_jump}')
        self.max_jump = max_jump
        self.last = None
        self._candidate = None

    def check(self, time):
        """
        Return None and take ``time`` (s) when it is acceptable, else say why not.

        ``restarted`` is True after a call that moved to a new time line (the caller
        resets what depends on the time line: the alpha estimate).
        """
        self.restarted = False
        if self.last is None or 0.0 < time - self.last <= self.max_jump:
            self.last, self._candidate = time, None
            return None
        # Far from the time line (either way): perhaps a new one, if the next sample agrees.
        # Slightly late samples (reordered in transit) are only rejected.
        candidate = self._candidate
        self._candidate = time if abs(time - self.last) > self.max_jump else None
        if candidate is not None and 0.0 < time - candidate <= self.max_jump:
            self.last, self._candidate, self.restarted = time, None, True
            return None
        if time <= self.last:
            return f'stamp {time:.9f} s not after the previous {self.last:.9f} s'
        return (f'stamp {time:.9f} s jumps {time - self.last:.6g} s past the previous '
                f'(more than max_stamp_jump {self.max_jump:g} s)')

    restarted = False


def acceleration_series(time, omega, time_constant, block=None):
    """
    Compute the :class:`AccelerationEstimator`'s output for whole arrays, vectorised.

    ``time`` (s, increasing) and ``omega`` (rad/s) are numpy arrays. Each sum
    of the estimator is a first-order recursion s_k = exp(-dt_k / tau) s_(k-1)
    + x_k, solved per block as exp(-(t_k - c) / tau) (carry + cumsum of
    x_i exp((t_i - c) / tau)) about the block's first time c; blocks span at
    most ``block`` seconds (default 10 tau) so that neither the exponentials
    nor the translation of the moments lose digits. The slope
    (S0 S1y - S1 Sy) / (S0 S2 - S1^2) does not depend on the time origin.
    """
    import numpy as np

    time = np.asarray(time, dtype=float)
    omega = np.asarray(omega, dtype=float)
    n = len(time)
    alpha = np.zeros(n)
    if n == 0:
        return alpha
    span = 10.0 * time_constant if block is None else block
    # S0, S1, S2, Sy, S1y with weights as at time ``weighed``, moments about ``origin``.
    sums, origin, weighed = np.zeros(5), time[0], time[0]
    start = 0
    while start < n:
        stop = max(int(np.searchsorted(time, time[start] + span, side='right')), start + 1)
        # Carry the older samples to this block: age their weights, move the origin.
        shift = time[start] - origin
        s0, s1, s2, sy, s1y = np.exp(-(time[start] - weighed) / time_constant) * sums
        carry = (s0, s1 - shift * s0, s2 - 2 * shift * s1 + shift * shift * s0, sy,
                 s1y - shift * sy)
        origin = time[start]
        u = time[start:stop] - origin
        grow = np.exp(u / time_constant)
        y = omega[start:stop]
        terms = (grow, grow * u, grow * u * u, grow * y, grow * u * y)
        s0, s1, s2, sy, s1y = ((c + np.cumsum(term)) / grow for c, term in zip(carry, terms))
        spread = s0 * s2 - s1 * s1
        tt = s2 - 2 * u * s1 + u * u * s0          # the live estimator's threshold
        ok = (spread > 1e-12 * s0 * tt) & (spread > 0.0)
        alpha[start:stop] = np.where(ok, (s0 * s1y - s1 * sy) / np.where(ok, spread, 1.0), 0.0)
        sums, weighed = np.array([s0[-1], s1[-1], s2[-1], sy[-1], s1y[-1]]), time[stop - 1]
        start = stop
    return alpha


def accepted_samples(time, angle, omega, max_speed, max_jump=math.inf):
    """
    Which samples the live node accepts, vectorised (see :func:`sample_problem`).

    Finite angle and speed, |omega| <= max_speed, and a stamp the node's
    :class:`StampGate` takes. Returns a boolean array; :func:`gate_samples` also
    says where the time line restarted.
    """
    return gate_samples(time, angle, omega, max_speed, max_jump)[0]


def gate_samples(time, angle, omega, max_speed, max_jump=math.inf):
    """
    Return (accepted, restarted): boolean arrays over the samples, as the live node decides.

    Without implausible stamps (every valid one after the previous valid one by at most
    ``max_jump``) this is a few numpy calls; otherwise the valid samples go through a
    :class:`StampGate` one by one (a damaged stream only).
    """
    import numpy as np

    time = np.asarray(time, float)
    valid = np.isfinite(angle) & np.isfinite(omega) & (np.abs(omega) <= max_speed)
    restarted = np.zeros(len(time), bool)
    stamps = time[valid]
    steps = np.diff(stamps)
    if np.all((steps > 0.0) & (steps <= max_jump)):
        return valid, restarted
    accepted = np.zeros(len(time), bool)
    gate = StampGate(max_jump)
    for index in np.flatnonzero(valid).tolist():
        accepted[index] = gate.check(float(time[index])) is None
        restarted[index] = gate.restarted
    return accepted, restarted


def accepted_motion(time, angle, omega, max_speed, time_constant, max_jump=MAX_STAMP_JUMP):
    """
    Return (accepted, alpha): the samples the live node takes, and its alpha for each of them.

    ``accepted`` is a boolean array over the samples (:func:`gate_samples`); ``alpha``
    (rad/s^2) the :class:`AccelerationEstimator` of the accepted ones, started afresh
    where their time line restarted, as the node resets it.
    """
    import numpy as np

    accepted, restarted = gate_samples(time, angle, omega, max_speed, max_jump)
    t, w = np.asarray(time, float)[accepted], np.asarray(omega, float)[accepted]
    bounds = [0, *np.flatnonzero(restarted[accepted]).tolist(), len(t)]
    alpha = np.zeros(len(t))
    for start, stop in zip(bounds[:-1], bounds[1:]):
        alpha[start:stop] = acceleration_series(t[start:stop], w[start:stop], time_constant)
    return accepted, alpha
