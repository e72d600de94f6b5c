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
"""s: how far a motion sample's stamp may run ahead of the receive clock (the node's default)."""

LINE_SLEW = 0.01
"""
s per s: how fast a time line's offset from the receive clock may follow its stamps.

Clocks differ in rate by parts per million (10^-4 at worst, an undisciplined crystal), so
1 % lets a line follow any clock; a run of stamps that creeps ahead of the receive clock
would gain max_stamp_jump + 0.01 s per s of receive time (11.6 days ahead: 3 years).
"""

NANOSECONDS = 1_000_000_000


def stamp_problem(sec, nanosec):
    """Say what is wrong with a header stamp (``builtin_interfaces/Time``), or return None."""
    if not 0 <= nanosec < NANOSECONDS:
        return f'stamp nanosec {nanosec} not below 10^9 (sec {sec})'
    if sec < 0 or sec == 0 and nanosec == 0:
        return f'stamp {sec}.{nanosec:09d} s: unset (0) or before 0'
    return None


def stamp_seconds(sec, nanosec):
    """
    Return a header stamp in s, rounded as a bag's nanoseconds are (``ns * 1e-9``).

    Not ``sec + nanosec * 1e-9``: at 1.7e9 s a float resolves 0.24 us, and two roundings
    that differ move the alpha estimate (the live node and the replay would disagree by
    1e-8 of the bearing load).
    """
    return (sec * NANOSECONDS + nanosec) * 1e-9


class StampGate:
    """
    Stamps of a motion stream on one time line with the receive clock.

    Each sample comes with its stamp t and its receive time r (s: the node's monotonic
    clock, the bag's log time offline). A sample is on the time line when its stamp is
    after the last accepted one, has advanced by no more than the receive clock did plus
    ``max_jump``, and runs no more than ``max_jump`` ahead of the line t = r + offset. The
    offset is that of the line's first sample, and follows the stamps' offset t - r by at
    most :data:`LINE_SLEW` per second of receive time: clock drift, not a jump. So no
    sample, and no run of samples that agree with one another, is ever accepted more than
    ``max_jump`` ahead of the receive clock's line. Stamps that advance less than the
    receive clock (a pause, a slower simulation clock) are on the line.

    A sample off the line is rejected. While the line is alive (its last sample received
    less than ``max_jump`` ago) that is all: far-future stamps sent in pairs cannot take
    over a stream that goes on. After the line has been silent for ``max_jump``, a sample
    off it (a restarted driver, a clock stepped either way) is remembered; when the next
    sample follows it plausibly (as a sample follows on a line), a new time line starts
    at that next sample (``restarted``). With ``max_jump`` inf the gate only keeps the
    order of the stamps.
    """

    restarted = False

    def __init__(self, max_jump=math.inf):
        """Start with no stamp; ``max_jump`` s (> 0) is the largest plausible lead."""
        if not max_jump > 0.0:
            raise ValueError(f'max_jump must be > 0 s, got {max_jump}')
        self.max_jump = max_jump
        self.last = None            # stamp, s, of the last accepted sample
        self.received = None        # its receive time, s
        self.offset = None          # the line: stamp - receive time, s
        self._candidate = None      # (stamp, receive time) of a sample off a silent line

    def check(self, time, receive):
        """
        Return None and take the sample stamped ``time`` received at ``receive`` (s), or why not.

        ``restarted`` is True after a call that moved to a new time line (the caller
        resets what depends on the time line: the alpha estimate).
        """
        self.restarted = False
        if not time > 0.0:
            return f'stamp {time:.9f} s: unset (0) or before 0'
        if self.last is None:
            self._start(time, receive)
            return None
        problem = self._off_line(time, receive)
        if problem is None:
            elapsed = max(receive - self.received, 0.0)
            step = LINE_SLEW * elapsed
            self.offset += min(max(time - receive - self.offset, -step), step)
            self.last, self.received, self._candidate = time, receive, None
            return None
        if receive - self.received > self.max_jump:       # the line is silent
            candidate = self._candidate
            if candidate is not None and _follows(candidate, time, receive, self.max_jump):
                self._start(time, receive)
                self.restarted = True
                return None
            self._candidate = (time, receive)
        return problem

    def _start(self, time, receive):
        self.last, self.received, self.offset = time, receive, time - receive
        self._candidate = None

    def _off_line(self, time, receive):
        """Say why a sample is off the time line, or return None."""
        if time <= self.last:
            return f'stamp {time:.9f} s not after the previous {self.last:.9f} s'
        elapsed = receive - self.received
        if not _follows((self.last, self.received), time, receive, self.max_jump):
            return (f'stamp {time:.9f} s jumps {time - self.last:.6g} s past the previous, '
                    f'received {elapsed:.3g} s after it (max_stamp_jump {self.max_jump:g} s)')
        lead = time - receive - self.offset - LINE_SLEW * max(elapsed, 0.0)
        if lead > self.max_jump:
            return (f'stamp {time:.9f} s runs {lead:.3g} s ahead of the receive clock '
                    f'(max_stamp_jump {self.max_jump:g} s; stamps faster than real time?)')
        return None


def _follows(previous, time, receive, max_jump):
    """Whether a sample (``time``, ``receive``) follows ``previous`` (stamp, receive) plausibly."""
    last, received = previous
    return 0.0 < time - last <= max(receive - received, 0.0) + max_jump


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


def accepted_samples(time, angle, omega, max_speed, max_jump=math.inf, receive=None):
    """
    Which samples the live node accepts, vectorised (see :func:`sample_problem`).

    Finite angle and speed, |omega| <= max_speed, and a stamp the node's
    :class:`StampGate` takes. Returns a boolean array; :func:`gate_samples` also
    says where the time line restarted.
    """
    return gate_samples(time, angle, omega, max_speed, max_jump, receive)[0]


def gate_samples(time, angle, omega, max_speed, max_jump=math.inf, receive=None):
    """
    Return (accepted, restarted): boolean arrays over the samples, as the live node decides.

    ``time``: the stamps, s; ``receive``: their receive times, s (a bag's log times play
    the node's receive clock), needed with a finite ``max_jump``. When every valid
    sample is on one time line (each after the previous, advanced by no more than the
    receive clock plus ``max_jump``, and the stamps' offsets from the receive times
    within ``max_jump`` of one another: then no offset runs further ahead of the
    :class:`StampGate`'s line) this is a few numpy calls; otherwise the valid samples go
    through a :class:`StampGate` one by one.
    """
    import numpy as np

    time = np.asarray(time, float)
    if receive is None:
        if math.isfinite(max_jump):
            raise ValueError('a finite max_jump needs the receive times')
        receive = np.zeros(len(time))
    receive = np.asarray(receive, float)
    valid = np.isfinite(angle) & np.isfinite(omega) & (np.abs(omega) <= max_speed)
    restarted = np.zeros(len(time), bool)
    stamps, received = time[valid], receive[valid]
    steps, elapsed = np.diff(stamps), np.maximum(np.diff(received), 0.0)
    offsets = stamps - received
    if np.all(stamps > 0.0) and np.all((steps > 0.0) & (steps <= elapsed + max_jump)) and (
            not len(offsets) or offsets.max() - offsets.min() <= max_jump):
        return valid, restarted
    accepted = np.zeros(len(time), bool)
    gate = StampGate(max_jump)
    for index in np.flatnonzero(valid).tolist():
        accepted[index] = gate.check(float(time[index]), float(receive[index])) is None
        restarted[index] = gate.restarted
    return accepted, restarted


def accepted_motion(time, receive, angle, omega, max_speed, time_constant,
                    max_jump=MAX_STAMP_JUMP):
    """
    Return (accepted, alpha): the samples the live node takes, and its alpha for each of them.

    ``time``: the stamps, s; ``receive``: the receive times, s (a bag's log times).

    ``accepted`` is a boolean array over the samples (:func:`gate_samples`); ``alpha``
    (rad/s^2) the :class:`AccelerationEstimator` of the accepted ones, started afresh
    where their time line restarted, as the node resets it.
    """
    import numpy as np

    accepted, restarted = gate_samples(time, angle, omega, max_speed, max_jump, receive)
    t, w = np.asarray(time, float)[accepted], np.asarray(omega, float)[accepted]
    bounds = [0, *np.flatnonzero(restarted[accepted]).tolist(), len(t)]
    alpha = np.zeros(len(t))
    for start, stop in zip(bounds[:-1], bounds[1:]):
        alpha[start:stop] = acceleration_series(t[start:stop], w[start:stop], time_constant)
    return accepted, alpha
