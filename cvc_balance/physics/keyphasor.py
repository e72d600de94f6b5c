"""
A once-per-revolution mark (keyphasor, tach) instead of an encoder.

The rotor angle, speed and steady stretches from its marks.

A keyphasor sees one mark on the rotor once a turn (an optical pick-up on a reflective
strip, a magnetic or proximity probe at a notch). Its marks are the times the rotor angle
passes 0 (mod 2 pi). Between two marks the angle is interpolated, so it is 0 at every
mark and turns one revolution per period (with the speeds of the two marks as its slopes:
:meth:`Marks.motion`).

Marks come from a sampled tach signal (:func:`signal_marks`: where it crosses a threshold,
each crossing timed by linear interpolation between the two samples around it, with a
hysteresis band so noise near the threshold makes no extra mark) or one time per mark (a
TimeReference). :func:`checked_marks` checks every period against its neighbours': a period
about n = 2 or 3 times theirs lost n - 1 marks (put back, evenly: ``missed``); two
periods that add up to one of theirs, one of them short, hold an extra mark (dropped:
``doubled``); any other period off by more than :data:`PERIOD_TOLERANCE` is
``irregular``: no angle or speed is given
inside it. So a bad mark is repaired, or leaves a gap, and is counted; it never becomes a
wrong speed.

Steadiness is judged on the mean speed over :data:`SPAN_REVS` revolutions centred on each
mark (:meth:`Marks.mark_speed`), 2 pi (j - i) / (t_j - t_i), within its run of good
periods (fewer, still centred, near the run's ends; at an end mark, the speed of its one
period carried on along the slope to the next mark's): a coarse tach (16-20 samples a
revolution, each mark timed to a fraction of a sample) reads to a few tenths of a percent.
The rotor's speed at a mark (:meth:`Marks.fitted_speed`, what the motion is made of) is
the slope there of the constant-acceleration curve fitted (least squares) to the marks
of :data:`SPAN_REVS` revolutions about it: a mean over revolutions is off on a ramp (the
revolutions before a mark take longer than those after: 1.7 % at 23 rad/s and 4 rad/s^2
over 8), the fit is exact there. Between marks the speed is interpolated linearly and
the acceleration is its slope. Everything is vectorised over samples.

Times s, angles rad, speeds rad/s, accelerations rad/s^2.
"""

from collections import deque
from dataclasses import dataclass
import math

import numpy as np

EDGES = ('rising', 'falling')
"""Which crossing of the threshold is the mark."""
HYSTERESIS = 0.1
"""Half-width of the band around the threshold, as a fraction of high - low level."""
PERIOD_TOLERANCE = 0.2
"""A period within +-20 % of its neighbours' (median) is one revolution."""
NEIGHBOURS = 3
"""Periods either side whose median a period is checked against."""
MAX_MISSED = 2
"""Most marks put back in one period (a period about 3 times its neighbours'); longer is a gap."""
SPAN_REVS = 8
"""Revolutions the speed at a mark is averaged over (centred)."""
MIN_STRETCH_REVS = 8
"""Fewest whole revolutions of a steady stretch."""
SAMPLES_PER_REV = 64
"""Motion samples a revolution made from a tach of mark times (it has no samples)."""
CHANGE = 0.01
"""Revolutions a mark may lead (or lag) the live fit's prediction before the fit restarts."""
SCATTER_GAIN = 0.1
"""Weight of each new mark in the live marks' mean scatter on the fit."""
TWO_PI = 2.0 * math.pi


def signal_levels(values):
    """
    Return (low, high): the tach signal's two levels.

    The median of the samples below, and of those above, the middle of its range (so a
    narrow pulse, a few samples a revolution, still has its own level). Raises ValueError
    when the signal has no two levels.
    """
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    if len(values) < 2:
        raise ValueError(f'tach signal has {len(values)} finite samples: no marks')
    lowest, highest = float(values.min()), float(values.max())
    if not highest > lowest:
        raise ValueError(f'tach signal is flat at {lowest:.6g}: no marks')
    middle = 0.5 * (lowest + highest)
    return (float(np.median(values[values <= middle])),
            float(np.median(values[values > middle])))


def signal_marks(time, values, edge='rising', threshold=None, hysteresis=HYSTERESIS):
    """
    Return the mark times (s, increasing) of a sampled tach signal.

    ``time`` s (increasing) and ``values`` (any unit) of each sample; ``edge`` 'rising' or
    'falling'; ``threshold`` in the signal's unit (default: midway between its two levels,
    :func:`signal_levels`). A crossing counts once the signal has been beyond
    ``hysteresis`` (fraction of high - low) on each side of the threshold; its time is
    interpolated linearly between the last sample before the threshold and the next.
    """
    if edge not in EDGES:
        raise ValueError(f'keyphasor edge must be rising or falling, got {edge!r}')
    time, values = np.asarray(time, float), np.asarray(values, float)
    finite = np.isfinite(time) & np.isfinite(values)
    time, values = time[finite], values[finite]
    low, high = signal_levels(values)
    if threshold is None:
        threshold = 0.5 * (low + high)
    elif not math.isfinite(threshold):
        raise ValueError(f'keyphasor threshold must be finite, got {threshold}')
    band = hysteresis * (high - low)
    above = (values - threshold) if edge == 'rising' else (threshold - values)
    # The samples beyond the band on either side; an edge is one above it whose last such
    # sample before was below it (samples inside the band change nothing).
    decided = np.flatnonzero(np.abs(above) > band)
    high_side = above[decided] > 0.0
    edges = decided[1:][high_side[1:] & ~high_side[:-1]]
    # The crossing lies after the last sample below the threshold before the edge.
    below = np.flatnonzero(above < 0.0)
    before = below[np.searchsorted(below, edges) - 1]
    after = before + 1
    share = -above[before] / (above[after] - above[before])
    return time[before] + share * (time[after] - time[before])


@dataclass(frozen=True)
class Marks:
    """
    A tach's marks after checking (see the module's description).

    ``time`` s, increasing; ``good`` per period (len(time) - 1): one revolution between
    mark k and k + 1 (False: irregular, a gap). ``found`` marks the tach gave; ``missed``
    marks put back, ``doubled`` extra marks dropped, ``irregular`` periods left as gaps.
    """

    time: np.ndarray
    good: np.ndarray
    found: int
    missed: int = 0
    doubled: int = 0
    irregular: int = 0

    @property
    def revolutions(self):
        """Return the revolutions between good marks (the number of good periods)."""
        return int(self.good.sum())

    def angle(self, time):
        """
        Return the unwrapped rotor angle at ``time`` (s), rad: 2 pi k at mark k (:meth:`motion`).

        NaN before the first mark, after the last and inside irregular periods.
        """
        return self.motion(time)[0]

    def mark_speed(self, span=SPAN_REVS):
        """
        Return the speed (rad/s) at each mark: the mean over ``span`` revolutions centred on it.

        Within the mark's run of good periods; near its ends the span shrinks to stay
        centred (so a steady ramp reads its own slope there too); at an end mark it is the
        speed of the one period beside it carried on to the mark along the slope to the
        next mark's speed. NaN at a mark with no good period either side.
        """
        n = len(self.time)
        if n < 2:
            return np.full(n, np.nan)
        index = np.arange(n)
        bad_before = np.concatenate([[True], ~self.good])    # no good period before mark k
        bad_after = np.concatenate([~self.good, [True]])
        first = np.maximum.accumulate(np.where(bad_before, index, 0))
        last = np.minimum.accumulate(np.where(bad_after, index, n - 1)[::-1])[::-1]
        half = np.minimum(np.minimum(index - first, last - index), max(int(span) // 2, 1))
        lo, hi = index - half, index + half
        with np.errstate(divide='ignore', invalid='ignore'):
            speed = TWO_PI * (hi - lo) / (self.time[hi] - self.time[lo])
            # An end mark of a run: its one period's speed (that of the period's middle)
            # carried on to the mark along the slope to the next mark's speed.
            ahead = index[(half == 0) & (last > index)]
            behind = index[(half == 0) & (first < index)]
            period_ahead = TWO_PI / (self.time[ahead + 1] - self.time[ahead])
            period_behind = TWO_PI / (self.time[behind] - self.time[behind - 1])
            next_speed = speed[np.minimum(ahead + 1, n - 1)]
            previous_speed = speed[np.maximum(behind - 1, 0)]
        one_period = last[ahead] - first[ahead] == 1
        speed[ahead] = np.where(one_period, period_ahead, 2.0 * period_ahead - next_speed)
        one_period = last[behind] - first[behind] == 1
        speed[behind] = np.where(one_period, period_behind,
                                 2.0 * period_behind - previous_speed)
        return speed                # a lone mark (first == last): 0 / 0 above, NaN

    def fitted_speed(self, span=SPAN_REVS):
        """
        Return the speed (rad/s) at each mark: the slope of a constant-acceleration fit.

        The marks (angle 2 pi k at time t_k) of ``span`` revolutions about the mark,
        within its run of good periods (centred where the run allows, else the run's
        first or last ``span``; all of a shorter run), fitted by least squares with
        a + b (t - t_mark) + c (t - t_mark)^2; the speed is b. Exact at any constant
        acceleration; at a steady speed the least-squares slope (noise sigma s of each
        mark: a relative sigma of s / sqrt(sum of the offsets^2)). A run of one period
        gives its mean speed at both marks; NaN at a mark with no good period beside it.
        """
        n = len(self.time)
        if n < 2:
            return np.full(n, np.nan)
        index = np.arange(n)
        bad_before = np.concatenate([[True], ~self.good])
        bad_after = np.concatenate([~self.good, [True]])
        first = np.maximum.accumulate(np.where(bad_before, index, 0))
        last = np.minimum.accumulate(np.where(bad_after, index, n - 1)[::-1])[::-1]
        span = max(int(span), 1)
        width = np.minimum(last - first, span)
        lo = np.clip(index - width // 2, first, last - width)
        speed = np.full(n, np.nan)
        # Most marks: a whole span centred on them (the windows are views of the times,
        # the turns the same for all); the others (near a run's ends) gathered one by one.
        half = span // 2
        centred = (width == span) & (lo == index - half)
        if n > span and centred[half:n - span + half].any():
            # Windows as slices of the times: point j of mark k is mark k - half + j.
            middle = self.time[half:n - span + half]
            offsets = np.stack([self.time[j:n - span + j] - middle for j in range(span + 1)])
            inner = speed[half:n - span + half]
            found = fit_at_zero(offsets, TWO_PI * (np.arange(span + 1) - half))[1]
            use = centred[half:n - span + half]
            inner[use] = found[use]
        else:
            centred[:] = False
        other = ~centred & (width > 0)
        if other.any():
            columns = np.arange(span + 1)[:, None]
            rows = np.minimum(lo[other] + columns, n - 1)
            speed[other] = fit_at_zero(self.time[rows] - self.time[other],
                                       TWO_PI * (rows - index[other]),
                                       columns <= width[other])[1]
        return speed

    def motion(self, time, span=SPAN_REVS, acceleration=True):
        """
        Return (angle, omega, alpha) at ``time`` (s): unwrapped rad, rad/s, rad/s^2.

        ``acceleration`` False: alpha is None (not computed).

        Within a period, the cubic that turns from 2 pi k to 2 pi (k + 1) with the
        :meth:`fitted_speed` of its two marks as its slopes there (Hermite): exact at a
        constant acceleration, where a straight line between the marks is off by up to
        alpha T^2 / 8 (0.16 rad at 10 rad/s and 4 rad/s^2); omega and alpha are its
        derivatives, so the three agree. NaN before the first mark, after the last and
        inside irregular periods.
        """
        time = np.atleast_1d(np.asarray(time, float))
        n = len(self.time)
        if n < 2:
            nothing = np.full(len(time), np.nan)
            return nothing, nothing.copy(), nothing.copy()
        speed = self.fitted_speed(span)
        period = np.diff(self.time)
        # Per period, one row each: its mark, 1 / its length (NaN in an irregular one: no
        # angle there), the cubic, 2 pi k; gathered for every sample at once.
        rate = np.where(self.good, 1.0 / period, np.nan)
        table = np.stack([self.time[:-1], rate, *cubic(period, speed[:-1], speed[1:]),
                          TWO_PI * np.arange(n - 1)])
        k = np.clip(_marks_before(self.time, time) - 1, 0, n - 2)
        mark, rate, a1, a2, a3, turns = table[:, k]
        share = (time - mark) * rate
        angle, omega, alpha = cubic_motion(share, (a1, a2, a3), rate, acceleration)
        angle += turns
        outside = (time < self.time[0]) | (time > self.time[-1])
        if outside.any():           # before the first mark, after the last
            for values in (angle, omega, alpha):
                if values is not None:
                    values[outside] = np.nan
        return angle, omega, alpha


def fit_at_zero(offsets, turns, valid=None):
    """
    Return, per row, (value, slope, second derivative) at 0 of a least-squares quadratic.

    ``offsets`` (points, rows) s, ``turns`` (points, rows, or one per point for all) rad,
    ``valid`` (points, rows; None: all) the points that count: two give the chord (its
    value, slope and 0), three or more the quadratic's a + b x + c x^2 (a, b and 2 c, by
    Cramer's rule on the normal equations). NaN for a row of fewer than two. The sums run
    point by point over whole rows (a few long vectors, not many short ones).
    """
    offsets = np.asarray(offsets, float)
    turns = np.broadcast_to(np.asarray(turns, float).reshape(
        len(offsets), -1), offsets.shape)
    if valid is not None:       # the points that do not count: 0 (x and y), uncounted
        weight = np.asarray(valid, bool)
        offsets, turns = np.where(weight, offsets, 0.0), np.where(weight, turns, 0.0)
        n = weight.sum(axis=0).astype(float)
    else:
        n = float(len(offsets))
    scale = np.max(np.abs(offsets), axis=0)
    scale[~(scale > 0.0)] = 1.0
    inverse = 1.0 / scale
    s1, s2, s3, s4, r0, r1, r2 = (np.zeros(offsets.shape[1]) for _ in range(7))
    for offset, y in zip(offsets, turns):
        x = offset * inverse                                # within [-1, 1]
        x2 = x * x
        s1 += x
        s2 += x2
        s3 += x2 * x
        s4 += x2 * x2
        r0 += y
        r1 += y * x
        r2 += y * x2
    with np.errstate(divide='ignore', invalid='ignore'):
        a, b, c = _normal_solution(n, s1, s2, s3, s4, r0, r1, r2)
        through, chord = _chord(s1, s2, r0, r1)
    value = np.where(n == 2, through, np.where(n >= 3, a, np.nan))
    slope = np.where(n == 2, chord, np.where(n >= 3, b, np.nan)) / scale
    curvature = np.where(n == 2, 0.0, np.where(n >= 3, 2.0 * c, np.nan)) / (scale * scale)
    return value, slope, curvature


def _normal_solution(n, s1, s2, s3, s4, r0, r1, r2):
    """
    Return (a, b, c) of the least-squares a + b x + c x^2 from its sums (arrays or floats).

    n points, s_p the sums of x^p, r_p of y x^p: [[n s1 s2] [s1 s2 s3] [s2 s3 s4]]
    (a b c) = (r0 r1 r2), by Cramer's rule.
    """
    det = n * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s2 * s3) + s2 * (s1 * s3 - s2 * s2)
    return ((r0 * (s2 * s4 - s3 * s3) - s1 * (r1 * s4 - s3 * r2)
             + s2 * (r1 * s3 - s2 * r2)) / det,
            (n * (r1 * s4 - s3 * r2) - r0 * (s1 * s4 - s2 * s3) + s2 * (s1 * r2 - r1 * s2)) / det,
            (n * (s2 * r2 - r1 * s3) - s1 * (s1 * r2 - r1 * s2) + r0 * (s1 * s3 - s2 * s2)) / det)


def _chord(s1, s2, r0, r1):
    """Return (value at 0, slope) of the line through two points from their sums."""
    slope = (r1 / 2.0 - s1 * r0 / 4.0) / (s2 / 2.0 - s1 * s1 / 4.0)
    return (r0 - slope * s1) / 2.0, slope


def cubic(period, start_speed, end_speed):
    """
    Return (a1, a2, a3): a period's angle 2 pi k + a1 s + a2 s^2 + a3 s^3, s in [0, 1].

    The cubic that turns one revolution over ``period`` (s) with the speeds (rad/s) at
    its two marks as its slopes (Hermite): exact at a constant acceleration. Arrays or
    floats.
    """
    start, end = start_speed * period, end_speed * period      # rad a period
    return start, 3.0 * TWO_PI - 2.0 * start - end, start + end - 2.0 * TWO_PI


def cubic_motion(share, coefficients, rate, acceleration=True):
    """
    Return (angle since the period's mark rad, omega, alpha) of :func:`cubic` at ``share``.

    ``rate``: 1 / the period's length (1/s); ``acceleration`` False: alpha None.
    """
    a1, a2, a3 = coefficients
    return (share * (a1 + share * (a2 + share * a3)),
            (a1 + share * (2.0 * a2 + 3.0 * share * a3)) * rate,
            (2.0 * a2 + 6.0 * share * a3) * (rate * rate) if acceleration else None)


def _marks_before(marks, time):
    """
    Return, per sample time, how many marks are at or before it (searchsorted, right).

    Samples in order (as read from a bag): counted from where each mark falls among them
    (a cumulative sum, not a search per sample).
    """
    if len(time) > 1 and np.all(time[1:] >= time[:-1]):
        where = np.searchsorted(time, marks, side='left')
        return np.cumsum(np.bincount(where, minlength=len(time) + 1)[:len(time)])
    return np.searchsorted(marks, time, side='right')


def marks_summary(topic, found, missed, doubled, irregular, revolutions):
    """Return the one line that says what a tach's marks' check found (offline and live)."""
    return (f'keyphasor {topic}: {found} marks, {missed} missed (put back), {doubled} doubled '
            f'(dropped), {irregular} irregular periods (no angle there), {revolutions} '
            'revolutions')


def checked_marks(times, tolerance=PERIOD_TOLERANCE, neighbours=NEIGHBOURS):
    """
    Return the :class:`Marks` of raw mark ``times`` (s), checked and repaired.

    Doubled marks are dropped, missed ones put back, irregular periods marked as gaps
    (see the module's description); the counts are in the result. Not finite times are
    left out; the rest are sorted.
    """
    times = np.asarray(times, float)
    times = np.unique(times[np.isfinite(times)])
    found = len(times)
    if found < 2:
        return Marks(times, np.zeros(max(found - 1, 0), bool), found)
    doubled, usual = 0, None
    while len(times) > 3:                       # an extra mark splits one period in two
        periods = np.diff(times)
        usual = _neighbours_median(periods, neighbours)
        short = periods < (1.0 - tolerance) * usual
        pair = periods[:-1] + periods[1:]
        usual_pair = np.minimum(usual[:-1], usual[1:])
        extra = (short[:-1] | short[1:]) & (np.abs(pair / usual_pair - 1.0) <= tolerance)
        extra &= ~np.concatenate([[False], extra[:-1]])     # of three in a row, the first
        if not extra.any():
            break
        doubled += int(extra.sum())
        times, usual = np.delete(times, np.flatnonzero(extra) + 1), None
    periods = np.diff(times)
    if usual is None:
        usual = _neighbours_median(periods, neighbours)
    ratio = periods / usual
    turns = np.rint(ratio).astype(np.int64)
    lost = (turns >= 2) & (turns <= MAX_MISSED + 1) & \
        (np.abs(ratio / np.maximum(turns, 1) - 1.0) <= tolerance)
    missed = int((turns[lost] - 1).sum())
    if missed:
        counts = np.where(lost, turns, 1)
        start = np.repeat(times[:-1], counts)
        step = np.repeat(periods / counts, counts)
        within = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        times = np.concatenate([start + within * step, times[-1:]])
        periods = np.diff(times)
        usual = _neighbours_median(periods, neighbours)
        ratio = periods / usual
    good = np.abs(ratio - 1.0) <= tolerance
    return Marks(times, good, found, missed, doubled, int((~good).sum()))


def _neighbours_median(periods, neighbours):
    """
    Median of the ``neighbours`` periods either side of each (itself left out).

    At the ends, the periods beyond are the ones inside reflected (each end period's
    neighbours are all on one side).
    """
    n = len(periods)
    if n < 2:
        return periods.copy()
    reach = min(neighbours, n - 1)
    padded = np.pad(periods, reach, mode='reflect')
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * reach + 1)
    around = np.sort(np.delete(windows, reach, axis=1), axis=1)
    return 0.5 * (around[:, reach - 1] + around[:, reach])


@dataclass(frozen=True)
class Stretch:
    """
    A stretch of steady speed between two marks: whole revolutions.

    ``start``/``end`` s (mark times), ``first``/``last`` their mark indices; ``speed`` the
    mean speed over it, rad/s (2 pi revolutions / duration); ``revolutions``; ``spread``
    the largest relative deviation of a mark's speed from ``speed``.
    """

    start: float
    end: float
    first: int
    last: int
    speed: float
    revolutions: int
    spread: float


def steady_stretches(marks, tolerance=0.01, min_revolutions=MIN_STRETCH_REVS, span=SPAN_REVS):
    """
    Return the :class:`Stretch` es of steady speed of ``marks`` (:class:`Marks`), in order.

    A stretch is a run of good periods along which every mark's speed
    (:meth:`Marks.mark_speed` over ``span`` revolutions) stays within +-``tolerance`` of
    the middle of their range, then trimmed to its longest run within +-``tolerance`` of
    its median speed, of at least ``min_revolutions``. Stretches are taken greedily from
    the start; they never overlap and never hold a gap.
    """
    if not tolerance > 0.0:
        raise ValueError(f'speed tolerance must be > 0, got {tolerance}')
    speed = marks.mark_speed(span)
    speed_list, good = speed.tolist(), marks.good.tolist()
    stretches, n, i = [], len(speed_list), 0
    while i < n - 1:
        if not math.isfinite(speed_list[i]) or not good[i]:
            i += 1
            continue
        low = high = speed_list[i]
        j = i
        while j + 1 < n and good[j] and math.isfinite(speed_list[j + 1]):
            s = speed_list[j + 1]
            new_low, new_high = min(low, s), max(high, s)
            if new_high - new_low > tolerance * (new_high + new_low):
                break
            low, high, j = new_low, new_high, j + 1
        if j - i < min_revolutions:
            i += 1
            continue
        # Trimmed to its longest run within +-tolerance of its median: a stretch that
        # began on the end of a ramp keeps only the steady part.
        median = float(np.median(speed[i:j + 1]))
        near = np.abs(speed[i:j + 1] - median) <= tolerance * median
        start, stop = _longest_run(near)
        first, last = i + start, i + stop - 1
        if last - first >= min_revolutions:
            inside = speed[first:last + 1]
            mean = TWO_PI * (last - first) / float(marks.time[last] - marks.time[first])
            stretches.append(Stretch(float(marks.time[first]), float(marks.time[last]), first,
                                     last, mean, last - first,
                                     float(np.max(np.abs(inside - mean)) / mean)))
        i = max(last, i + 1)
    return stretches


def _longest_run(mask):
    """Return (start, stop) of the longest run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    longest = int(np.argmax(stops - starts))
    return int(starts[longest]), int(stops[longest])


LEVEL_FIRST = 256
"""Samples a live tach signal's levels are first judged over."""
LEVEL_WINDOW = 4096
"""Samples (the latest) its levels are judged over, at most every so many samples."""


class LiveSignal:
    """
    A sampled tach's marks as its samples come (the node's): :func:`signal_marks` looking back.

    The same crossings (``edge``, ``threshold``, ``hysteresis``; a crossing counts once
    the signal has been beyond the band on each side, timed between the last sample
    below the threshold and the next): a sample can only end a crossing, never move one.
    The levels are those of the first :data:`LEVEL_FIRST` samples (no marks before), judged
    again each time the samples have doubled, then every :data:`LEVEL_WINDOW` samples over
    the latest :data:`LEVEL_WINDOW`.
    """

    def __init__(self, edge='rising', threshold=None, hysteresis=HYSTERESIS):
        """Start with no samples; ``threshold`` None: midway between the signal's levels."""
        if edge not in EDGES:
            raise ValueError(f'keyphasor edge must be rising or falling, got {edge!r}')
        if threshold is not None and not math.isfinite(threshold):
            raise ValueError(f'keyphasor threshold must be finite, got {threshold}')
        self.sign = 1.0 if edge == 'rising' else -1.0
        self.given, self.hysteresis = threshold, hysteresis
        self.levels = None              # (low, high) once judged
        self.threshold = self.band = None
        self._values = deque(maxlen=LEVEL_WINDOW)
        self._until = LEVEL_FIRST       # samples until the levels are judged (again)
        self._seen = 0                  # samples taken
        self._high = None               # the side of the last sample beyond the band
        self._previous = None           # (time, signed distance) of the last sample
        self._crossing = None           # time of the last crossing from below
        self.spacing = 0.0              # s between the last two samples

    def sample(self, time, value):
        """
        Take a sample: ``time`` s (increasing) and ``value``.

        Return the time (s) of the mark it ends, or None.
        """
        if not (math.isfinite(time) and math.isfinite(value)):
            return None
        self._values.append(value)
        self._seen += 1
        self._until -= 1
        if self._until <= 0:
            self._judge_levels()
        if self.threshold is None:
            return None
        above = self.sign * (value - self.threshold)
        previous, self._previous = self._previous, (time, above)
        if previous is not None:
            self.spacing = time - previous[0]
        if above < 0.0:
            self._crossing = None
        elif previous is not None and previous[1] < 0.0:
            before, below = previous
            self._crossing = before + (-below / (above - below)) * (time - before)
        if above > self.band:
            mark = self._crossing if self._high is False else None
            self._high = True
            return mark
        if above < -self.band:
            self._high = False
        return None

    def _judge_levels(self):
        self._until = min(self._seen, LEVEL_WINDOW)     # after 256, 512, ... 4096, 4096 ...
        try:
            low, high = signal_levels(np.fromiter(self._values, float, len(self._values)))
        except ValueError:          # flat so far: no marks yet
            return
        self.levels = (low, high)
        self.threshold = 0.5 * (low + high) if self.given is None else self.given
        self.band = self.hysteresis * (high - low)


class LiveMarks:
    """
    A tach's marks checked as they come, looking back only (the node's).

    A run of good marks gives, at its newest mark, the speed and acceleration of the
    constant-acceleration fit to its last :data:`SPAN_REVS` revolutions
    (:func:`fit_at_zero`), hence the time the next revolution should take (``period``:
    on a ramp a median of the last periods would lag them by several). Each period is
    judged against it (:data:`PERIOD_TOLERANCE`): about one revolution is good; about
    n = 2 or 3 lost n - 1 marks (put back evenly: ``missed``); a short one is held until
    the next mark, and when the two make one revolution the held mark was extra
    (dropped: ``doubled``); anything else is ``irregular``: the marks start again, and
    :data:`LEARN` periods each within the tolerance of the one before (learning, as at
    the start) must come before an angle is given. Between marks the angle and speed are
    extrapolated along the fit (:meth:`motion_at`). No mark for ``MAX_MISSED + 1``
    periods and the tolerance: the marks start again. Times s (increasing), speeds rad/s.
    """

    LEARN = 3
    """Periods that must agree before the first angle (and after an irregular period)."""

    def __init__(self, tolerance=PERIOD_TOLERANCE, span=SPAN_REVS):
        """Start with no marks."""
        self.tolerance, self.span = tolerance, span
        self.found = self.missed = self.doubled = self.irregular = self.revolutions = 0
        self._run = deque(maxlen=span + 1)     # (time, speed, acceleration) of good marks
        self._learning = []                    # marks while learning
        self._held = None                      # a mark after a short period
        self.period = None                     # s the next revolution should take
        self._scatter = 0.0                    # mean |lead| of the marks on the fit, rev
        self._leads = 0                        # leads the scatter is the mean of
        self._offset = 0.0

    @property
    def ready(self):
        """Tell whether an angle can be given (the period is learnt)."""
        return self.period is not None

    @property
    def last(self):
        """Return the time (s) of the newest good mark, or None."""
        return self._run[-1][0] if self._run else None

    def mark(self, time, resolution=0.0):
        """
        Take a mark at ``time`` (s); return the good periods it completes, in order.

        Each as (start s, end s, speed at start, speed at end, rad/s). None for a mark not
        after the previous one (left out, not counted). ``resolution``: s the mark may be
        off by (a sampled tach's sample spacing: a 0/1 signal's crossing is timed to it).
        """
        newest = self._held if self._held is not None else (
            self.last if self.ready else (self._learning[-1] if self._learning else None))
        if newest is not None and not time > newest:
            return None
        self.found += 1
        if not self.ready:
            return self._learn(time)
        elapsed = time - self.last
        if self._held is not None:
            held, self._held = self._held, None
            if self._turns(elapsed) == 1:
                self.doubled += 1
                return self._take(time, resolution)
            self.irregular += 1                 # the short period was a period after all
            return self._restart(held, time)
        turns = self._turns(elapsed)
        if turns == 1:
            return self._take(time, resolution)
        if elapsed < (1.0 - self.tolerance) * self.period:
            self._held = time
            return []
        if turns:
            self.missed += turns - 1
            start, done = self.last, []
            for k in range(1, turns):
                done += self._take(start + k * (elapsed / turns))     # as checked_marks
            return done + self._take(time, resolution)
        self.irregular += 1
        return self._restart(time)

    def motion_at(self, time):
        """
        Return (angle rad since the newest good mark, omega rad/s), or a reason there is none.

        Extrapolated along the constant-acceleration fit at the newest mark, until the fit
        has the rotor stop (then the angle stays, omega 0: a tach sees no turning back); a
        reason (str) while the period is being learnt, or when no mark came for longer than
        ``MAX_MISSED + 1`` periods (then the marks start again).
        """
        if not self.ready:
            return (f'keyphasor: learning the period ({len(self._learning)} marks of '
                    f'{self.LEARN + 1})')
        last, speed, acceleration = self._run[-1]
        elapsed = time - last
        if elapsed > (MAX_MISSED + 1 + self.tolerance) * self.period:
            self.irregular += 1
            self._restart()
            return f'keyphasor: no mark for {elapsed:.3g} s (the rotor stopped?)'
        if acceleration < 0.0 < speed:
            elapsed = min(elapsed, -speed / acceleration)
        return (self._offset + speed * elapsed + 0.5 * acceleration * elapsed * elapsed,
                speed + acceleration * elapsed)

    def _turns(self, elapsed):
        """Return the revolutions (1 to MAX_MISSED + 1) ``elapsed`` s make, or 0: none."""
        _, speed, acceleration = self._run[-1]
        for turns in range(1, MAX_MISSED + 2):
            expected = _turn_time(speed, acceleration, turns, self.period * turns)
            if abs(elapsed / expected - 1.0) <= self.tolerance:
                return turns
        return 0

    def _learn(self, time):
        """Take a mark while learning; once LEARN periods agree, they are the first good ones."""
        marks = self._learning
        marks.append(time)
        if len(marks) < self.LEARN + 1:
            return []
        periods = np.diff(marks)
        if np.any(np.abs(periods[1:] / periods[:-1] - 1.0) > self.tolerance):
            del marks[0]
            self.irregular += 1
            return []
        self._learning = []
        done = []
        for mark in marks:
            done += self._take(mark)
        return done

    def _take(self, time, resolution=0.0):
        """Add a good mark; return the good period it ends (none for a run's first)."""
        run = self._run
        previous = run[-1] if run else None
        if previous is not None and len(run) > 3 and self.period is not None:
            # The mark's lead on the fit's prediction (revolutions): a change of
            # acceleration shows as one beyond the marks' own scatter; the fit then
            # forgets the revolutions before it (the speed follows within a few).
            lead = (time - previous[0]) / self.period - 1.0
            limit = max(CHANGE, 4.0 * self._scatter, 2.0 * resolution / self.period)
            if self._leads >= self.LEARN and abs(lead) > limit:
                for _ in range(len(run) - 2):
                    run.popleft()
            self._leads += 1
            self._scatter += max(SCATTER_GAIN, 1.0 / self._leads) * (abs(lead) - self._scatter)
        run.append((time, math.nan, 0.0))
        if previous is None:
            return []
        self._offset, speed, acceleration = _fit_run([r[0] - time for r in run])
        run[-1] = (time, speed, acceleration)
        if len(run) == 2:               # the run's first mark: its period's speed
            run[0] = (previous[0], speed, 0.0)
        self.period = _turn_time(speed, acceleration, 1, time - previous[0])
        self.revolutions += 1
        return [(previous[0], time, run[-2][1], speed)]

    def _restart(self, *marks):
        """Start again from ``marks`` (learning): nothing before them is trusted."""
        self._run.clear()
        self._held = None
        self.period = None
        self._learning = list(marks)
        return []


def _fit_run(offsets):
    """
    Return :func:`fit_at_zero` of one run of marks (plain floats: the node's, per mark).

    ``offsets`` s of its marks from the newest (the last, 0), one revolution apart.
    """
    scale = max(-offsets[0], 1e-300)
    last = len(offsets) - 1
    n = s1 = s2 = s3 = s4 = r0 = r1 = r2 = 0.0
    for k, offset in enumerate(offsets):
        x, y = offset / scale, TWO_PI * (k - last)
        x2 = x * x
        n, s1, s2, s3, s4 = n + 1.0, s1 + x, s2 + x2, s3 + x2 * x, s4 + x2 * x2
        r0, r1, r2 = r0 + y, r1 + y * x, r2 + y * x2
    if n == 2.0:
        value, slope = _chord(s1, s2, r0, r1)
        return value, slope / scale, 0.0
    value, slope, curvature = _normal_solution(n, s1, s2, s3, s4, r0, r1, r2)
    return value, slope / scale, 2.0 * curvature / (scale * scale)


def _turn_time(speed, acceleration, turns, otherwise):
    """
    Return the time (s) ``turns`` revolutions take from a mark at ``speed`` and ``acceleration``.

    The root of speed t + acceleration t^2 / 2 = 2 pi turns (in its stable form);
    ``otherwise`` when there is none (the rotor would stop first) or the speed is not
    forward.
    """
    angle = TWO_PI * turns
    root = speed * speed + 2.0 * acceleration * angle
    if not (speed > 0.0 and root > 0.0):
        return otherwise
    return 2.0 * angle / (speed + math.sqrt(root))
