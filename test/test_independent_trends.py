"""
The fleet's trends by hand: bearing life, urgency, steps, the summary, tables read back.

References: sums and ratios of a few runs worked out here, dates by :mod:`datetime`
arithmetic, straight lines by numpy's polyfit (least squares written another way than
the trends' design matrix), results tables written by pyarrow row by row.
"""

from datetime import datetime, timedelta, timezone
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from cvc_balance.fleet import trends
from cvc_balance.fleet.rows import RESULT_SCHEMA, table
from cvc_balance.fleet.trends import (BearingTrend, FEW, LayoutChange, LEAVES, MachineTrend,
                                      OUT, PlaneTrend, STABLE)

DAY_NS = 86_400 * 10**9
START_NS = 1_760_000_000 * 10**9
START = datetime(2025, 10, 9, 8, 53, 20, tzinfo=timezone.utc)


def test_the_start_by_hand():
    assert START.timestamp() * 10**9 == START_NS


def life_series(days, used, hours, digests, measured):
    return {'t': (START_NS + np.asarray(days, float) * DAY_NS).astype(np.int64),
            'layout_digest': np.array(digests, dtype=object),
            'life_used': np.asarray(used, float), 'hours': np.asarray(hours, float),
            'measured': np.asarray(measured, bool)}


def test_a_bearings_life_and_its_duty_over_the_latest_layout_by_hand():
    """
    Life used summed (Palmgren-Miner), the duty of the latest epoch, hours and days left.

    Front: 5 runs (layouts d1 d1 d2 d2 d2, days 0 10 20 30 40), life used 0.01 ... 0.05,
    hours 1 2 1 2 1 (a missing value counts 0). Used 0.15 of 7 h; the latest epoch's
    0.12 in 4 h: 0.03 an hour, 0.85 / 0.03 h left; a day: runs after its first, 0.09 over
    its 20 days, 0.0045 a day: worn out 0.85 / 0.0045 days after the last run.
    """
    front = life_series([0, 10, 20, 30, 40], [0.01, 0.02, 0.03, 0.04, 0.05],
                        [1, 2, 1, 2, 1], ['d1', 'd1', 'd2', 'd2', 'd2'],
                        [True, False, True, True, False])
    missing = life_series([0, 10, 20], [0.2, np.nan, 0.1], [np.nan, 5, 5], ['d1'] * 3,
                          [False] * 3)
    one = life_series([0, 30], [0.5, 0.25], [2, 1], ['d1', 'd2'], [True, True])
    slow = life_series([0, 1], [0.0, 1e-6], [1, 1], ['d1', 'd1'], [False, False])
    worn = life_series([0, 2], [0.75, 0.5], [1, 1], ['d1', 'd1'], [False, False])
    got = {b.support: b for b in trends.bearing_trends(
        {'front': front, 'missing': missing, 'one': one, 'slow': slow, 'worn': worn})}
    assert list(got) == ['front', 'missing', 'one', 'slow', 'worn']
    f = got['front']
    assert (f.runs, f.measured_runs) == (5, 3)
    assert f.life_used == pytest.approx(0.15, rel=1e-15) and f.hours == 7.0
    assert f.duty_per_hour == pytest.approx(0.12 / 4, rel=1e-15)
    assert f.left_hours == pytest.approx(0.85 / 0.03, rel=1e-14)
    assert f.duty_per_day == pytest.approx(0.09 / 20, rel=1e-15)
    want = START + timedelta(days=40 + 0.85 / 0.0045)
    assert abs(f.worn_out - want) <= timedelta(microseconds=2), (f.worn_out, want)
    m = got['missing']                      # nan life 0, nan hours 0: 0.3 of 10 h
    assert (m.life_used, m.hours) == (pytest.approx(0.3, rel=1e-15), 10.0)
    assert m.duty_per_hour == pytest.approx(0.03, rel=1e-14)
    assert m.left_hours == pytest.approx(0.7 / 0.03, rel=1e-14)
    assert m.duty_per_day == pytest.approx(0.1 / 20, rel=1e-15)
    assert abs(m.worn_out - (START + timedelta(days=20 + 0.7 / 0.005))) \
        <= timedelta(microseconds=2)
    o = got['one']                          # one run in the latest epoch: no per-day duty
    assert (o.duty_per_hour, o.left_hours) == (0.25, pytest.approx(0.25 / 0.25))
    assert (o.duty_per_day, o.worn_out) == (None, None)
    assert (o.measured_runs, o.life_used, o.hours) == (2, 0.75, 3.0)
    s = got['slow']                         # 1e-6 a day: worn out beyond ten years
    assert s.duty_per_day == pytest.approx(1e-6) and s.worn_out is None
    assert s.left_hours == pytest.approx((1 - 1e-6) / 5e-7)
    w = got['worn']                         # more than its rating life used: none left
    assert (w.left_hours, w.worn_out) == (0.0, START + timedelta(days=2))
    assert w.duty_per_day == 0.25


def test_no_duty_without_running_time_or_life_used():
    """A run of no hours or no life used tells no duty; a span of no days no daily one."""
    idle = life_series([0, 5], [0.0, 0.0], [1, 1], ['d'] * 2, [False] * 2)
    stopped = life_series([0, 5], [0.1, 0.1], [0, 0], ['d'] * 2, [False] * 2)
    instant = life_series([3, 3], [0.1, 0.1], [1, 1], ['d'] * 2, [False] * 2)
    got = trends.bearing_trends({'idle': idle, 'stopped': stopped, 'instant': instant})
    for b in got[:2]:
        assert (b.duty_per_hour, b.left_hours) == (None, None), b
    assert got[1].duty_per_day == pytest.approx(0.1 / 5)
    assert (got[0].duty_per_day, got[0].worn_out) == (None, None)
    assert got[2].duty_per_hour == pytest.approx(0.1) and got[2].duty_per_day is None


def machine(name, bearings):
    return MachineTrend(name, 1, START, START, 'g', 6.3, [], [], bearings=bearings)


def test_machines_ranked_by_the_bearing_with_the_fewest_hours_left():
    """Hours left first (fewest first), then bearings of untold duty by life used, then none."""
    def bearing(support, used, left):
        return BearingTrend(support, 1, 0, used, 1.0, left_hours=left)
    a = machine('a', [bearing('x', 0.1, 500.0), bearing('y', 0.9, 80.0)])
    b = machine('b', [bearing('x', 0.2, None), bearing('y', 0.6, 120.0)])
    c = machine('c', [bearing('x', 0.3, None), bearing('y', 0.7, None)])
    d = machine('d', [bearing('x', 0.8, None)])
    e, f = machine('e', []), machine('f', [])
    assert a.worst_bearing.support == 'y' and b.worst_bearing.support == 'y'
    assert c.worst_bearing.support == 'y' and e.worst_bearing is None
    ranked = trends.life_ranked([f, c, e, b, d, a])
    assert [t.machine_id for t in ranked] == ['a', 'b', 'd', 'c', 'e', 'f']
    tie = machine('0', [bearing('x', 0.1, 80.0)])
    assert [t.machine_id for t in trends.life_ranked([a, tie])] == ['0', 'a']
    unused = machine('z', [bearing('x', 0.0, None)])
    assert [t.machine_id for t in trends.life_ranked([e, unused])] == ['z', 'e']


def plane(name, status, fraction, leaves=None):
    trend = PlaneTrend(name, np.array([START_NS]), np.array([1.0]), np.array([np.nan]),
                       np.array([1.0]), np.array([0]), np.array([False]))
    trend.status, trend.now_fraction, trend.leaves = status, fraction, leaves
    return trend


def urgency(*planes):
    m = MachineTrend('m', 1, START, START, 'g', 6.3, list(planes), [])
    trends._urgency(m)
    return m.status, m.worst_plane, m.leaves, m.urgency


def test_a_machines_status_worst_plane_and_urgency_by_hand():
    """Out of grade: the plane most over; leaving: the earliest date; else the nearest."""
    soon, later = START + timedelta(days=30), START + timedelta(days=90)
    assert urgency() == (FEW, None, None, (3, 0.0, 'm'))
    assert urgency(plane('I', OUT, 1.2), plane('II', OUT, 1.5), plane('III', LEAVES, 2.0,
                                                                      soon)) == \
        (OUT, 'II', None, (0, -1.5, 'm'))
    assert urgency(plane('I', STABLE, 0.9), plane('II', OUT, 1.1)) == \
        (OUT, 'II', None, (0, -1.1, 'm'))
    assert urgency(plane('I', LEAVES, 0.3, later), plane('II', LEAVES, 0.2, soon),
                   plane('III', STABLE, 0.95)) == \
        (LEAVES, 'II', soon, (1, soon.timestamp(), 'm'))
    assert urgency(plane('I', LEAVES, 0.3, None), plane('II', STABLE, 0.4)) == \
        (STABLE, 'II', None, (2, -0.4, 'm'))
    assert urgency(plane('I', FEW, 0.7), plane('II', FEW, 0.2)) == \
        (FEW, 'I', None, (2, -0.7, 'm'))
    assert urgency(plane('I', FEW, 0.7), plane('II', STABLE, 0.2))[0] == STABLE


def series(days, amounts, digests=None, permissible=1000.0, amounts_ii=None):
    """One machine's series as read_series gives it."""
    n = len(days)
    digests = ['d1'] * n if digests is None else digests
    amounts_ii = np.full(n, np.nan) if amounts_ii is None else amounts_ii
    return {'t': (START_NS + np.asarray(days, float) * DAY_NS).astype(np.int64),
            'layout_digest': np.array(digests, dtype=object),
            'layout_name': np.array([f'gantry {d}' for d in digests], dtype=object),
            'grade': np.full(n, 6.3),
            'amount_I': np.asarray(amounts, float), 'ci95_I': np.full(n, np.nan),
            'permissible_I': np.full(n, permissible), 'identified_I': np.zeros(n, bool),
            'amount_II': np.asarray(amounts_ii, float), 'ci95_II': np.full(n, np.nan),
            'permissible_II': np.full(n, 2 * permissible), 'identified_II': np.ones(n, bool)}


def test_a_projection_from_a_given_date_and_a_drift_too_slow_to_matter():
    """
    ``now``: the fitted line there (numpy's polyfit), the crossing counted from it.

    A drift of 0.2 g mm/day from 500 takes 2500 days to 1000 g mm: the first whole day
    there counted from the last run, or from 1200 days later; from 3000 days it is out
    already. A drift of 0.1 g mm/day: beyond the horizon, no significant drift said.
    """
    days = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 50.0])
    wiggle = np.array([0.01, -0.02, 0.0, 0.02, -0.01, 0.0])
    amounts = 500.0 + 0.2 * days + wiggle
    b, a = np.polyfit(days, amounts, 1)
    fitted = trends.fit_machine('m', series(days, amounts))
    (p,) = fitted.planes
    assert p.status == LEAVES
    first = math.ceil((1000.0 - a) / b - days[-1])            # whole days after the last run
    assert p.leaves == START + timedelta(days=days[-1] + first)
    now = START + timedelta(days=1200)
    later = trends.fit_machine('m', series(days, amounts), now=now).planes[0]
    assert later.now_fraction == pytest.approx((a + b * 1200) / 1000.0, rel=1e-12)
    assert later.leaves == now + timedelta(days=math.ceil((1000.0 - a) / b - 1200))
    slow = trends.fit_machine('m', series(days, 500.0 + 0.1 * days + wiggle)).planes[0]
    assert slow.drift - slow.drift_ci95 > 0 and slow.status == STABLE
    assert (slow.leaves, slow.leaves_earliest, slow.leaves_latest) == (None, None, None)
    # Out of grade already at ``now``: said out, not projected.
    out = trends.fit_machine('m', series(days, amounts),
                             now=START + timedelta(days=3000)).planes[0]
    assert out.status == OUT and out.leaves is None
    assert out.now_fraction == pytest.approx((a + b * 3000) / 1000.0, rel=1e-12)


def test_runs_at_one_moment_or_too_few_for_an_epoch_tell_no_drift():
    """Three runs at one time: no spread of days; two epochs of 1 and 2 runs: no dof."""
    same = trends.fit_machine('m', series([5.0, 5.0, 5.0], [300.0, 320.0, 310.0]))
    assert same.planes[0].status == FEW and same.planes[0].now_fraction == 0.31
    assert same.planes[0].levels is None and math.isnan(same.planes[0].drift)
    split = trends.fit_machine('m', series([0.0, 5.0, 9.0], [300.0, 500.0, 520.0],
                                           ['a', 'b', 'b']))
    assert split.planes[0].status == FEW and split.status == FEW
    (change,) = split.changes
    assert all(math.isnan(v) for v in change.steps['I'])
    assert (change.when, change.before, change.after) == (START + timedelta(days=5), 'a', 'b')


def test_two_planes_their_epochs_and_a_plane_that_misses_runs():
    """
    Plane II measured only in epoch b and c: its epochs renumbered, no step a -> b for it.

    Plane I's levels and drift against numpy least squares with a column per epoch.
    """
    days = np.array([0.0, 7.0, 15.0, 22.0, 31.0, 40.0, 48.0, 55.0, 63.0])
    digests = ['a', 'a', 'a', 'b', 'b', 'b', 'c', 'c', 'c']
    noise = np.array([3.0, -2.0, 1.0, -4.0, 2.0, 1.0, -1.0, 3.0, -2.0])
    level = {'a': 200.0, 'b': 350.0, 'c': 300.0}
    amounts = np.array([level[d] for d in digests]) + 2.0 * days + noise
    second = np.where(days >= 20.0, 400.0 + 1.0 * days + noise[::-1], np.nan)
    fitted = trends.fit_machine('m', series(days, amounts, digests, amounts_ii=second))
    one, two = fitted.planes
    assert (one.plane, two.plane) == ('I', 'II')
    design = np.column_stack([[d == e for d in digests] for e in 'abc'] + [days]).astype(float)
    x, *_ = np.linalg.lstsq(design, amounts, rcond=None)
    assert np.allclose(one.levels + [one.drift], x, rtol=1e-12, atol=0)
    from scipy import stats
    s2 = np.sum((amounts - design @ x) ** 2) / (len(days) - 4)
    half = stats.t.ppf(0.975, len(days) - 4) * math.sqrt(
        s2 * np.linalg.inv(design.T @ design)[3, 3])
    assert one.drift_ci95 == pytest.approx(half, rel=1e-9)
    assert two.epoch_ids.tolist() == [1, 2] and two.epoch.tolist() == [0] * 3 + [1] * 3
    assert two.identified.all() and not one.identified.any()
    first, last = fitted.changes
    assert (first.before, first.after, last.before, last.after) == ('a', 'b', 'b', 'c')
    assert all(math.isnan(v) for v in first.steps['II'])
    assert first.steps['I'][0] == pytest.approx(x[1] - x[0], rel=1e-12)
    assert last.steps['I'][0] == pytest.approx(x[2] - x[1], rel=1e-12)
    keep = ~np.isnan(second)
    design = np.column_stack([[d == e for d in np.array(digests)[keep]] for e in 'bc']
                             + [days[keep]]).astype(float)
    y, *_ = np.linalg.lstsq(design, second[keep], rcond=None)
    assert last.steps['II'][0] == pytest.approx(y[1] - y[0], rel=1e-12)
    assert (fitted.layout, fitted.grade, fitted.runs) == ('gantry c', 6.3, 9)
    assert (fitted.first, fitted.last) == (START, START + timedelta(days=63))
    # The fitted line of an epoch asked for, and of the latest by default.
    assert one.line([START_NS + 10 * DAY_NS], 0)[0] == pytest.approx(x[0] + 10 * x[3])
    assert one.line([START_NS + 10 * DAY_NS])[0] == pytest.approx(x[2] + 10 * x[3])


def test_a_machines_summary_as_json_by_hand():
    """Dates in ISO 8601 with Z, numbers not finite as null, every field by hand."""
    p = PlaneTrend('I', START_NS + np.arange(3) * DAY_NS, np.array([300.0, 310.0, 320.0]),
                   np.array([5.0, np.nan, 6.0]), np.array([900.0, 950.0, 1000.0]),
                   np.zeros(3, int), np.array([True, False, True]), drift=2.5,
                   drift_ci95=0.75, now_fraction=0.32, status=LEAVES,
                   leaves=START + timedelta(days=3),
                   leaves_earliest=START + timedelta(days=2, microseconds=5),
                   leaves_latest=START + timedelta(days=9))
    q = PlaneTrend('II', START_NS + np.arange(3) * DAY_NS, np.array([1.0, 2.0, 3.0]),
                   np.full(3, np.nan), np.full(3, 50.0), np.zeros(3, int), np.zeros(3, bool),
                   drift=math.nan, drift_ci95=math.inf, now_fraction=math.nan)
    change = LayoutChange(START + timedelta(hours=1), 'd1', 'd2',
                          {'I': (12.5, math.inf), 'II': (-3.0, 1.5)})
    bearing = BearingTrend('front', 4, 1, 0.25, 12.0, duty_per_hour=0.01, duty_per_day=0.002,
                           left_hours=75.0, worn_out=START + timedelta(days=400))
    idle = BearingTrend('rear', 1, 0, 0.0, 0.0)
    m = MachineTrend('m1', 3, START, START + timedelta(days=2), 'gantry', 6.3, [p, q],
                     [change], status=LEAVES, worst_plane='I', leaves=START + timedelta(days=3),
                     bearings=[bearing, idle])
    assert trends.trend_summary(m) == {
        'machine_id': 'm1', 'status': 'LEAVES GRADE', 'runs': 3,
        'first_run': '2025-10-09T08:53:20Z', 'last_run': '2025-10-11T08:53:20Z',
        'layout': 'gantry', 'grade': 6.3, 'worst_plane': 'I',
        'leaves_grade': '2025-10-12T08:53:20Z',
        'planes': [{'plane': 'I', 'status': 'LEAVES GRADE', 'runs': 3, 'identified_runs': 2,
                    'last_g_mm': 320.0, 'permissible_g_mm': 1000.0, 'fraction_now': 0.32,
                    'drift_g_mm_per_day': 2.5, 'drift_ci95_g_mm_per_day': 0.75,
                    'leaves_grade': '2025-10-12T08:53:20Z',
                    'leaves_grade_earliest': '2025-10-11T08:53:20.000005Z',
                    'leaves_grade_latest': '2025-10-18T08:53:20Z'},
                   {'plane': 'II', 'status': 'TOO FEW RUNS', 'runs': 3, 'identified_runs': 0,
                    'last_g_mm': 3.0, 'permissible_g_mm': 50.0, 'fraction_now': None,
                    'drift_g_mm_per_day': None, 'drift_ci95_g_mm_per_day': None,
                    'leaves_grade': None, 'leaves_grade_earliest': None,
                    'leaves_grade_latest': None}],
        'layout_changes': [{'at': '2025-10-09T09:53:20Z', 'from_digest': 'd1',
                            'to_digest': 'd2',
                            'steps': {'I': {'g_mm': 12.5, 'ci95_g_mm': None},
                                      'II': {'g_mm': -3.0, 'ci95_g_mm': 1.5}}}],
        'bearings': [{'support': 'front', 'runs': 4, 'measured_runs': 1, 'life_used': 0.25,
                      'running_hours': 12.0, 'life_per_running_hour': 0.01,
                      'life_per_day': 0.002, 'hours_left': 75.0,
                      'rating_life_reached': '2026-11-13T08:53:20Z'},
                     {'support': 'rear', 'runs': 1, 'measured_runs': 0, 'life_used': 0.0,
                      'running_hours': 0.0, 'life_per_running_hour': None,
                      'life_per_day': None, 'hours_left': None,
                      'rating_life_reached': None}]}


def test_the_line_and_band_of_an_epoch_of_one_run_and_of_a_precise_fit():
    """
    Fit the line and band of a one-run epoch and of a precise fit.

    Epochs a a a a b (b: the last run alone): the default epoch is b. A fit to 0.01 g mm:
    a band far under 1 g mm; each against numpy least squares, the band
    t sqrt(s^2 g' (X'X)^-1 g), g = (epoch indicator, days).
    """
    from scipy import stats
    days = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    wiggle = np.array([0.01, -0.02, 0.0, 0.02, 0.005])
    amounts = 500.0 + 0.2 * days + 30.0 * (days == 40.0) + wiggle
    fitted = trends.fit_machine('m', series(days, amounts, ['a'] * 4 + ['b']))
    (p,) = fitted.planes
    design = np.column_stack([days < 40, days == 40, days]).astype(float)
    x, *_ = np.linalg.lstsq(design, amounts, rcond=None)
    s2 = np.sum((amounts - design @ x) ** 2) / 2
    inverse = np.linalg.inv(design.T @ design)
    t = stats.t.ppf(0.975, 2)
    at = START_NS + np.array([15, 60]) * DAY_NS
    for epoch, level in ((0, x[0]), (1, x[1])):
        g = np.column_stack([np.full(2, epoch == 0), np.full(2, epoch == 1),
                             [15.0, 60.0]]).astype(float)
        half = t * np.sqrt(s2 * np.einsum('ij,jk,ik->i', g, inverse, g))
        assert np.allclose(p.line(at, epoch), level + x[2] * np.array([15.0, 60.0]),
                           rtol=1e-12)
        assert np.allclose(p.band(at, epoch), half, rtol=1e-9), (epoch, half)
        assert half.max() < 0.5
    assert np.array_equal(p.line(at), p.line(at, 1)) and np.array_equal(p.band(at),
                                                                        p.band(at, 1))
    (change,) = fitted.changes
    e = np.array([-1.0, 1.0, 0.0])
    assert change.steps['I'][0] == pytest.approx(x[1] - x[0], rel=1e-9)
    assert change.steps['I'][1] == pytest.approx(t * math.sqrt(s2 * e @ inverse @ e), rel=1e-9)
    assert change.steps['I'][1] < 0.5


def result_row(machine, day, digest='d1', analysed=0, **columns):
    row = {'machine_id': machine, 'segment_start': START_NS + int(day * DAY_NS),
           'layout_digest': digest, 'layout_name': 'gantry', 'grade': 6.3,
           'segment_samples': 100, 'plane_I_permissible_g_mm': 1000.0,
           'plane_II_permissible_g_mm': 2000.0, 'plane_I_g_mm': 100.0 + day,
           'plane_II_g_mm': 200.0 + day, 'verdict_source': 'layout',
           'analysed_at': START_NS + analysed, 'running_hours': 0.5}
    row.update(columns)
    return row


def bearings(*uses):
    return [{'support': s, 'life_used': u, 'l10_hours': 1000.0, 'equivalent_load_N': 10.0,
             'unbalance_share': 0.1, 'source': source} for s, u, source in uses]


def test_bearing_life_read_from_the_table_each_run_once(tmp_path):
    """
    Read bearing life from the table, each run once.

    read_life: per machine and support the runs by time, the latest analysis of a run,
    not the runs without samples, a start or bearings; machine_trends carries them.
    """
    rows = [result_row('m', 0, bearings=bearings(('front', 0.01, 'measured'),
                                                 ('rear', 0.02, 'layout'))),
            result_row('m', 2, analysed=5, bearings=bearings(('front', 0.05, 'layout'))),
            result_row('m', 2, analysed=9, running_hours=1.5,
                       bearings=bearings(('front', 0.03, 'measured'))),
            result_row('m', 1, 'd2', bearings=bearings(('front', 0.02, 'layout'))),
            result_row('m', 3, segment_samples=0, bearings=bearings(('front', 0.5, 'layout'))),
            result_row('m', 4, bearings=None),
            result_row('m', 5, segment_start=None, bearings=bearings(('front', 0.5, 'x'))),
            result_row('other', 1, bearings=bearings(('front', 0.07, 'layout')))]
    path = tmp_path / 'fleet.parquet'
    pq.write_table(table(rows, RESULT_SCHEMA), path)
    life = trends.read_life(path)
    assert sorted(life) == ['m', 'other'] and sorted(life['m']) == ['front', 'rear']
    front = life['m']['front']
    assert ((front['t'] - START_NS) // DAY_NS).tolist() == [0, 1, 2]
    assert front['layout_digest'].tolist() == ['d1', 'd2', 'd1']
    assert front['life_used'].tolist() == [0.01, 0.02, 0.03]
    assert front['hours'].tolist() == [0.5, 0.5, 1.5]
    assert front['measured'].tolist() == [True, False, True]
    assert life['m']['rear']['life_used'].tolist() == [0.02]
    assert list(trends.read_life(path, machine='other')) == ['other']
    assert trends.read_life(path, machine='none') == {}
    (m,) = trends.machine_trends(path, machine='m')
    assert [(b.support, b.runs, b.measured_runs) for b in m.bearings] == \
        [('front', 3, 2), ('rear', 1, 0)]
    assert m.bearings[0].life_used == pytest.approx(0.06, rel=1e-15)


def test_a_tables_missing_values_read_as_nan_or_false_and_machines_ranked(tmp_path):
    """
    Nulls read back: a number as nan, a name as None; the machines by urgency.

    Bug: a null text read as '?' (numpy's default fill of object arrays, ``filled(None)``).
    """
    rows = [result_row('b', d, plane_I_g_mm=700.0 + 100.0 * d) for d in range(5)]
    rows += [result_row('a', d, plane_I_g_mm=100.0, plane_II_g_mm=None, grade=None,
                        layout_name=None if d == 3 else 'gantry') for d in range(4)]
    rows += [result_row('c', 0, plane_I_g_mm=None, plane_II_g_mm=None)]
    path = tmp_path / 'fleet.parquet'
    pq.write_table(table(rows, RESULT_SCHEMA), path)
    series = trends.read_series(path)
    assert list(series) == ['a', 'b', 'c']
    a = series['a']
    assert np.isnan(a['amount_II']).all() and np.isnan(a['grade']).all()
    assert a['layout_name'].tolist() == ['gantry'] * 3 + [None]
    assert a['identified_I'].tolist() == [False] * 4
    ranked = trends.machine_trends(path)
    assert [t.machine_id for t in ranked] == ['b', 'a', 'c']
    assert ranked[0].status == OUT and ranked[0].worst_plane == 'I'
    assert [p.plane for p in ranked[1].planes] == ['I'] and ranked[2].planes == []
    assert ranked[2].urgency == (3, 0.0, 'c')
    assert trends.read_series(path, machine='z') == {}
    assert trends.machine_trends(path, machine='z') == []
    # Projected from a date given: 'a' (100 of its 1000 g mm, no drift) stays; 'b', 100 g
    # mm a day from 1100 at day 4, is out of grade from that date on too.
    later = trends.machine_trends(path, machine='b', now=START + timedelta(days=400))
    assert later[0].planes[0].now_fraction == pytest.approx((1100 + 396 * 100) / 1000,
                                                            rel=1e-9)


def test_the_fewest_runs_fitted_and_runs_within_a_day():
    """
    Fit the fewest runs, and runs within a day.

    Three runs of one layout (1 degree of freedom): fitted, the drift numpy's polyfit
    slope; runs hours apart (less than a day between first and last): fitted too.
    """
    three = trends.fit_machine('m', series([0.0, 5.0, 11.0], [300.0, 330.0, 351.0]))
    slope = np.polyfit([0.0, 5.0, 11.0], [300.0, 330.0, 351.0], 1)[0]
    assert three.planes[0].drift == pytest.approx(slope, rel=1e-12)
    assert three.planes[0].status != FEW
    hours = np.array([0.0, 3.0, 7.0, 11.0, 20.0]) / 24.0
    amounts = np.array([300.0, 301.0, 305.0, 306.0, 310.0])
    quick = trends.fit_machine('m', series(hours, amounts)).planes[0]
    assert quick.drift == pytest.approx(np.polyfit(hours, amounts, 1)[0], rel=1e-12)


def test_too_few_runs_are_judged_by_the_last_run_and_its_share():
    """Three runs, two layouts (no degree of freedom): the last amount over the last share."""
    data = series([0.0, 5.0, 9.0], [300.0, 500.0, 520.0], ['a', 'b', 'b'])
    data['permissible_I'] = np.array([1000.0, 900.0, 800.0])
    (plane,) = trends.fit_machine('m', data).planes
    assert plane.status == FEW and plane.now_fraction == 520.0 / 800.0


def test_a_plane_with_no_run_and_a_layout_of_one_run_between_two():
    """
    Fit a plane never measured beside one that is, and a one-run layout.

    Plane I never measured: only plane II, its 95 % radii kept. Layouts a a a b c c c: the
    step b -> c is a_c - a_b (numpy least squares with a column per layout).
    """
    days = np.array([0.0, 8.0, 17.0, 25.0, 33.0, 41.0, 50.0])
    digests = ['a', 'a', 'a', 'b', 'c', 'c', 'c']
    noise = np.array([2.0, -3.0, 1.0, 0.0, -2.0, 3.0, -1.0])
    amounts = np.array([100.0, 100.0, 100.0, 160.0, 130.0, 130.0, 130.0]) + days + noise
    data = series(days, np.full(7, np.nan), digests)
    data['amount_II'], data['ci95_II'] = amounts, np.arange(7.0)
    data['identified_II'] = np.ones(7, bool)
    fitted = trends.fit_machine('m', data)
    (plane,) = fitted.planes
    assert plane.plane == 'II' and plane.ci95.tolist() == list(range(7))
    design = np.column_stack([[d == e for d in digests] for e in 'abc'] + [days]).astype(float)
    x, *_ = np.linalg.lstsq(design, amounts, rcond=None)
    first, second = fitted.changes
    assert first.steps['II'][0] == pytest.approx(x[1] - x[0], rel=1e-9)
    assert second.steps['II'][0] == pytest.approx(x[2] - x[1], rel=1e-9)
    assert 'I' not in first.steps


def test_a_bearing_whose_life_went_in_the_first_run_of_its_layout():
    """All of the latest layout's life used in its first run: no daily duty, no date."""
    early = life_series([0, 4, 9], [0.1, 0.0, 0.0], [1, 1, 1], ['d'] * 3, [False] * 3)
    (b,) = trends.bearing_trends({'early': early})
    assert b.duty_per_day == 0.0 and b.worn_out is None
    assert b.duty_per_hour == pytest.approx(0.1 / 3) and b.left_hours == pytest.approx(27.0)


def test_masked_values_and_dates_by_hand():
    """Masked numbers nan, flags False, texts None, whatever lies under the mask; ns floored."""
    texts = np.ma.array(np.array(['a', 'b', 'c'], dtype=object), mask=[False, True, False])
    assert trends._filled(texts).tolist() == ['a', None, 'c']
    flags = np.ma.array([True, True, False], mask=[False, True, False])
    assert trends._filled(flags).tolist() == [True, False, False]
    numbers = np.ma.array([1.5, 2.5], mask=[True, False])
    assert np.isnan(trends._filled(numbers)[0]) and trends._filled(numbers)[1] == 2.5
    counts = np.ma.array(np.array([4, 5], dtype=np.int64), mask=[False, True])
    assert trends._filled(counts).tolist() == [4, 5]
    plain = np.array([1.0])
    assert trends._filled(plain) is plain
    epoch = datetime(1970, 1, 1, tzinfo=timezone.utc)
    assert trends._date(1_999) == epoch + timedelta(microseconds=1)


def test_a_stable_plane_is_not_projected_and_its_share_is_the_last_runs():
    """
    Project nothing for a stable plane; judge by the last run's share.

    No significant drift: no date, no interval. A share changed at the last run (a new
    layout): the level over that share.
    """
    days = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    flat = trends.fit_machine('m', series(days, [500.0, 520.0, 480.0, 510.0, 490.0]))
    plane = flat.planes[0]
    assert plane.status == STABLE
    assert (plane.leaves, plane.leaves_earliest, plane.leaves_latest) == (None, None, None)
    data = series(days, [500.0, 502.0, 504.0, 506.0, 540.0], ['a'] * 4 + ['b'])
    data['permissible_I'] = np.array([1000.0] * 4 + [1200.0])
    (plane,) = trends.fit_machine('m', data).planes
    design = np.column_stack([days < 40, days == 40, days]).astype(float)
    x, *_ = np.linalg.lstsq(design, data['amount_I'], rcond=None)
    assert plane.now_fraction == pytest.approx((x[1] + 40.0 * x[2]) / 1200.0, rel=1e-12)


def test_a_crossing_on_the_horizons_last_day_and_the_day_after():
    """
    Find a crossing on the horizon's last day, not the day after.

    A line from about 500 g mm rising 0.1 g mm/day reaches a share put 3649.5 days after
    the last run on day 3650 (the horizon's last: said), one put 3650.5 days after on day
    3651 (beyond: no date, no significant drift).
    """
    days = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    amounts = 500.0 + 0.1 * days + np.array([0.001, -0.002, 0.0, 0.002, -0.001])
    b, a = np.polyfit(days, amounts, 1)
    for ahead, found in ((3649.5, 3650), (3650.5, None)):
        limit = a + b * (40.0 + ahead)
        (plane,) = trends.fit_machine('m', series(days, amounts, permissible=limit)).planes
        if found is None:
            assert plane.leaves is None and plane.status == STABLE
        else:
            assert plane.leaves == START + timedelta(days=40 + found)
            assert plane.status == LEAVES
