"""
The tach core (cvc_balance/physics/keyphasor.py) on small signals and mark lists worked by hand.

Each expected value is counted or computed here from the definitions in the module's
description: the two levels as medians, a crossing timed by linear interpolation, a band
that must be left on both sides, periods checked against the median of their neighbours
(the ends reflected), marks put back evenly, an extra mark dropped, the speed at a mark
the mean over the revolutions centred on it, the angle 2 pi k at mark k and linear between,
steady stretches as runs of marks whose speeds stay within the tolerance. Exact binary
fractions put values on the boundaries the module names (a tolerance of 0.25).
"""

import math

import numpy as np
import pytest

from cvc_balance.physics.keyphasor import (_longest_run, _neighbours_median, _turn_time,
                                           checked_marks, fit_at_zero, LiveMarks,
                                           LiveSignal, Marks,
                                           marks_summary, signal_levels, signal_marks,
                                           steady_stretches)

TWO_PI = 2 * math.pi


# -- the signal's levels and its crossings --------------------------------------------------

def test_the_two_levels_are_the_medians_either_side_of_the_middle():
    # Middle 2: 0, 1 and 2 are the low side (median 1), 4 the high one.
    assert signal_levels([0.0, 1.0, 2.0, 4.0]) == (1.0, 4.0)
    # Middle 15.5 (not 0.5 / 31): 10, 11 low; 20, 21 high.
    assert signal_levels([10.0, 20.0, 11.0, 21.0, math.nan]) == (10.5, 20.5)
    assert signal_levels([0.0, 1.0]) == (0.0, 1.0)                  # two samples suffice
    for values, says in (([1.0, math.nan], 'tach signal has 1 finite samples: no marks'),
                         ([], 'tach signal has 0 finite samples: no marks'),
                         ([2.0, 2.0, 2.0], 'tach signal is flat at 2: no marks')):
        with pytest.raises(ValueError) as caught:
            signal_levels(values)
        assert str(caught.value) == says


def test_crossings_by_linear_interpolation_either_edge():
    t = np.arange(9.0)
    values = np.array([0.0, 0.0, 0.25, 1.0, 1.0, 0.0, 0.0, 0.75, 1.0])
    # Threshold 0.5: rising between 0.25 (t 2) and 1 (t 3), and between 0 (t 6) and 0.75.
    assert signal_marks(t, values).tolist() == [2.0 + 1.0 / 3.0, 6.0 + 2.0 / 3.0]
    # Falling: between 1 (t 4) and 0 (t 5), halfway.
    assert signal_marks(t, values, 'falling').tolist() == [4.5]
    # A threshold given: 0.25 rising is crossed exactly at t 2 and between t 6 and 7.
    assert signal_marks(t, values, threshold=0.25).tolist() == [2.0, 6.0 + 1.0 / 3.0]
    for kwargs, says in (({'edge': 'up'}, "keyphasor edge must be rising or falling, got 'up'"),
                         ({'threshold': math.nan}, 'keyphasor threshold must be finite, got '
                          'nan')):
        with pytest.raises(ValueError) as caught:
            signal_marks(t, values, **kwargs)
        assert str(caught.value) == says


def test_a_wiggle_counts_only_beyond_the_band_on_both_sides():
    """Levels 1 and 6 (band 0.1 x 5 = 0.5 about 3.5): 4.1 and 2.9 leave it, 4.0, 3.0 do not."""
    t = np.arange(8.0)
    beyond = np.array([1.0, 1.0, 4.1, 2.9, 6.0, 6.0, 1.0, 1.0])
    marks = signal_marks(t, beyond)
    np.testing.assert_allclose(marks, [1.0 + 2.5 / 3.1, 3.0 + 0.6 / 3.1], rtol=0, atol=1e-15)
    # Exactly 0.5 off is not beyond: one edge, at 6.0, timed after the last sample below.
    on_the_band = np.array([1.0, 1.0, 4.0, 3.0, 6.0, 6.0, 1.0, 1.0])
    assert signal_marks(t, on_the_band).tolist() == [3.0 + 0.5 / 3.0]


def test_a_sample_without_a_finite_time_or_value_is_left_out():
    t = np.arange(10.0)
    values = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0])
    clean = signal_marks(t, values)
    for k in (2, 3, 7):
        t_gap, v_gap = t.copy(), values.copy()
        t_gap[k] = math.nan
        kept = np.arange(10) != k
        assert signal_marks(t_gap, values).tolist() == signal_marks(t[kept], values[kept]) \
            .tolist(), k
        v_gap[k] = math.nan
        assert signal_marks(t, v_gap).tolist() == signal_marks(t[kept], values[kept]) \
            .tolist(), k
    assert clean.tolist() == [2.5, 7.5]


# -- checking the marks ----------------------------------------------------------------------

def neighbours_median_by_hand(periods, neighbours):
    """Return the median of up to ``neighbours`` periods either side, the ends reflected."""
    n = len(periods)
    if n < 2:
        return list(periods)
    reach = min(neighbours, n - 1)

    def at(j):                            # reflect about the end elements
        return periods[-j] if j < 0 else periods[2 * (n - 1) - j] if j >= n else periods[j]
    out = []
    for i in range(n):
        around = sorted(at(j) for j in range(i - reach, i + reach + 1) if j != i)
        out.append(0.5 * (around[reach - 1] + around[reach]))
    return out


@pytest.mark.parametrize('periods', [[1.0], [1.0, 3.0], [1.0, 2.0, 7.0], [4.0, 1.0, 3.0, 2.0],
                                     [5.0, 1.0, 4.0, 2.0, 3.0, 9.0, 6.0, 8.0]])
@pytest.mark.parametrize('neighbours', [1, 2, 3])
def test_neighbours_median_by_hand(periods, neighbours):
    got = _neighbours_median(np.array(periods), neighbours)
    assert got.tolist() == neighbours_median_by_hand(periods, neighbours)


def test_few_marks_are_taken_as_they_are():
    for times in ([], [3.0], [math.nan, 2.0]):
        marks = checked_marks(times)
        assert marks.found == len([t for t in times if math.isfinite(t)])
        assert marks.good.shape == (max(marks.found - 1, 0),) and marks.good.dtype == bool
        assert marks.time.tolist() == [t for t in times if math.isfinite(t)]
    two = checked_marks([1.0, 0.0])                            # sorted
    assert two.time.tolist() == [0.0, 1.0] and two.good.tolist() == [True] and two.found == 2
    three = checked_marks([0.0, 1.0, 2.0])
    assert three.good.tolist() == [True, True] and three.revolutions == 2


def test_a_doubled_mark_is_dropped_even_in_the_first_period():
    for extra_at in (0.4, 3.4, 6.7):
        times = sorted([float(k) for k in range(8)] + [extra_at])
        marks = checked_marks(times)
        assert marks.time.tolist() == [float(k) for k in range(8)], extra_at
        assert (marks.found, marks.doubled, marks.missed, marks.irregular) == (9, 1, 0, 0)
    # Two extra marks near each other (11.76: 0.76 + 0.24; 13.56: 0.56 + 0.53 = 1.09): the
    # second is told only once the first is gone (its neighbours' median): two passes,
    # both counted; the short period 0.47 after them is left a gap.
    times = [float(k) for k in range(12)] + [11.76, 12.0, 13.0, 13.56, 14.09, 14.56, 15.56,
                                             16.56]
    marks = checked_marks(times)
    assert marks.time.tolist() == [t for t in times if t not in (11.76, 13.56)]
    assert (marks.doubled, marks.missed, marks.irregular) == (2, 0, 1)


def test_a_doubled_mark_on_a_coast_down_against_its_own_neighbours():
    """Periods growing 10 % a turn: a split period late in the run is judged on its own."""
    periods = 0.05 * 1.1 ** np.arange(16)
    times = np.concatenate([[0.0], np.cumsum(periods)])
    split = times[13] + 0.3 * periods[13]
    marks = checked_marks(np.sort(np.append(times, split)))
    assert marks.doubled == 1 and np.array_equal(marks.time, times)


def test_missed_marks_put_back_evenly_and_longer_gaps_left():
    # A period of 2 (one mark lost) and of 3 (two lost): put back at the thirds.
    times = [0.0, 1.0, 3.0, 4.0, 7.0, 8.0, 9.0]
    marks = checked_marks(times)
    np.testing.assert_allclose(marks.time, np.arange(10.0), rtol=0, atol=1e-15)
    assert (marks.missed, marks.irregular, marks.revolutions) == (3, 0, 9)
    # Four times (three lost): more than MAX_MISSED, a gap; 2.5 times: no whole number.
    for long in (4.0, 2.5):
        times = [0.0, 1.0, 2.0, 3.0, 3.0 + long, 4.0 + long, 5.0 + long, 6.0 + long]
        marks = checked_marks(times)
        assert marks.time.tolist() == times, long
        assert (marks.missed, marks.irregular) == (0, 1)
        assert marks.good.tolist() == [True, True, True, False, True, True, True]


def test_the_tolerance_is_met_exactly_at_its_bound():
    """Tolerance 0.25 (exact in binary): a period 1.25 is good, 1.3 is not; likewise 2.5/2."""
    ok = checked_marks([0.0, 1.0, 2.0, 3.25, 4.25, 5.25], tolerance=0.25)
    assert ok.good.all() and ok.irregular == 0
    off = checked_marks([0.0, 1.0, 2.0, 3.3, 4.3, 5.3], tolerance=0.25)
    assert off.good.tolist() == [True, True, False, True, True]
    # A lost mark in a period of 2.5 = 2 x 1.25: put back; a doubled pair adding to 1.25.
    lost = checked_marks([0.0, 1.0, 2.0, 4.5, 5.5, 6.5], tolerance=0.25)
    assert lost.missed == 1 and lost.time.tolist() == [0.0, 1.0, 2.0, 3.25, 4.5, 5.5, 6.5]
    double = checked_marks([0.0, 1.0, 2.0, 2.5, 3.25, 4.25, 5.25, 6.25], tolerance=0.25)
    assert double.doubled == 1 and double.time.tolist() == [0.0, 1.0, 2.0, 3.25, 4.25,
                                                            5.25, 6.25]


# -- angle, speed and acceleration from the marks ----------------------------------------------

def ramp_marks(count, speed=10.0, alpha=4.0):
    """Mark times of theta = speed t + alpha t^2 / 2 = 2 pi k, solved by hand."""
    k = np.arange(count)
    return (-speed + np.sqrt(speed * speed + 2 * alpha * TWO_PI * k)) / alpha


def test_the_speed_at_each_mark_by_hand_on_a_ramp():
    t = ramp_marks(12)
    marks = Marks(t, np.ones(11, bool), 12)
    for span in (8, 2, 3):
        speed = marks.mark_speed(span)
        half = max(span // 2, 1)
        for k in range(1, 11):
            h = min(k, 11 - k, half)
            assert speed[k] == pytest.approx(TWO_PI * 2 * h / (t[k + h] - t[k - h]), rel=1e-13)
        # The end marks: the one period's speed carried on along the slope to the next.
        first = TWO_PI / (t[1] - t[0])
        last = TWO_PI / (t[11] - t[10])
        assert speed[0] == pytest.approx(2 * first - speed[1], rel=1e-13)
        assert speed[11] == pytest.approx(2 * last - speed[10], rel=1e-13)


def test_runs_of_one_and_two_periods_and_a_lone_mark():
    t = ramp_marks(9)
    # Runs: marks 0-1 (one period), gap, 2-4 (two periods), gap, 5 alone, gap, 6-8.
    good = np.array([True, False, True, True, False, False, True, True])
    speed = Marks(t, good, 9).mark_speed()
    one = TWO_PI / (t[1] - t[0])
    assert speed[0] == speed[1] == pytest.approx(one, rel=1e-15)
    middle = TWO_PI * 2 / (t[4] - t[2])
    assert speed[3] == pytest.approx(middle, rel=1e-13)
    assert speed[2] == pytest.approx(2 * TWO_PI / (t[3] - t[2]) - middle, rel=1e-13)
    assert speed[4] == pytest.approx(2 * TWO_PI / (t[4] - t[3]) - middle, rel=1e-13)
    assert math.isnan(speed[5])
    assert np.isfinite(speed[[6, 7, 8]]).all()
    assert np.isnan(Marks(np.array([1.0]), np.zeros(0, bool), 1).mark_speed()).tolist() == \
        [True]
    assert Marks(np.zeros(0), np.zeros(0, bool), 0).mark_speed().shape == (0,)
    two = Marks(np.array([0.0, 0.5]), np.array([True]), 2)
    assert two.mark_speed().tolist() == [TWO_PI / 0.5] * 2


def hermite_by_hand(t, speed, k, share):
    """
    Angle, speed and acceleration a share (0..1) into period k, by the motion's definition.

    The cubic from 2 pi k to 2 pi (k + 1) whose slopes at the marks are their fitted speeds:
    Hermite's basis written out here, its derivatives by hand.
    """
    h = t[k + 1] - t[k]
    m0, m1, s = speed[k] * h, speed[k + 1] * h, share
    angle = TWO_PI * k + (s**3 - 2 * s**2 + s) * m0 + (-2 * s**3 + 3 * s**2) * TWO_PI \
        + (s**3 - s**2) * m1
    omega = ((3 * s**2 - 4 * s + 1) * m0 + (6 * s - 6 * s**2) * TWO_PI
             + (3 * s**2 - 2 * s) * m1) / h
    alpha = ((6 * s - 4) * m0 + (6 - 12 * s) * TWO_PI + (6 * s - 2) * m1) / h**2
    return angle, omega, alpha


def test_angle_speed_and_acceleration_between_marks_by_hand():
    t = ramp_marks(10)
    marks = Marks(t, np.array([True] * 4 + [False] + [True] * 4), 10)
    speed = marks.fitted_speed()
    # A third of the way through period 2; at the marks themselves (a mark starts its
    # period; the last mark ends the last one); half way through the last period.
    at = np.array([t[2] + (t[3] - t[2]) / 3, t[0], t[3], t[9], t[8] + 0.5 * (t[9] - t[8])])
    where = [(2, 1 / 3), (0, 0.0), (3, 0.0), (8, 1.0), (8, 0.5)]
    angle, omega, alpha = marks.motion(at)
    for n, (k, share) in enumerate(where):
        expected = hermite_by_hand(t, speed, k, share)
        assert (angle[n], omega[n], alpha[n]) == pytest.approx(expected, rel=1e-12, abs=1e-9)
    # The cubic passes through the marks' turns and takes their fitted speeds there.
    assert angle[1:4].tolist() == pytest.approx([0.0, TWO_PI * 3, TWO_PI * 9], abs=1e-12)
    assert omega[1:4].tolist() == pytest.approx(speed[[0, 3, 9]].tolist(), rel=1e-12)
    assert marks.angle(at).tolist() == angle.tolist()
    # NaN before, after, and in the irregular period 4.
    outside = np.array([t[0] - 1e-9, t[9] + 1e-9, 0.5 * (t[4] + t[5])])
    for values in (*marks.motion(outside), marks.angle(outside)):
        assert np.isnan(values).all()
    # No period at all: NaN of the times' length.
    lone = Marks(np.array([1.0]), np.zeros(0, bool), 1)
    for values in (*lone.motion([0.5, 1.0, 2.0]), lone.angle([0.5, 1.0, 2.0])):
        assert values.shape == (3,) and np.isnan(values).all()
    two = Marks(np.array([0.0, 0.5]), np.array([True]), 2)
    angle, omega, alpha = two.motion([0.25])
    assert (angle[0], omega[0], alpha[0]) == (math.pi, TWO_PI / 0.5, 0.0)


# -- steady stretches ---------------------------------------------------------------------------

def stepped_marks(steps):
    """Return the marks of constant speeds: [(revolutions, period s)] one after the other."""
    periods = np.concatenate([np.full(n, period) for n, period in steps])
    return Marks(np.concatenate([[0.0], np.cumsum(periods)]), np.ones(len(periods), bool),
                 len(periods) + 1)


def test_steady_stretches_of_a_speed_step_by_hand():
    """
    Split a speed step: 15 revolutions at 0.1 s, then 14 at 0.1 / 1.5 s.

    Each mark's speed is averaged over 8 revolutions centred on it, so the marks within 4
    of the step blend (3 % off and more): the first stretch is marks 0-11, the second
    19-29, each at its exact speed.
    """
    marks = stepped_marks([(15, 0.1), (14, 0.1 / 1.5)])
    slow, fast = steady_stretches(marks)
    assert (slow.first, slow.last, slow.revolutions) == (0, 11, 11)
    assert (fast.first, fast.last, fast.revolutions) == (19, 29, 10)
    assert slow.speed == pytest.approx(TWO_PI / 0.1, rel=1e-13)
    assert fast.speed == pytest.approx(TWO_PI * 1.5 / 0.1, rel=1e-13)
    assert (slow.start, slow.end) == (marks.time[0], marks.time[11])
    assert slow.spread < 1e-13 and fast.spread < 1e-13
    # A wide tolerance (10 %: the whole run is one stretch? no: a 50 % step) still splits.
    assert len(steady_stretches(marks, tolerance=0.1)) == 2
    # Not a stretch when it is one revolution short.
    assert steady_stretches(stepped_marks([(7, 0.1)])) == []
    (exactly,) = steady_stretches(stepped_marks([(8, 0.1)]))
    assert (exactly.first, exactly.last, exactly.revolutions) == (0, 8, 8)
    assert steady_stretches(stepped_marks([(12, 0.1)]), min_revolutions=12)[0].last == 12
    with pytest.raises(ValueError) as caught:
        steady_stretches(marks, tolerance=0.0)
    assert str(caught.value) == 'speed tolerance must be > 0, got 0.0'


def test_a_stretch_stops_at_a_gap_and_its_spread_is_its_worst_mark():
    marks = stepped_marks([(10, 0.1), (1, 0.37), (12, 0.1)])
    checked = checked_marks(marks.time)
    assert checked.good.tolist() == [True] * 10 + [False] + [True] * 12
    first, second = steady_stretches(checked)
    assert (first.first, first.last, second.first, second.last) == (0, 10, 11, 23)
    # A 0.5 % slower period in the middle: the spread is the worst mark's speed off the mean.
    jittered = stepped_marks([(6, 0.1), (1, 0.1005), (6, 0.1)])
    (stretch,) = steady_stretches(jittered)
    speed = jittered.mark_speed()
    mean = TWO_PI * 13 / jittered.time[-1]
    assert stretch.speed == pytest.approx(mean, rel=1e-14)
    assert stretch.spread == pytest.approx(np.max(np.abs(speed - mean)) / mean, rel=1e-12)
    assert stretch.spread > 1e-4


def test_the_longest_run():
    for mask, want in (([1, 1, 0, 1, 1, 1, 0], (3, 6)), ([0, 1, 0, 0, 1, 1], (4, 6)),
                       ([1, 1, 1], (0, 3)), ([0, 1], (1, 2)),
                       ([1, 1, 1, 0, 1], (0, 3)), ([1, 0, 1, 1, 0, 1, 1], (2, 4))):
        assert _longest_run(np.array(mask, bool)) == want


def test_a_run_of_one_period_between_gaps_has_its_periods_speed_at_both_marks():
    t = ramp_marks(7)
    # Runs: marks 0-1, 2-3 (one period, not the first run), 4-6.
    speed = Marks(t, np.array([True, False, True, False, True, True]), 7).mark_speed()
    for k in (0, 2):
        assert speed[k] == speed[k + 1] == pytest.approx(TWO_PI / (t[k + 1] - t[k]), rel=1e-15)


# -- steady stretches of given mark speeds ------------------------------------------------

class GivenSpeeds:
    """Marks whose speeds at the marks are given (all that steady_stretches reads of them)."""

    def __init__(self, speed, good, time):
        self.speed, self.good, self.time = np.array(speed, float), np.array(good, bool), time

    def mark_speed(self, span):
        """Return the given speeds, whatever the span."""
        return self.speed.copy()


def stretches_by_hand(speed, good, time, tolerance, least):
    """
    Steady stretches as the description defines them, one start at a time, in plain Python.

    From each start (a finite speed, its period good), the marks while the periods stay
    good, the speeds finite and max - min <= tolerance (max + min); kept when that is at
    least ``least`` revolutions, then cut to its first longest run within tolerance x its
    median of that median, kept again if still ``least``; the next start is the kept
    stretch's last mark (or the next mark).
    """
    found, i, n = [], 0, len(speed)
    while i < n - 1:
        j = i
        while j + 1 < n and good[j] and math.isfinite(speed[j + 1]):
            part = speed[i:j + 2]
            if max(part) - min(part) > tolerance * (max(part) + min(part)):
                break
            j += 1
        if not (math.isfinite(speed[i]) and good[i]) or j - i < least:
            i += 1
            continue
        part = list(speed[i:j + 1])
        middle = sorted(part)[len(part) // 2] if len(part) % 2 else \
            0.5 * (sorted(part)[len(part) // 2 - 1] + sorted(part)[len(part) // 2])
        best, start = (0, 0), None
        for k, value in enumerate(part + [math.inf]):
            if abs(value - middle) <= tolerance * middle:
                start = k if start is None else start
            elif start is not None:
                best = max(best, (k - start, -start))
                start = None
        first, last = i - best[1], i - best[1] + best[0] - 1
        if last - first >= least:
            mean = TWO_PI * (last - first) / (time[last] - time[first])
            found.append((first, last, mean, max(abs(s - mean) for s in speed[first:last + 1])
                          / mean))
        i = max(last, i + 1)
    return found


def test_stretches_on_the_bounds_by_hand():
    """Tolerance 1/4, speeds of a few binary fractions: both bounds met exactly."""
    time = np.arange(9.0) * math.pi      # 2 pi 8 / 8 pi: a mean speed of 2
    # 1.5 and 2.5: the range 1 is 1/4 of 1.5 + 2.5 exactly; the median 2 and 2.5 - 2 = 2 / 4.
    (stretch,) = steady_stretches(GivenSpeeds([2.0] * 7 + [1.5, 2.5], [True] * 8, time),
                                  tolerance=0.25)
    assert (stretch.first, stretch.last, stretch.revolutions) == (0, 8, 8)
    assert stretch.speed == pytest.approx(2.0, rel=1e-15)
    assert stretch.spread == pytest.approx(0.25, rel=1e-15)      # 1.5 and 2.5 are 1/2 off
    # A stretch of one revolution at the very end; after a short one, the next start.
    ends = GivenSpeeds([1.0, 1.0, 9.0, 9.0], [True] * 3, np.arange(4.0))
    assert [(s.first, s.last) for s in steady_stretches(ends, 0.25, 1)] == [(0, 1), (2, 3)]
    late = GivenSpeeds([1.0, 9.0, 9.0, 9.0], [True] * 3, np.arange(4.0))
    assert [(s.first, s.last) for s in steady_stretches(late, 0.25, 2)] == [(1, 3)]


def test_stretches_of_random_speeds_as_defined():
    """Speeds drawn from a few binary fractions (ties on both bounds), gaps, lone marks."""
    rng = np.random.default_rng(29)
    levels = np.array([3.0, 3.5, 4.0, 4.5, 5.0, 6.0])
    checked = 0
    for case in range(120):
        n = int(rng.integers(2, 40))
        good = rng.random(n - 1) < 0.9
        # A speed drifts from level to level, or steps; NaN where a mark has no good period.
        speed = levels[np.clip(np.cumsum(rng.integers(-1, 2, n)) + 2, 0, 5)]
        lone = ~np.concatenate([[False], good]) & ~np.concatenate([good, [False]])
        speed[lone] = np.nan
        time = np.cumsum(rng.uniform(0.5, 1.5, n))
        tolerance, least = [0.25, 0.125, 0.0625][case % 3], int(rng.integers(1, 6))
        got = steady_stretches(GivenSpeeds(speed, good, time), tolerance, least)
        want = stretches_by_hand(speed.tolist(), good.tolist(), time, tolerance, least)
        assert [(s.first, s.last) for s in got] == [w[:2] for w in want], case
        for s, (first, last, mean, spread) in zip(got, want):
            assert (s.start, s.end, s.revolutions) == (time[first], time[last], last - first)
            assert s.speed == pytest.approx(mean, rel=1e-15)
            assert s.spread == pytest.approx(spread, rel=1e-12, abs=1e-15)
        checked += len(want)
    assert checked > 100


def test_the_marks_summary_in_words():
    assert marks_summary('/tach', 10, 1, 2, 3, 9) == (
        'keyphasor /tach: 10 marks, 1 missed (put back), 2 doubled (dropped), 3 irregular '
        'periods (no angle there), 9 revolutions')


# -- the marks, live: the fit, and when it forgets ------------------------------------------

def live_speeds(times, resolution=None, **options):
    """Feed mark times to LiveMarks; return it and the speed it gives at each good mark."""
    marks, speeds = LiveMarks(**options), {}
    for time in times:
        given = marks.mark(time) if resolution is None else marks.mark(time, resolution)
        for _, end, _, speed in given or []:
            speeds[end] = speed
    return marks, speeds


def least_squares_speed(times, first, k):
    """Slope at mark k of numpy's least-squares quadratic (a line for two), marks first..k."""
    x = np.asarray(times[first:k + 1]) - times[k]
    return np.polyfit(x, TWO_PI * np.arange(first - k, 1), 2 if k - first >= 2 else 1)[-2]


def stepped_times(period, step, at, count=30, jitter=0.0):
    """
    Return mark times ``period`` s apart, each odd one ``jitter`` periods late.

    From mark ``at`` on the periods are ``step`` shorter (relative).
    """
    times, time = [], 0.0
    for k in range(count):
        times.append(time + (jitter * period if k % 2 else 0.0))
        time += period * (1.0 - step if k + 1 >= at else 1.0)
    return times


def test_a_change_of_speed_restarts_the_live_fit_from_the_two_marks_before_it():
    """
    Steady at 0.1 s a turn, then 5 % faster from mark 12 on (exact mark times).

    Each speed is the least-squares slope over the run's last nine marks (SPAN_REVS), until
    a mark leads the fit's prediction by more than 1 % of a turn (CHANGE: the marks' own
    scatter here is nil) once three leads were seen: mark 12 leads by 5 %, so the fit
    keeps only the two marks before it; once the kept marks are all on the new speed (mark
    15), the speed is exact again.
    """
    times = stepped_times(0.1, 0.05, 12)
    marks, speed = live_speeds(times)
    assert (marks.found, marks.revolutions, marks.irregular) == (30, 29, 0)
    for k in range(1, 12):
        assert speed[times[k]] == pytest.approx(TWO_PI / 0.1, rel=1e-12), k
    for k in (12, 13):
        assert speed[times[k]] == pytest.approx(least_squares_speed(times, 10, k), rel=1e-9)
    for k in range(15, 30):
        assert speed[times[k]] == pytest.approx(TWO_PI / 0.095, rel=1e-12), k
    # Without the restart mark 14 would still see marks 10 and 11 of the old speed.
    assert speed[times[14]] != pytest.approx(least_squares_speed(times, 6, 14), rel=1e-3)
    # A sampled tach's resolution widens the limit to 2 x resolution / period: 6 % keeps
    # every mark in the fit, 4 % does not; a 0.5 % step is below CHANGE.
    _, wide = live_speeds(times, resolution=0.003)
    _, narrow = live_speeds(times, resolution=0.002)
    _, small = live_speeds(stepped_times(0.1, 0.005, 12))
    small_times = stepped_times(0.1, 0.005, 12)
    for k in range(12, 20):
        assert wide[times[k]] == pytest.approx(least_squares_speed(times, k - 8, k), rel=1e-9)
        assert small[small_times[k]] == pytest.approx(
            least_squares_speed(small_times, k - 8, k), rel=1e-9)
    assert narrow[times[12]] == pytest.approx(least_squares_speed(times, 10, 12), rel=1e-9)
    # The same with a doubled mark in the period before the step: dropped, and the mark
    # that ends the period still judged with the tach's resolution.
    doubled = sorted(times + [0.5 * (times[11] + times[12])])
    marks, wide = live_speeds(doubled, resolution=0.003)
    assert marks.doubled == 1
    assert wide[times[12]] == pytest.approx(least_squares_speed(times, 4, 12), rel=1e-9)


def test_the_first_three_leads_only_learn_the_marks_scatter():
    """Marks 0-3 are learnt; marks 4, 5, 6 give the first three leads; mark 7 the first check."""
    early = stepped_times(0.1, 0.05, 6)
    _, speed = live_speeds(early)
    for k in (6, 7):
        assert speed[early[k]] == pytest.approx(least_squares_speed(early, 0, k), rel=1e-9)
    late = stepped_times(0.1, 0.05, 7)
    _, speed = live_speeds(late)
    assert speed[late[7]] == pytest.approx(least_squares_speed(late, 5, 7), rel=1e-9)


def test_the_limit_is_four_times_the_marks_mean_scatter():
    """
    Odd marks 0.3 % of a turn late: leads of +-0.36 %, a mean |lead| of 0.37 % at mark 19.

    The limit is then 4 x 0.37 % = 1.46 % (measured 0.0146): a lead of 1.66 % at mark 20
    (the jitter's -0.36 % and a step of -1.3 %) restarts the fit, one of 1.26 % (a step of
    -0.9 %) does not, though it is more than CHANGE.
    """
    restarts = stepped_times(0.1, 0.013, 20, jitter=0.003)
    _, speed = live_speeds(restarts)
    assert speed[restarts[20]] == pytest.approx(least_squares_speed(restarts, 18, 20),
                                                rel=1e-9)
    kept = stepped_times(0.1, 0.009, 20, jitter=0.003)
    _, speed = live_speeds(kept)
    for k in (19, 20, 21):
        assert speed[kept[k]] == pytest.approx(least_squares_speed(kept, k - 8, k), rel=1e-9)


def test_a_fast_ramp_is_followed_with_a_tight_tolerance():
    """Spin-up 2 % a turn (omega 100 rad/s, alpha 32 rad/s^2): each period against its own."""
    omega, alpha = 100.0, 32.0
    times = (-omega + np.sqrt(omega ** 2 + 2 * alpha * TWO_PI * np.arange(40))) / alpha
    marks, speed = live_speeds(times, tolerance=0.05)
    assert (marks.missed, marks.doubled, marks.irregular, marks.revolutions) == (0, 0, 0, 39)
    # Each period's speed at its start is the one given at the end of the period before.
    periods = [p for t in times for p in marks.mark(t) or []]
    assert periods == [] and marks.found == 40          # repeated marks: left out
    again = LiveMarks(tolerance=0.05)
    periods = [p for t in times for p in again.mark(t) or []]
    assert [p[2] for p in periods[1:]] == [p[3] for p in periods[:-1]]
    for k in range(2, 40):
        assert speed[times[k]] == pytest.approx(omega + alpha * times[k], rel=1e-9), k


# -- the marks, live: which marks are taken ----------------------------------------------------

def test_a_mark_not_after_the_newest_is_left_out_in_every_state():
    marks = LiveMarks()
    assert marks.mark(0.0) == [] and marks.mark(0.0) is None and marks.mark(-1.0) is None
    assert marks.found == 1                                          # learning
    for time in (0.1, 0.2, 0.3):
        marks.mark(time)
    assert marks.ready and marks.found == 4
    assert marks.mark(0.3) is None and marks.found == 4             # the newest good mark
    assert marks.mark(0.34) == [] and marks.found == 5              # short: held
    assert marks.mark(0.34) is None and marks.mark(0.32) is None    # not after the held one
    assert marks.found == 5
    (period,) = marks.mark(0.4)
    assert period[:2] == (0.3, 0.4) and (marks.found, marks.doubled) == (6, 1)


def test_a_short_period_not_followed_by_one_revolution_starts_again_from_its_mark():
    marks = LiveMarks()
    for time in (0.0, 0.1, 0.2, 0.3):
        marks.mark(time)
    assert marks.mark(0.45) == [] and marks.irregular == 1          # 1.5 turns: irregular
    for time in (0.55, 0.65, 0.75):
        marks.mark(time)
    assert marks.ready
    assert marks.mark(0.79) == []                                   # short: held
    assert marks.mark(0.9) == [] and marks.irregular == 2           # 1.5 turns from 0.75
    assert not marks.ready
    assert marks.motion_at(0.95) == 'keyphasor: learning the period (2 marks of 4)'
    assert marks.mark(1.01) == []
    periods = marks.mark(1.12)
    assert [p[:2] for p in periods] == [(0.79, 0.9), (0.9, 1.01), (1.01, 1.12)]
    assert marks.mark(1.28) == [] and marks.irregular == 3          # 1.45 turns


def test_learning_takes_three_periods_each_within_the_tolerance_of_the_one_before():
    # 1, 1.3, 1.1: the second is 30 % longer than the first.
    marks = LiveMarks()
    for time in (0.0, 1.0, 2.3, 3.4):
        marks.mark(time)
    assert not marks.ready and marks.irregular == 1
    # 1, 1.1, 1.3: each within 20 % of the one before (1.3 / 1.1 = 1.18).
    marks = LiveMarks()
    for time in (0.0, 1.0, 2.1, 3.4):
        marks.mark(time)
    assert marks.ready and marks.irregular == 0 and marks.revolutions == 3
    # Tolerance 1/4: 1.25 after 1 is within it, exactly.
    marks = LiveMarks(tolerance=0.25)
    for time in (0.0, 1.0, 2.25, 3.5625):
        marks.mark(time)
    assert marks.ready and marks.irregular == 0


def test_the_angle_is_given_until_three_periods_and_the_tolerance_without_a_mark():
    marks = LiveMarks()
    for time in (0.0, 0.1, 0.2, 0.3):
        marks.mark(time)
    for periods in (1.5, 3.0):
        angle, omega = marks.motion_at(0.3 + 0.1 * periods)
        assert angle == pytest.approx(TWO_PI * periods, rel=1e-12)
        assert omega == pytest.approx(TWO_PI / 0.1, rel=1e-12)
    assert marks.motion_at(0.3 + 0.1 * 3.25) == 'keyphasor: no mark for 0.325 s (the rotor ' \
        'stopped?)'


def test_four_turns_without_a_mark_are_a_gap_and_a_coast_down_keeps_its_last_period():
    marks = LiveMarks()
    for time in (0.0, 0.1, 0.2, 0.3, 0.7):          # 4 turns: more than MAX_MISSED lost
        marks.mark(time)
    assert (marks.missed, marks.irregular, marks.ready) == (0, 1, False)
    # Coasting to a stop 10.5 turns on: after the last mark the fit has the rotor stop
    # within half a turn; the period it expects is then the last one's.
    omega, alpha = 20.0, -400.0 / (2.0 * TWO_PI * 10.5)
    times = (-omega + np.sqrt(omega ** 2 + 2.0 * alpha * TWO_PI * np.arange(11))) / alpha
    marks, speed = live_speeds(times)
    assert marks.ready and marks.revolutions == 10
    assert marks.period == pytest.approx(times[10] - times[9], rel=1e-12)
    assert speed[times[10]] == pytest.approx(omega + alpha * times[10], rel=1e-9)


def test_marks_missed_at_a_speed_step_are_judged_with_the_tachs_resolution_at_the_last():
    """
    Steady at 0.1 s a turn, 2 % faster from mark 12 on; marks 12 and 13 missed.

    Mark 14 ends about three periods: 12 and 13 are put back evenly (at their true times:
    the speed is constant after the step). Put back, mark 12 leads the fit by -2 % of a
    turn (beyond CHANGE; the scatter is nil): the fit keeps the two marks before it. Mark 13
    joins a run of three (no lead judged). Mark 14 leads the quadratic through marks 10-13
    by 1.4 % (numpy's, below): beyond CHANGE and 4 x the scatter, within 2 x the tach's
    resolution / period (10 %) with a resolution of 5 ms, so the fit keeps marks 10-14;
    without a resolution it restarts from marks 12 and 13.
    """
    times = stepped_times(0.1, 0.02, 12, count=20)
    seen = times[:12] + times[14:]
    marks, speed = live_speeds(seen, resolution=0.005)
    assert (marks.found, marks.missed, marks.irregular, marks.revolutions) == (18, 2, 0, 19)
    for k in (12, 13, 14):
        assert speed[times[k]] == pytest.approx(least_squares_speed(times, 10, k), rel=1e-9), k
    # The lead of mark 14 on numpy's quadratic through marks 10-13: the time its speed and
    # acceleration at mark 13 take to turn 2 pi more.
    a, b, _ = np.polyfit(np.asarray(times[10:14]) - times[13], TWO_PI * np.arange(-3, 1), 2)
    predicted = min(r.real for r in np.roots([a, b, -TWO_PI]) if r.real > 0.0)
    lead = (times[14] - times[13]) / predicted - 1.0
    assert 0.01 < lead < 2.0 * 0.005 / predicted and lead == pytest.approx(0.014, abs=5e-4)
    _, exact = live_speeds(seen)
    assert exact[times[14]] == pytest.approx(TWO_PI / 0.098, rel=1e-12)
    assert exact[times[14]] == pytest.approx(least_squares_speed(times, 12, 14), rel=1e-12)


def test_a_coast_down_whose_fit_stops_the_rotor_expects_n_last_periods_for_n_turns():
    """
    Coasting to a stop 10.5 turns on, then driven again: a turn each last period P.

    After mark 10 the fit has the rotor stop within half a turn, so n turns are expected
    to take n P: a mark P, 2 P or 3 P after mark 10 ends 1, 2 or 3 revolutions (0, 1, 2
    marks missed, put back evenly).
    """
    omega, alpha = 20.0, -400.0 / (2.0 * TWO_PI * 10.5)
    times = list((-omega + np.sqrt(omega ** 2 + 2.0 * alpha * TWO_PI * np.arange(11))) / alpha)
    last = times[10] - times[9]
    for turns in (1, 2, 3):
        marks = LiveMarks()
        periods = [p for t in times + [times[10] + turns * last] for p in marks.mark(t) or []]
        assert (marks.missed, marks.irregular, marks.revolutions) == (turns - 1, 0, 10 + turns)
        ends = [times[10] + k * last for k in range(turns + 1)]
        assert [p[:2] for p in periods[-turns:]] == [
            (pytest.approx(start, rel=1e-12), pytest.approx(end, rel=1e-12))
            for start, end in zip(ends, ends[1:])]


def test_a_period_exactly_on_the_tolerance_of_a_stopping_fits_last_period_is_a_turn():
    """
    Periods 1, 1.25, 1.5625 (each 1.25 x the one before: learnt at a tolerance of 1/4).

    numpy's quadratic through the four marks stops before a turn (its discriminant for
    2 pi is negative), so the next turn is expected to take the last period, 1.5625 s: a
    period of 1.25 x or 0.75 x it (exact in binary) is within the tolerance, one turn.
    """
    learnt = [0.0, 1.0, 2.25, 3.8125]
    a, b, _ = np.polyfit(np.asarray(learnt) - learnt[-1], TWO_PI * np.arange(-3, 1), 2)
    assert b * b + 4.0 * a * TWO_PI < 0.0
    for share in (1.25, 0.75):
        marks = LiveMarks(tolerance=0.25)
        for time in learnt:
            marks.mark(time)
        (period,) = marks.mark(learnt[-1] + share * 1.5625)
        assert period[:2] == (3.8125, 3.8125 + share * 1.5625)
        assert (marks.irregular, marks.revolutions) == (0, 4)


def test_the_silence_limit_of_a_stopping_fit_is_met_exactly():
    """The same four marks: (3 + 1/4) x 1.5625 s without a mark still gives an angle."""
    marks = LiveMarks(tolerance=0.25)
    for time in (0.0, 1.0, 2.25, 3.8125):
        marks.mark(time)
    assert isinstance(marks.motion_at(3.8125 + 3.25 * 1.5625), tuple)
    assert marks.ready and marks.irregular == 0
    assert marks.motion_at(3.8125 + 3.25 * 1.5625 + 2.0 ** -10) == \
        'keyphasor: no mark for 5.08 s (the rotor stopped?)'
    assert not marks.ready and marks.irregular == 1


def test_a_coast_down_stops_where_it_stops_and_does_not_turn_back():
    """
    Coasting to a stop 10.5 turns on: after mark 10 the rotor turns half a turn and stays.

    The motion by hand: theta(t) = omega t + alpha t^2 / 2 from mark 0 until the stop at
    -omega / alpha, then theta = 10.5 turns, omega 0 (a tach cannot see it turn back),
    until the silence limit (3.2 x the last period after mark 10; 3.1 here).
    """
    omega, alpha = 20.0, -400.0 / (2.0 * TWO_PI * 10.5)
    times = (-omega + np.sqrt(omega ** 2 + 2.0 * alpha * TWO_PI * np.arange(11))) / alpha
    marks, _ = live_speeds(times)
    stop, silent = -omega / alpha, times[10] + 3.1 * (times[10] - times[9])
    for time in np.linspace(times[10], stop, 5).tolist() + [stop + 0.1, stop + 1.0, silent]:
        angle, speed = marks.motion_at(time)
        moved = min(time, stop)
        assert angle == pytest.approx(omega * moved + 0.5 * alpha * moved ** 2 - 10 * TWO_PI,
                                      abs=1e-9), time
        assert speed == pytest.approx(omega + alpha * moved, abs=1e-9), time


def test_a_slow_spin_up_is_extrapolated_along_its_fit_after_the_last_mark():
    """Spin-up at 0.5 rad/s^2 from 10 rad/s: theta and omega by hand up to 3 periods on."""
    omega, alpha = 10.0, 0.5
    times = (-omega + np.sqrt(omega ** 2 + 2.0 * alpha * TWO_PI * np.arange(12))) / alpha
    marks, _ = live_speeds(times)
    for time in times[11] + np.array([0.0, 0.3, 1.0, 3.0]) * (times[11] - times[10]):
        angle, speed = marks.motion_at(time)
        assert angle == pytest.approx(omega * time + 0.5 * alpha * time ** 2 - 11 * TWO_PI,
                                      abs=1e-9), time
        assert speed == pytest.approx(omega + alpha * time, rel=1e-12), time


def test_the_time_of_some_turns_from_a_mark_by_hand():
    # 2 pi t + 2 t^2 / 2 = 2 pi: t = (-2 pi + sqrt(4 pi^2 + 8 pi)) / 2.
    assert _turn_time(TWO_PI, 2.0, 1, None) == pytest.approx(
        (-TWO_PI + math.sqrt(TWO_PI ** 2 + 8 * math.pi)) / 2.0, rel=1e-15)
    assert _turn_time(TWO_PI, 0.0, 3, None) == pytest.approx(3.0, rel=1e-15)
    assert _turn_time(0.5, 0.0, 1, None) == pytest.approx(4.0 * math.pi, rel=1e-15)
    # Stopping exactly at the turn (4 pi^2 - 2 pi 2 pi = 0): it never passes it.
    assert _turn_time(TWO_PI, -math.pi, 1, 'x') == 'x'
    # Stopping first (4 pi^2 - 2 x 4 x 4 pi < 0), or not turning forward: the value given.
    assert _turn_time(TWO_PI, -4.0, 2, 'x') == 'x'
    assert _turn_time(0.0, 1.0, 1, 'x') == 'x' and _turn_time(-1.0, 5.0, 1, 'x') == 'x'


# -- a sampled tach, live ------------------------------------------------------------------

def warmed_up(signal, levels=(0.0, 8.0)):
    """Feed the 256 samples the levels are first judged over (half low, half high); t < 0."""
    for k in range(256):
        signal.sample(-1.0 + k / 1024.0, levels[k % 2])
    return signal


def test_live_crossings_by_hand():
    """Levels 0 and 8, threshold 4, band 1/8 x 8 = 1 (every figure exact in binary)."""
    tach = warmed_up(LiveSignal(hysteresis=0.125))
    assert (tach.levels, tach.threshold, tach.band) == ((0.0, 8.0), 4.0, 1.0)
    # Below the band, then up through the threshold (3 -> 6 between t 1 and 2: at 1 1/3);
    # the mark is said by the first sample beyond the band.
    said = [tach.sample(t, v) for t, v in ((0.0, 2.0), (1.0, 3.0), (2.0, 4.5), (3.0, 6.0))]
    assert said == [None, None, None, 1.0 + 1.0 / 1.5] and tach.spacing == 1.0
    # Exactly on the band's edge (5) is not beyond it; a sample exactly on the threshold is
    # where the crossing is.
    said = [tach.sample(t, v) for t, v in ((4.0, 2.0), (5.0, 4.0), (6.0, 5.0), (7.0, 5.5))]
    assert said == [None, None, None, 5.0]
    # Timed between the last sample below and the next, whatever follows inside the band.
    said = [tach.sample(t, v) for t, v in ((8.0, 2.0), (9.0, 4.5), (10.0, 4.0), (11.0, 6.0),
                                           (11.5, 6.0))]
    assert said == [None, None, None, 8.0 + 2.0 / 2.5, None] and tach.spacing == 0.5
    # Falling: the same levels, the crossing from above; 3.25 is inside the band.
    falling = warmed_up(LiveSignal('falling', hysteresis=0.125))
    said = [falling.sample(t, v) for t, v in ((0.0, 6.0), (1.0, 4.5), (2.0, 3.25),
                                              (3.0, 2.5))]
    assert said == [None, None, None, 1.4]
    # After a mark: down to exactly -band (3) and a wiggle inside the band are not below it.
    said = [tach.sample(t, v) for t, v in ((12.0, 3.0), (13.0, 6.0), (14.0, 3.5), (15.0, 6.0))]
    assert said == [None, None, None, None]
    # Levels 2 and 10: the band is 1/8 of their difference (1), about 6.
    offset = warmed_up(LiveSignal(hysteresis=0.125), levels=(2.0, 10.0))
    said = [offset.sample(t, v) for t, v in ((0.0, 4.0), (1.0, 7.25))]
    assert (offset.threshold, offset.band, said) == (6.0, 1.0, [None, 2.0 / 3.25])
    given = warmed_up(LiveSignal(threshold=2.0, hysteresis=0.125))
    said = [given.sample(t, v) for t, v in ((0.0, 0.5), (1.0, 2.5), (2.0, 3.5))]
    assert given.threshold == 2.0 and said == [None, None, 0.75]


def test_live_levels_are_judged_at_256_512_1024_samples_then_over_the_latest_4096():
    tach = LiveSignal()
    assert tach.levels is None
    for k in range(255):
        tach.sample(k, math.nan)                # not counted
        tach.sample(k + 0.5, 1.0 if k % 2 else 0.0)
    assert tach.levels is None and tach.threshold is None
    tach.sample(300.0, 1.0)
    assert tach.levels == (0.0, 1.0)            # the 256th sample
    for k in range(255):
        tach.sample(301.0 + k, 3.0 if k % 2 else 0.0)
    assert tach.levels == (0.0, 1.0)
    tach.sample(556.0, 3.0)                     # the 512th: 0 below 1.5; 128 3's above
    assert tach.levels == (0.0, 3.0)
    highs = iter([1.0, 1.5] * 4096)
    values = [next(highs) if k % 2 else 0.0 for k in range(8192 - 512)]
    for k, value in enumerate(values[:-1]):
        tach.sample(557.0 + k, value)
    # Judged last at the 4096th sample, over all: 3 is the top, 1.5 the middle.
    assert tach.levels == (0.0, 3.0)
    tach.sample(10000.0, values[-1])
    # The 8192nd: over the latest 4096 only (1's and 1.5's: the 3's are gone).
    assert tach.levels == (0.0, 1.25)
    for text, kwargs in (("keyphasor edge must be rising or falling, got 'up'", {'edge': 'up'}),
                         ('keyphasor threshold must be finite, got inf',
                          {'threshold': math.inf})):
        with pytest.raises(ValueError) as caught:
            LiveSignal(**kwargs)
        assert str(caught.value) == text


def test_a_sample_on_the_threshold_after_the_crossing_is_not_below_it():
    """Threshold 4 (levels 0, 8; band 1): -4, +0.5, 0, +4: the crossing is between the first."""
    t = np.arange(8.0)
    values = np.array([0.0, 0.0, 4.5, 4.0, 8.0, 8.0, 0.0, 0.0])
    assert signal_marks(t, values, threshold=4.0, hysteresis=0.125).tolist() == \
        [1.0 + 4.0 / 4.5]


# -- the fitted speed at each mark, against numpy's least squares ----------------------------

def fitted_by_numpy(time, good, k, span):
    """
    Return the fitted speed at mark k as Marks.fitted_speed defines it, by numpy's polyfit.

    The marks of ``span`` revolutions of its run of good periods, centred on it where the
    run allows (else the run's first or last ``span``; all of a shorter run); NaN alone.
    """
    first = k
    while first > 0 and good[first - 1]:
        first -= 1
    last = k
    while last < len(good) and good[last]:
        last += 1
    width = min(last - first, span)
    if width == 0:
        return math.nan
    lo = min(max(k - width // 2, first), last - width)
    x = time[lo:lo + width + 1] - time[k]
    return np.polyfit(x, TWO_PI * (np.arange(lo, lo + width + 1) - k),
                      2 if width >= 2 else 1)[-2]


@pytest.mark.parametrize('span', [8, 3, 2, 1])
def test_fitted_speeds_of_jittered_marks_with_gaps(span):
    rng = np.random.default_rng(span)
    time = np.cumsum(rng.uniform(0.09, 0.11, 60))
    good = np.ones(59, bool)
    good[[5, 6, 20, 30, 31, 33, 50]] = False        # runs of 5, 13, 9, 1, 16, 8 periods...
    speed = Marks(time, good, 60).fitted_speed(span)
    for k in range(60):
        want = fitted_by_numpy(time, good, k, span)
        if math.isnan(want):
            assert math.isnan(speed[k]), k
        else:
            assert speed[k] == pytest.approx(want, rel=1e-10), k
    assert math.isnan(speed[6]) and math.isnan(speed[31])     # alone between two gaps
    assert np.isnan(Marks(time[:1], good[:0], 1).fitted_speed(span)).tolist() == [True]


def test_fit_at_zero_against_numpy_row_by_row():
    rng = np.random.default_rng(5)
    offsets = rng.uniform(-2.0, 1.0, (7, 30))
    turns = rng.normal(size=(7, 30))
    valid = rng.random((7, 30)) < 0.6
    valid[:, :4] = [[True] * 4, [True] * 4] + [[False] * 4] * 5     # two points each
    valid[:, 4:6] = [[True] * 2] + [[False] * 2] * 6                 # one point
    valid[:, 6] = False                                              # none
    value, slope, second = fit_at_zero(offsets, turns, valid)
    for row in range(30):
        used = valid[:, row]
        if used.sum() < 2:
            assert math.isnan(value[row]) and math.isnan(slope[row]), row
            assert math.isnan(second[row]), row
            continue
        degree = 2 if used.sum() >= 3 else 1
        fit = np.polyfit(offsets[used, row], turns[used, row], degree)[::-1]
        want = (fit[0], fit[1], 2.0 * fit[2] if degree == 2 else 0.0)
        got = (value[row], slope[row], second[row])
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), row
    # Without a mask every point counts; the turns given once for all rows.
    value, slope, second = fit_at_zero(offsets, turns[:, 0])
    for row in (0, 17):
        fit = np.polyfit(offsets[:, row], turns[:, 0], 2)[::-1]
        assert (value[row], slope[row], second[row]) == pytest.approx(
            (fit[0], fit[1], 2.0 * fit[2]), rel=1e-9)


def test_motion_between_jittered_marks_is_the_hermite_cubic_of_their_fitted_speeds():
    """Jittered marks (the cubic's third-order term is not 0 there), a gap; any sample order."""
    rng = np.random.default_rng(17)
    time = np.cumsum(rng.uniform(0.09, 0.11, 14))
    good = np.ones(13, bool)
    good[6] = False
    marks = Marks(time, good, 14)
    speed = [fitted_by_numpy(time, good, k, 8) for k in range(14)]
    where = [(k, share) for k in (0, 3, 5, 7, 12) for share in (0.0, 0.3, 0.8)] + [(12, 1.0)]
    at = np.array([time[k] + share * (time[k + 1] - time[k]) for k, share in where])
    for order in (np.arange(len(at)), np.arange(len(at))[::-1], rng.permutation(len(at))):
        angle, omega, alpha = marks.motion(at[order])
        for n, (k, share) in enumerate(where[i] for i in order):
            want = hermite_by_hand(time, speed, k, share)
            assert (angle[n], omega[n], alpha[n]) == pytest.approx(want, rel=1e-9, abs=1e-9), \
                (k, share)
    first_smallest = np.array([0, 5, 2, 3])      # the first is the earliest, the rest not sorted
    angle, omega, alpha = marks.motion(at[first_smallest])
    for n, i in enumerate(first_smallest):
        assert angle[n] == pytest.approx(hermite_by_hand(time, speed, *where[i])[0], abs=1e-9)
    no_alpha = marks.motion(at, acceleration=False)
    assert no_alpha[2] is None and np.array_equal(no_alpha[1], marks.motion(at)[1])


def test_a_doubled_mark_among_four_and_on_a_slow_rotor():
    """
    Drop the extra mark of periods 0.1, 1.2, 1.3, and of a 2 s turn split in two.

    The neighbours' medians (ends reflected) are 1.25, 1.2, 0.65; the first period is short
    and with the next makes 1.3, within 20 % of min(1.25, 1.2): an extra mark.
    """
    marks = checked_marks([0.0, 0.1, 1.3, 2.6])
    assert marks.time.tolist() == [0.0, 1.3, 2.6] and marks.doubled == 1
    # A turn of 2 s split 1.2 + 0.8: short is against 0.8 x the usual period (1.6 s).
    slow = checked_marks([0.0, 2.0, 4.0, 6.0, 7.2, 8.0, 10.0, 12.0])
    assert slow.time.tolist() == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0] and slow.doubled == 1
