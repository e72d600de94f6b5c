"""
What the fleet's charts draw, against the trends worked out here by numpy least squares.

A machine of two layout epochs drifting about 4 g mm/day toward a share that the layout
change moved: its chart (one panel) must draw the runs (identified with their 95 % bars,
the layout's hollow), the permissible share as a red step, each epoch's fitted line, the
projection with its band, the interval of the date it leaves the grade and that date, the
layout change with its step; the fleet chart a bar per machine to the day it leaves, in
urgency order. Every number from the design matrix [epoch a, epoch b, days] solved by
numpy here and Student's t by scipy; every date by :mod:`datetime`. Each test draws the
PNG the function writes (tight layout and Agg: about 0.4 s a figure here, its cost).
"""

from datetime import datetime, timedelta, timezone
import math

from matplotlib.colors import to_hex
from matplotlib.dates import date2num, num2date
import numpy as np
import pytest
from scipy import stats

from cvc_balance.fleet.charts import chart_name, fleet_chart, machine_chart
from cvc_balance.fleet.trends import fit_machine

DAY_NS = 86_400 * 10**9
START = datetime(2025, 10, 9, 8, 53, 20, tzinfo=timezone.utc)
START_NS = 1_760_000_000 * 10**9
RED, BLUE, GREY = '#c0392b', '#1f5f99', '#7f7f7f'
DAYS = np.array([0.0, 9.0, 20.0, 31.0, 40.0, 52.0, 60.0, 71.0, 83.0, 90.0, 101.0, 112.0])
NOISE = np.array([6.0, -9.0, 4.0, 8.0, -5.0, 2.0, -7.0, 9.0, -3.0, 5.0, -6.0, 1.0])
AFTER = DAYS >= 50.0
AMOUNTS = 300.0 + 4.0 * DAYS + 120.0 * AFTER + NOISE
SHARE = np.where(AFTER, 1300.0, 1200.0)
MEASURED = np.array([True, False] * 6)
CI95 = np.where(MEASURED, 20.0 + DAYS / 10.0, np.nan)


def series(amounts=AMOUNTS, share=SHARE):
    n = len(DAYS)
    digests = np.where(AFTER, 'b', 'a').astype(object)
    return {'t': (START_NS + DAYS * DAY_NS).astype(np.int64), 'layout_digest': digests,
            'layout_name': np.array([f'gantry {d}' for d in digests], dtype=object),
            'grade': np.full(n, 6.3), 'amount_I': np.asarray(amounts, float), 'ci95_I': CI95,
            'permissible_I': np.asarray(share, float), 'identified_I': MEASURED,
            'amount_II': np.full(n, np.nan), 'ci95_II': np.full(n, np.nan),
            'permissible_II': np.full(n, 1.0), 'identified_II': np.zeros(n, bool)}


def by_hand():
    """Levels, drift, their covariance and t, the line and band of epoch b at days d."""
    design = np.column_stack([~AFTER, AFTER, DAYS]).astype(float)
    x, *_ = np.linalg.lstsq(design, AMOUNTS, rcond=None)
    dof = len(DAYS) - 3
    s2 = np.sum((AMOUNTS - design @ x) ** 2) / dof
    inverse = np.linalg.inv(design.T @ design)
    t = stats.t.ppf(0.975, dof)

    def line(d):
        return x[1] + x[2] * np.asarray(d)

    def half(d):
        d = np.asarray(d, float)
        return t * np.sqrt(s2 * (inverse[1, 1] + 2 * inverse[1, 2] * d + inverse[2, 2] * d * d))
    return x, s2, inverse, t, line, half


def day(k):
    return START + timedelta(days=float(k))


def to_days(value):
    """Days since START of a chart's x value: a datetime (UTC, naive) or a date number."""
    when = value.replace(tzinfo=timezone.utc) if isinstance(value, datetime) \
        else num2date(value)
    return (when - START).total_seconds() / 86400


def first(values):
    return int(np.flatnonzero(values >= 1300.0)[0])


def test_a_machines_chart_draws_its_runs_share_fit_projection_and_change(tmp_path):
    x, s2, inverse, t, line, half = by_hand()
    grid = DAYS[-1] + np.arange(3651)
    leaves, earliest, latest = (first(line(grid)), first(line(grid) + half(grid)),
                                first(line(grid) - half(grid)))
    trend = fit_machine('site/m 1', series())
    assert trend.leaves == day(grid[leaves])                  # the premise, by hand
    figure = machine_chart(trend, tmp_path / chart_name(trend.machine_id))
    assert chart_name('site/m 1') == 'site_m_1.png'
    assert chart_name('Gantry-7@Site+B.x') == 'Gantry-7@Site+B.x.png'
    assert (tmp_path / 'site_m_1.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert figure._suptitle.get_text() == (
        f'site/m 1: LEAVES GRADE {day(grid[leaves]):%Y-%m-%d}   (layout gantry b, G 6.3, '
        '12 runs)')
    (ax,) = figure.axes
    assert ax.get_title(loc='left') == f'plane I: LEAVES GRADE {day(grid[leaves]):%Y-%m-%d}'
    assert ax.get_ylabel() == 'unbalance [g mm]' and ax.get_ylim()[0] == 0.0
    lines = {line_.get_label(): line_ for line_ in ax.get_lines()}

    def days_of(artist):
        return np.array([to_days(v) for v in artist.get_xdata()])
    # The runs: identified ones with their 95 % bars, the layout's hollow.
    (dots,) = [ln for ln in ax.get_lines() if ln.get_marker() == 'o'
               and ln.get_markerfacecolor() != 'none']
    assert np.allclose(days_of(dots), DAYS[MEASURED], atol=1e-9)
    assert np.array_equal(dots.get_ydata(), AMOUNTS[MEASURED])
    assert to_hex(dots.get_color()) == BLUE and dots.get_marker() == 'o'
    (bars,) = [c for c in ax.collections if type(c).__name__ == 'LineCollection']
    assert np.allclose([s[1, 1] - s[0, 1] for s in bars.get_segments()],
                       2 * CI95[MEASURED], rtol=1e-12)
    hollow = lines["layout's"]
    assert np.array_equal(hollow.get_ydata(), AMOUNTS[~MEASURED])
    assert hollow.get_markerfacecolor() == 'none'
    # The share: a red step at each run, held to the chart's end (the latest crossing).
    share = lines['permissible (G 6.3)']
    assert to_hex(share.get_color()) == RED and share.get_drawstyle() == 'steps-post'
    assert np.array_equal(share.get_ydata(), np.append(SHARE, 1300.0))
    assert np.allclose(days_of(share), np.append(DAYS, grid[latest]), atol=1e-9)
    # Each epoch's fitted line over its runs.
    fitted = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 20]
    assert len(fitted) == 2
    for level, ln, (d0, d1) in zip(x[:2], fitted, ((0.0, 40.0), (52.0, 112.0))):
        d = days_of(ln)
        assert abs(d[0] - d0) < 1e-9 and abs(d[-1] - d1) < 1e-9
        assert np.allclose(ln.get_ydata(), level + x[2] * d, rtol=1e-9)
        assert to_hex(ln.get_color()) == '#000000'
    # The projection, dashed, to the latest crossing; its band; its interval and date.
    label = f'drift {x[2]:+.0f} +- {t * math.sqrt(s2 * inverse[2, 2]):.0f} g mm/day'
    ahead = lines[label]
    d = days_of(ahead)
    assert ahead.get_linestyle() == '--' and len(d) == 200
    assert abs(d[0] - DAYS[-1]) < 1e-9 and abs(d[-1] - grid[latest]) < 1e-9
    assert np.allclose(ahead.get_ydata(), line(d), rtol=1e-9)
    (band,) = [c for c in ax.collections if type(c).__name__ == 'FillBetweenPolyCollection']
    top = band.get_paths()[0].vertices[:, 1]
    assert abs(top.max() - (line(d) + half(d)).max()) < 1e-6 * top.max()
    assert abs(top.min() - (line(d) - half(d)).min()) < 1e-6 * top.max()
    (span,) = ax.patches
    left, right = span.get_x(), span.get_x() + span.get_width()
    assert abs(left - date2num(day(grid[earliest]))) < 1e-9
    assert abs(right - date2num(day(grid[latest]))) < 1e-9
    assert to_hex(span.get_facecolor()) == RED
    marks = [ln for ln in ax.get_lines() if ln.get_linestyle() in (':', '--')
             and len(ln.get_xdata()) == 2]
    assert {(to_hex(ln.get_color()), ln.get_linestyle(), round(ln.get_xdata()[0], 9))
            for ln in marks} == {(RED, ':', round(date2num(day(grid[leaves])), 9)),
                                 (GREY, '--', round(date2num(day(52.0)), 9))}
    # The layout change's step, by hand: a_b - a_a and t sqrt(s^2 (e_b - e_a)' N^-1 (...)).
    e = np.array([-1.0, 1.0, 0.0])
    step, width = x[1] - x[0], t * math.sqrt(s2 * e @ inverse @ e)
    (note,) = ax.texts
    assert note.get_text() == f'layout change: {step:+,.0f} +- {width:,.0f} g mm'
    assert note.xy == (date2num(day(52.0)), 0.97)


def test_a_stable_machines_chart_says_its_drift_and_projects_nothing(tmp_path):
    flat = 500.0 + NOISE
    trend = fit_machine('m', series(flat, np.full(len(DAYS), 1200.0)))
    figure = machine_chart(trend, tmp_path / 'm.png')
    (ax,) = figure.axes
    assert figure._suptitle.get_text() == \
        'm: NO SIGNIFICANT DRIFT   (layout gantry b, G 6.3, 12 runs)'
    assert ax.get_title(loc='left') == 'plane I: NO SIGNIFICANT DRIFT'
    design = np.column_stack([~AFTER, AFTER, DAYS]).astype(float)
    x, *_ = np.linalg.lstsq(design, flat, rcond=None)
    labels = [ln.get_label() for ln in ax.get_lines()]
    (drift,) = [text for text in labels if text.startswith('drift ')]
    assert drift.startswith(f'drift {x[2]:+.0f} +- ')
    assert len(ax.patches) == 0 and ax.texts[0].get_text().startswith('layout change: ')
    share = [ln for ln in ax.get_lines() if ln.get_label() == 'permissible (G 6.3)'][0]
    assert abs(to_days(share.get_xdata()[-1]) - 112) < 1e-9


def test_the_fleet_chart_ranks_the_machines_to_their_dates(tmp_path):
    """Out of grade at the left in red, then a bar to each date, then the rest, in order."""
    x, s2, inverse, t, line, half = by_hand()
    grid = DAYS[-1] + np.arange(3651)
    leaves, earliest, latest = (first(line(grid)), first(line(grid) + half(grid)),
                                first(line(grid) - half(grid)))
    out = fit_machine('out', series(AMOUNTS + 1000.0))
    leaving = fit_machine('leaving', series())
    calm = fit_machine('calm', series(500.0 + NOISE, np.full(len(DAYS), 1200.0)))
    figure = _last_figure(tmp_path / 'fleet.png', [out, leaving, calm])
    assert (tmp_path / 'fleet.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    (ax,) = figure.axes
    assert [t.get_text() for t in ax.get_yticklabels()] == ['out', 'leaving', 'calm']
    assert ax.yaxis_inverted()
    assert ax.get_xlabel() == 'days from the last run to leaving the grade (95 % interval)'
    assert ax.get_title(loc='left') == 'machines by urgency'
    bars = ax.patches
    assert [round(b.get_width(), 9) for b in bars] == [0.0, float(grid[leaves] - DAYS[-1])]
    assert [to_hex(b.get_facecolor()[:3]) for b in bars] == [RED, BLUE]
    fraction = (line(DAYS[-1]) + 1000.0) / 1300.0      # the same fit, 1000 g mm higher
    texts = [t.get_text() for t in ax.texts]
    assert texts == [f' out of grade now (plane I: {fraction:.2f} of its share)',
                     f' {day(grid[leaves]):%Y-%m-%d} (plane I)', ' NO SIGNIFICANT DRIFT']
    (interval,) = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 2]
    assert np.allclose(interval.get_xdata(), [grid[earliest] - DAYS[-1],
                                              grid[latest] - DAYS[-1]], rtol=0, atol=1e-6)
    assert list(interval.get_ydata()) == [1, 1]
    # At most ``most`` machines.
    two = _last_figure(tmp_path / 'two.png', [out, leaving, calm], most=2)
    assert [t.get_text() for t in two.axes[0].get_yticklabels()] == ['out', 'leaving']


def _last_figure(path, trends, **options):
    """Draw the fleet chart again and keep its Figure (fleet_chart returns none)."""
    from matplotlib.figure import Figure
    made = []
    real = Figure.savefig

    def keep(self, *args, **kwargs):
        made.append(self)
        return real(self, *args, **kwargs)
    Figure.savefig = keep
    try:
        fleet_chart(trends, path, **options)
    finally:
        Figure.savefig = real
    return made[-1]


def test_the_fleet_chart_of_a_date_with_no_latest_end(tmp_path):
    """A band that never comes down to the share: the bar twice as long, 'may never leave'."""
    trend = fit_machine('leaving', series())
    plane = trend.planes[0]
    plane.leaves_latest = None
    figure = _last_figure(tmp_path / 'f.png', [trend])
    (ax,) = figure.axes
    days = (plane.leaves.timestamp() * 1e9 - plane.times[-1]) / DAY_NS
    assert ax.texts[0].get_text() == f' {plane.leaves:%Y-%m-%d} (plane I; may never leave)'
    (interval,) = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 2]
    assert interval.get_xdata()[1] == pytest.approx(2 * days, rel=1e-12)
    figure = machine_chart(trend, tmp_path / 'm.png')
    (span,) = figure.axes[0].patches
    end = plane.leaves + timedelta(days=30)
    assert abs(span.get_x() + span.get_width() - date2num(end)) < 1e-9
    # The chart runs to 30 days past the date: the share's step and the projection.
    lines = {ln.get_label(): ln for ln in figure.axes[0].get_lines()}
    assert abs(to_days(lines['permissible (G 6.3)'].get_xdata()[-1])
               - (end - START).total_seconds() / 86400) < 1e-9
    # Two planes: a panel each; a machine without a plane: a row that says so.
    data = series()
    data['amount_II'], data['permissible_II'] = AMOUNTS / 2, SHARE
    data['ci95_II'], data['identified_II'] = CI95, MEASURED
    both = fit_machine('both', data)
    assert [p.plane for p in both.planes] == ['I', 'II']
    assert len(machine_chart(both, tmp_path / 'b.png').axes) == 2
    empty = fit_machine('none', series(np.full(len(DAYS), np.nan)))
    figure = _last_figure(tmp_path / 'e.png', [empty])
    assert [t.get_text() for t in figure.axes[0].texts] == [' TOO FEW RUNS']


def test_the_legend_names_each_mark_and_the_layouts_runs_are_drawn_where_they_are(tmp_path):
    """The legend's words; hollow dots at the layout's runs' days, none when all measured."""
    x, s2, inverse, t, line, half = by_hand()
    figure = machine_chart(fit_machine('m', series()), tmp_path / 'm.png')
    (ax,) = figure.axes
    label = f'drift {x[2]:+.0f} +- {t * math.sqrt(s2 * inverse[2, 2]):.0f} g mm/day'
    assert sorted(text.get_text() for text in ax.get_legend().get_texts()) == sorted([
        'identified (load cells), 95 %', "layout's", 'permissible (G 6.3)', label])
    (hollow,) = [ln for ln in ax.get_lines() if ln.get_label() == "layout's"]
    assert np.allclose([to_days(v) for v in hollow.get_xdata()], DAYS[~MEASURED], atol=1e-9)
    assert hollow.get_marker() == 'o' and hollow.get_linestyle() == 'None'
    assert to_hex(hollow.get_color()) == BLUE
    every = series()
    every['identified_I'] = np.ones(len(DAYS), bool)
    every['ci95_I'] = np.full(len(DAYS), 20.0)
    figure = machine_chart(fit_machine('m', every), tmp_path / 'all.png')
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert "layout's" not in labels and 'identified (load cells), 95 %' in labels
    assert not [ln for ln in figure.axes[0].get_lines() if ln.get_label() == "layout's"]


def test_the_fleet_chart_shows_the_30_most_urgent_by_default(tmp_path):
    from dataclasses import replace
    calm = fit_machine('calm', series(500.0 + NOISE, np.full(len(DAYS), 1200.0)))
    trends = [replace(calm, machine_id=f'm{k:02d}') for k in range(31)]
    figure = _last_figure(tmp_path / 'fleet.png', trends)
    assert [t.get_text() for t in figure.axes[0].get_yticklabels()] == \
        [f'm{k:02d}' for k in range(30)]


def test_a_layout_change_a_plane_cannot_fit_is_drawn_without_a_step(tmp_path):
    """A plane of two runs (too few for a drift): the change's line, and no step said."""
    data = series()
    data['amount_II'] = np.where(np.isin(DAYS, (0.0, 101.0)), 400.0, np.nan)
    data['permissible_II'] = SHARE
    trend = fit_machine('m', data)
    assert [p.plane for p in trend.planes] == ['I', 'II']
    assert not np.isfinite(trend.changes[0].steps['II'][0])          # the premise
    first, second = machine_chart(trend, tmp_path / 'm.png').axes
    assert [t.get_text()[:15] for t in first.texts] == ['layout change: ']
    assert len(second.texts) == 0
    (change,) = [ln for ln in second.get_lines() if ln.get_linestyle() == '--']
    assert abs(change.get_xdata()[0] - date2num(day(52.0))) < 1e-9


def test_a_machine_without_a_plane_gets_its_chart_saying_so(tmp_path):
    """No plane in any run (``cvc-balance fleet`` draws every machine): one panel, in words."""
    empty = fit_machine('none', series(np.full(len(DAYS), np.nan)))
    assert empty.planes == []                                   # the premise
    figure = machine_chart(empty, tmp_path / 'none.png')
    assert (tmp_path / 'none.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert figure._suptitle.get_text() == 'none: TOO FEW RUNS   (layout gantry b, G 6.3, ' \
        '12 runs)'
    (ax,) = figure.axes
    assert [t.get_text() for t in ax.texts] == ['no correction plane to chart: its runs gave '
                                                'no plane unbalance']


def test_the_fleet_chart_keeps_its_last_row_inside_its_axes(tmp_path):
    """Rows 0 .. n-1 from the top, each half a row from the edges (a row without a bar too)."""
    leaving = fit_machine('leaving', series())
    calm = fit_machine('calm', series(500.0 + NOISE, np.full(len(DAYS), 1200.0)))
    figure = _last_figure(tmp_path / 'fleet.png', [leaving, calm, calm])
    (ax,) = figure.axes
    assert ax.get_ylim() == (2.5, -0.5)         # the last row's words not on the axis' edge
    assert [t.get_position()[1] for t in ax.texts] == [0, 1, 2]
    # One machine: one row, 8 x (0.28 + 1.4) inches.
    one = _last_figure(tmp_path / 'one.png', [leaving])
    assert one.axes[0].get_ylim() == (0.5, -0.5)
    assert np.allclose(one.get_size_inches(), (8.0, 1.68), rtol=0, atol=1e-12)
