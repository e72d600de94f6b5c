"""
Order tracking: a scalar channel's once-per-revolution (1x) amplitude and phase.

A field-balancing instrument reads each sensor's 1x vector against a once-per-turn
reference; here the reference is the encoder's angle q itself. Over a stretch of steady
speed cut to whole revolutions, the samples x_k at angles q_k are fitted by least squares
with x = c + a cos q + b sin q (synchronous demodulation: over whole revolutions sampled
evenly the columns are orthogonal and this is (2/n) sum x e^{-iq}); the 1x phasor is
X = a - i b, so that

    x(q) ~ c + Re(X e^{iq}) = c + |X| cos(q + arg X).

The phase is arg X: the signal peaks where the rotor angle is -arg X. A stator-frame force
x component from an unbalance U at rotor angle phi has X = omega^2 |U| e^{i phi} times the
support's share: its phase is the heavy spot's angle. Every harmonic but the first, and any
constant, is orthogonal to the fit over whole revolutions. The standard error of X (per
component, circular) comes from the fit's residual. Times s, angles rad, speeds rad/s.
"""

from dataclasses import dataclass
import math

import numpy as np

DEFAULT_TOLERANCE = 0.01
"""Relative speed band taken as steady: +-1 % of the steady speed."""
MIN_SAMPLES = 8
"""Fewest samples of a channel in the window to fit its 1x phasor."""


@dataclass(frozen=True)
class SteadyWindow:
    """
    A stretch of steady speed cut to whole revolutions.

    ``start``/``end`` s; ``speed`` the mean |omega| over it, rad/s; ``revolutions`` the
    whole turns in it; ``spread`` the largest relative deviation of |omega| from ``speed``.
    """

    start: float
    end: float
    speed: float
    revolutions: int
    spread: float


@dataclass(frozen=True)
class Phasor:
    """
    A channel's 1x phasor X (complex, the channel's unit) with x ~ offset + Re(X e^{iq}).

    ``sigma``: standard error of X's real and of its imaginary part; ``samples`` used.
    """

    value: complex
    sigma: float
    offset: float
    samples: int

    @property
    def amplitude(self):
        """Return |X|, the channel's unit."""
        return abs(self.value)

    @property
    def phase(self):
        """Return arg X, rad (the signal peaks at rotor angle -phase)."""
        return math.atan2(self.value.imag, self.value.real)


def steady_window(time, angle, omega, speed=None, tolerance=DEFAULT_TOLERANCE):
    """
    Return the longest :class:`SteadyWindow` of a run's motion.

    ``time`` s (increasing), ``angle`` rad (unwrapped), ``omega`` rad/s, arrays of one
    length. ``speed`` rad/s: the steady speed wanted (default: the speed the rotor spent
    most time at, in bands of ``tolerance``). Samples within +-``tolerance`` of it are
    steady; the longest unbroken stretch of them is cut to whole revolutions. Raises
    ValueError when there is no such stretch of at least one revolution.
    """
    return max(steady_stretches(time, angle, omega, speed, tolerance),
               key=lambda w: (w.revolutions, w.end - w.start))


def steady_stretches(time, angle, omega, speed=None, tolerance=DEFAULT_TOLERANCE):
    """
    Return every unbroken stretch at one steady speed, cut to whole revolutions, in order.

    Arguments as :func:`steady_window`'s; stretches under one revolution are left out.
    Raises ValueError when none is left.
    """
    time, angle = np.asarray(time, float), np.asarray(angle, float)
    magnitude = np.abs(np.asarray(omega, float))
    if len(time) < 2:
        raise ValueError('fewer than two motion samples: no steady speed to read')
    if not tolerance > 0.0:
        raise ValueError(f'speed tolerance must be > 0, got {tolerance}')
    target = busiest_speed(time, magnitude, tolerance) if speed is None else abs(speed)
    if not target > 0.0:
        raise ValueError('the rotor does not turn in this run')
    steady = np.abs(magnitude - target) <= tolerance * target
    stretches, longest = [], 0.0
    for start, stop in _runs(steady):
        if stop - start < 2:
            continue
        window = _whole_turns(time[start:stop], angle[start:stop], magnitude[start:stop])
        longest = max(longest, abs(angle[stop - 1] - angle[start]) / (2.0 * math.pi))
        if window is not None:
            stretches.append(window)
    if stretches:
        return stretches
    if longest == 0.0:
        raise ValueError(f'no steady stretch at {target:.4g} rad/s (+-{tolerance:.1%}): the '
                         f'run spans {magnitude.min():.4g}-{magnitude.max():.4g} rad/s')
    raise ValueError(f'the steady stretch at {target:.4g} rad/s turns {longest:.2f} '
                     'revolutions: at least one whole revolution is needed')


def _whole_turns(t, q, magnitude):
    """Return the :class:`SteadyWindow` of a steady stretch cut to whole turns, or None."""
    turned = abs(q[-1] - q[0])
    revolutions = int(math.floor(turned / (2.0 * math.pi) + 1e-9))
    if revolutions < 1:
        return None
    direction = 1.0 if q[-1] >= q[0] else -1.0
    end_angle = q[0] + direction * 2.0 * math.pi * revolutions
    # The angle is monotonic over a steady stretch: the time of the last whole turn.
    end = float(np.interp(direction * end_angle, direction * q, t))
    mean = float(np.mean(magnitude))
    return SteadyWindow(float(t[0]), end, mean, revolutions,
                        float(np.max(np.abs(magnitude - mean)) / mean))


def track(time, values, motion_time, motion_angle, window):
    """
    Return the 1x :class:`Phasor` of a channel over a :class:`SteadyWindow`.

    ``time`` s and ``values`` of the channel (any unit); ``motion_time`` s and
    ``motion_angle`` rad (unwrapped) of the encoder, interpolated at the channel's times.
    Samples outside the window or not finite are left out. Raises ValueError with fewer
    than :data:`MIN_SAMPLES` samples in the window.
    """
    time, values = np.asarray(time, float), np.asarray(values, float)
    inside = (time >= window.start) & (time < window.end) & np.isfinite(values) \
        & np.isfinite(time)
    count = int(inside.sum())
    if count < MIN_SAMPLES:
        raise ValueError(f'{count} samples in the steady window {window.start:.3f}-'
                         f'{window.end:.3f} s; at least {MIN_SAMPLES} are needed')
    q = np.interp(time[inside], motion_time, motion_angle)
    x = values[inside]
    design = np.column_stack([np.ones(count), np.cos(q), np.sin(q)])
    solution, _, rank, _ = np.linalg.lstsq(design, x, rcond=None)
    if rank < 3:
        raise ValueError('the channel\'s samples do not cover the revolution')
    residual = x - design @ solution
    dof = count - 3
    variance = float(residual @ residual) / dof if dof > 0 else math.inf
    covariance = np.linalg.inv(design.T @ design) * variance
    sigma = math.sqrt(0.5 * (covariance[1, 1] + covariance[2, 2]))
    c, a, b = (float(v) for v in solution)
    return Phasor(complex(a, -b), sigma, c, count)


def busiest_speed(time, magnitude, tolerance=DEFAULT_TOLERANCE):
    """Return the speed (rad/s) the rotor spent most time near (bands of ``tolerance``)."""
    dt = np.diff(time, append=time[-1])
    turning = magnitude > 1e-6 * max(float(magnitude.max()), 1e-300)
    if not turning.any():
        return 0.0
    logs = np.log(magnitude[turning])
    width = math.log1p(tolerance)
    bands = np.floor((logs - logs.min()) / width).astype(np.int64)
    spent = np.bincount(bands, weights=dt[turning])
    busiest = int(np.argmax(spent))
    return float(np.median(magnitude[turning][bands == busiest]))


def _runs(mask):
    """Return (start, stop) of each run of True in ``mask``, in order."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))
