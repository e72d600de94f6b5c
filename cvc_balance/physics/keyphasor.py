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
        speed[(half == 0) & (first == last)] = np.nan
        return speed

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
        width = np.minimum(last - first, max(int(span), 1))
        lo = np.clip(index - width // 2, first, last - width)
        columns = np.arange(max(int(span), 1) + 1)
        rows = np.minimum(lo[:, None] + columns, n - 1)
        valid = columns <= width[:, None]
        speed = slopes_at_zero(self.time[rows] - self.time[:, None],
                               TWO_PI * (rows - index[:, None]), valid)
        speed[width == 0] = np.nan
        return speed

    def motion(self, time, span=SPAN_REVS):
        """
        Return (angle, omega, alpha) at ``time`` (s): unwrapped rad, rad/s, rad/s^2.

        Within a period, the cubic that turns from 2 pi k to 2 pi (k + 1) with the
        :meth:`fitted_speed` of its two marks as its slopes there (Hermite): exact at a
        constant acceleration, where a straight line between the marks is off by up to
        alpha T^2 / 8 (0.16 rad at 10 rad/s and 4 rad/s^2); omega and alpha are its
        derivatives, so the three agree. NaN before the first mark, after the last and
        inside irregular periods.
        """
        k, s, inside = self._period(time)
        if len(self.time) < 2:
            nothing = np.full(len(k), np.nan)
            return nothing, nothing.copy(), nothing.copy()
        # Per period: angle = 2 pi k + a1 s + a2 s^2 + a3 s^3 (s its share elapsed), the
        # Hermite cubic's coefficients from the slopes a period: start, end (rad).
        speed = self.fitted_speed(span)
        period = np.diff(self.time)
        start, end = speed[:-1] * period, speed[1:] * period
        a1, a2, a3 = start, 3.0 * TWO_PI - 2.0 * start - end, start + end - 2.0 * TWO_PI
        a1, a2, a3, rate = a1[k], a2[k], a3[k], 1.0 / period[k]
        angle = TWO_PI * k + s * (a1 + s * (a2 + s * a3))
        omega = (a1 + s * (2.0 * a2 + 3.0 * s * a3)) * rate
        alpha = (2.0 * a2 + 6.0 * s * a3) * (rate * rate)
        if not inside.all():        # before the first mark, after the last, irregular
            for values in (angle, omega, alpha):
                values[~inside] = np.nan
        return angle, omega, alpha

    def _period(self, time):
        """Return (period index, share of it elapsed, whether inside a good period)."""
        time = np.atleast_1d(np.asarray(time, float))
        n = len(self.time)
        if n < 2:
            return (np.zeros(len(time), np.int64), np.zeros(len(time)),
                    np.zeros(len(time), bool))
        k = np.clip(np.searchsorted(self.time, time, side='right') - 1, 0, n - 2)
        start, end = self.time[k], self.time[k + 1]
        inside = (time >= self.time[0]) & (time <= self.time[-1]) & self.good[k]
        with np.errstate(divide='ignore', invalid='ignore'):
            share = (time - start) / (end - start)
        return k, share, inside


def slopes_at_zero(offsets, turns, valid):
    """
    Return, per row, the slope at offset 0 of the least-squares quadratic through its points.

    ``offsets`` (rows, points) s, ``turns`` (rows, points) rad, ``valid`` (rows, points)
    the points that count: two give the chord's slope, three or more the quadratic's
    (a + b x + c x^2: b, by Cramer's rule on the normal equations). NaN for a row of
    fewer than two.
    """
    offsets, turns = np.asarray(offsets, float), np.asarray(turns, float)
    weight = np.asarray(valid, bool)
    scale = np.max(np.abs(np.where(weight, offsets, 0.0)), axis=1)
    scale[~(scale > 0.0)] = 1.0
    x = np.where(weight, offsets / scale[:, None], 0.0)      # within [-1, 1]
    y = np.where(weight, turns, 0.0)
    x2 = x * x
    n, s1, s2 = weight.sum(axis=1).astype(float), x.sum(axis=1), x2.sum(axis=1)
    s3, s4 = (x2 * x).sum(axis=1), (x2 * x2).sum(axis=1)
    r0, r1, r2 = y.sum(axis=1), (y * x).sum(axis=1), (y * x2).sum(axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        # [[n s1 s2] [s1 s2 s3] [s2 s3 s4]] (a b c) = (r0 r1 r2): b by Cramer's rule.
        det = n * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s2 * s3) + s2 * (s1 * s3 - s2 * s2)
        det_b = n * (r1 * s4 - s3 * r2) - r0 * (s1 * s4 - s2 * s3) + s2 * (s1 * r2 - r1 * s2)
        slope = det_b / det
        # Two points: the line through them.
        chord = (r1 / 2.0 - s1 * r0 / 4.0) / (s2 / 2.0 - s1 * s1 / 4.0)
    slope = np.where(n == 2, chord, np.where(n >= 3, slope, np.nan))
    return slope / scale


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
