"""
Trends per machine: each correction plane's unbalance over time, its drift, when it leaves.

Read with DuckDB straight from the results table (only the columns needed, only the
machine asked for): per run and layout segment the plane's unbalance, the one the load
cells identified where they can tell (the verdict of record is the measured rotor's), else
the layout's, and the
plane's permissible share of the grade at the service speed.

The model per machine and plane, fitted by least squares:

    U(t) = a_e + b t

one level a_e per **layout epoch** (runs in a row with the same layout digest: a tube
swap, a change of counterweights starts a new one) and one **drift** b (g mm/day) common
to all, so a step at a layout change is not taken for drift and a drift goes on across
it. The 95 % interval of b is Student's t with n - epochs - 1 degrees of freedom (the
residual scatter, noise and all, estimated from the runs themselves). **Leaving the
grade**: the date the fitted line of the latest epoch reaches the plane's permissible
share, and its interval: the dates where the line's 95 % confidence band reaches it
(the earliest by the upper band, the latest by the lower; none when that band never
does within :data:`HORIZON_DAYS`). A drift whose interval holds 0 projects nothing.
**Steps**: a_new - a_old at each layout change, with its interval: the change that made
a plane worse. **Urgency**: machines out of their grade now first (worst first), then by
the earliest projected date, then the rest by how near their limit they are.

**Bearing life** (where the layouts describe the bearings): per machine and support the
life used summed over the runs (Palmgren-Miner: a fraction of the rating life, measured
where the verdict of record is the measured rotor's), the running hours, the **current
duty** (the life used per running hour, and per calendar day, over the runs of the latest
layout epoch), the running hours left at that duty and the date the bearing reaches its
rating life at it (within :data:`HORIZON_DAYS`). :func:`life_ranked` ranks the machines by
the bearing with the fewest hours left.
"""

from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
import math

import numpy as np

from cvc_balance.fleet.rows import PLANES

DAY_NS = 86_400 * 10**9
HORIZON_DAYS = 3650
"""How far ahead a crossing of the grade is looked for (days)."""
OUT, LEAVES, STABLE, FEW = 'OUT OF GRADE', 'LEAVES GRADE', 'NO SIGNIFICANT DRIFT', \
    'TOO FEW RUNS'


@dataclass
class PlaneTrend:
    """One plane of one machine: its series, the fit and the projection (g mm, days)."""

    plane: str
    times: np.ndarray           # ns since the epoch, per run segment
    amount: np.ndarray          # g mm
    ci95: np.ndarray            # g mm (nan where not identified)
    permissible: np.ndarray     # g mm, the plane's share of the grade at each run
    epoch: np.ndarray           # layout epoch index of each run (among this plane's)
    identified: np.ndarray      # bool: from the load cells (else the layout's)
    epoch_ids: np.ndarray = None  # the machine's epoch number of each of those
    drift: float = math.nan     # g mm/day
    drift_ci95: float = math.nan
    levels: list = None         # a_e per epoch, g mm at day 0
    covariance: np.ndarray = None
    t_quantile: float = math.nan
    origin_ns: int = 0          # day 0 of the fit
    now_fraction: float = math.nan   # the fitted level at the last run over the limit
    status: str = FEW
    leaves: datetime = None
    leaves_earliest: datetime = None
    leaves_latest: datetime = None  # None: the band never reaches the limit (or no drift)

    def line(self, times_ns, epoch=None):
        """Return the fitted U (g mm) at ``times_ns`` in ``epoch`` (default the latest)."""
        epoch = self.epoch[-1] if epoch is None else epoch
        days = (np.asarray(times_ns, dtype=float) - self.origin_ns) / DAY_NS
        return self.levels[epoch] + self.drift * days

    def band(self, times_ns, epoch=None):
        """Return the 95 % half-width (g mm) of the fitted line at ``times_ns``."""
        epoch = self.epoch[-1] if epoch is None else epoch
        days = (np.asarray(times_ns, dtype=float) - self.origin_ns) / DAY_NS
        c = self.covariance
        variance = c[epoch, epoch] + 2 * c[epoch, -1] * days + c[-1, -1] * days * days
        return self.t_quantile * np.sqrt(np.maximum(variance, 0.0))


@dataclass
class LayoutChange:
    """A change of layout on a machine and what it did to each plane (g mm, 95 %)."""

    when: datetime
    before: str                 # layout digests
    after: str
    steps: dict = field(default_factory=dict)   # plane: (step g mm, ci95 g mm)


@dataclass
class MachineTrend:
    """One machine: its planes' trends, its layout changes, its urgency."""

    machine_id: str
    runs: int
    first: datetime
    last: datetime
    layout: str                 # name of the latest layout
    grade: float
    planes: list
    changes: list
    status: str = FEW
    worst_plane: str = None
    leaves: datetime = None
    urgency: tuple = ()
    bearings: list = field(default_factory=list)    # BearingTrend per described bearing

    @property
    def worst_bearing(self):
        """Return the BearingTrend with the fewest running hours left (None: none)."""
        known = [b for b in self.bearings if b.left_hours is not None]
        if known:
            return min(known, key=lambda b: b.left_hours)
        return max(self.bearings, key=lambda b: b.life_used, default=None)


@dataclass
class BearingTrend:
    """
    One bearing of one machine over its runs (life used: fractions of its rating life).

    ``duty_per_hour``: life used per running hour, ``duty_per_day`` per calendar day, both
    over the latest layout epoch's runs (None: not told: no running time, one run);
    ``left_hours``: running hours left at that duty; ``worn_out``: when the bearing reaches
    its rating life at the per-day duty (None: not within HORIZON_DAYS, or not told).
    """

    support: str
    runs: int
    measured_runs: int
    life_used: float
    hours: float
    duty_per_hour: float = None
    duty_per_day: float = None
    left_hours: float = None
    worn_out: datetime = None


def read_series(results, machine=None):
    """
    Return {machine: columns (dict of numpy arrays)} of the results table, by time.

    DuckDB reads the Parquet file itself: only these columns, only ``machine`` if given.
    Segments without samples or without a verdict (no service speed) are left out.
    """
    import duckdb
    columns = ['machine_id', 'epoch_ns(segment_start) AS t', 'layout_digest', 'layout_name',
               'grade']
    for p in PLANES:
        # The measured plane where the verdict of record is the cells' (they can tell).
        measured = "verdict_source = 'measured'"
        columns += [f'plane_{p}_permissible_g_mm AS permissible_{p}',
                    f'CASE WHEN {measured} THEN identified_plane_{p}_g_mm '
                    f'ELSE plane_{p}_g_mm END AS amount_{p}',
                    f'CASE WHEN {measured} THEN identified_plane_{p}_g_mm_ci95 END AS ci95_{p}',
                    f'coalesce({measured}, false) AS identified_{p}']
    # A run analysed again (its bag changed: a new digest) counts once: the latest.
    query = (f"SELECT {', '.join(columns)} FROM read_parquet(?) "
             'WHERE segment_samples > 0 AND plane_I_permissible_g_mm IS NOT NULL '
             'AND segment_start IS NOT NULL'
             + (' AND machine_id = ?' if machine is not None else '')
             + ' QUALIFY row_number() OVER (PARTITION BY machine_id, segment_start, '
             'layout_digest ORDER BY analysed_at DESC) = 1'
             + ' ORDER BY machine_id, t, layout_digest')
    connection = duckdb.connect()
    try:
        parameters = [str(results)] + ([machine] if machine is not None else [])
        found = connection.execute(query, parameters).fetchnumpy()
    finally:
        connection.close()
    machines = found['machine_id']
    out = {}
    if not len(machines):
        return out
    names = np.asarray(machines, dtype=object)
    edges = np.flatnonzero(names[1:] != names[:-1]) + 1
    for part in np.split(np.arange(len(names)), edges):
        out[str(names[part[0]])] = {key: np.asarray(_filled(value))[part]
                                    for key, value in found.items() if key != 'machine_id'}
    return out


def _filled(values):
    """Return a masked array's values, nan (numbers), False (flags), None (text) where masked."""
    if isinstance(values, np.ma.MaskedArray):
        if values.dtype.kind == 'f':
            return values.filled(np.nan)
        if values.dtype.kind == 'b':
            return values.filled(False)
        if values.dtype.kind == 'O':      # filled(None) would fill with numpy's default, '?'
            return np.where(np.ma.getmaskarray(values), None, values.data)
        return values.data
    return values


def machine_trends(results, machine=None, now=None):
    """
    Return [MachineTrend] of the results table, ranked by urgency (most urgent first).

    ``machine``: only that one; ``now`` (datetime, UTC): the date projections start
    from (default each machine's last run).
    """
    trends = [fit_machine(name, series, now) for name, series in
              read_series(results, machine).items()]
    life = read_life(results, machine)
    for trend in trends:
        trend.bearings = bearing_trends(life.get(trend.machine_id, {}))
    return sorted(trends, key=lambda trend: trend.urgency)


def life_ranked(trends):
    """Return ``trends`` ranked by bearing life: the fewest running hours left first."""
    def key(trend):
        worst = trend.worst_bearing
        if worst is None:
            return (2, 0.0, trend.machine_id)
        if worst.left_hours is None:
            return (1, -worst.life_used, trend.machine_id)
        return (0, worst.left_hours, trend.machine_id)
    return sorted(trends, key=key)


def read_life(results, machine=None):
    """
    Return {machine: {support: columns (dict of numpy arrays)}} of the bearings, by time.

    DuckDB reads the table's ``bearings`` lists (one row per run segment and bearing),
    each run counted once as :func:`read_series` does.
    """
    import duckdb
    query = ('WITH runs AS (SELECT machine_id, segment_start, layout_digest, running_hours, '
             'bearings FROM read_parquet(?) WHERE segment_samples > 0 AND segment_start IS '
             'NOT NULL AND bearings IS NOT NULL'
             + (' AND machine_id = ?' if machine is not None else '')
             + ' QUALIFY row_number() OVER (PARTITION BY machine_id, segment_start, '
             'layout_digest ORDER BY analysed_at DESC) = 1), '
             'used AS (SELECT machine_id, segment_start, layout_digest, running_hours, '
             'unnest(bearings) AS b FROM runs) '
             'SELECT machine_id, b.support AS support, epoch_ns(segment_start) AS t, '
             'layout_digest, running_hours AS hours, b.life_used AS life_used, '
             "b.source = 'measured' AS measured FROM used "
             'ORDER BY machine_id, support, t, layout_digest')
    connection = duckdb.connect()
    try:
        parameters = [str(results)] + ([machine] if machine is not None else [])
        found = connection.execute(query, parameters).fetchnumpy()
    finally:
        connection.close()
    out = {}
    keys = list(zip(np.asarray(found['machine_id'], dtype=object),
                    np.asarray(found['support'], dtype=object)))
    for k, (name, support) in enumerate(keys):
        rows = out.setdefault(str(name), {}).setdefault(str(support), [])
        rows.append(k)
    columns = {key: np.asarray(_filled(value)) for key, value in found.items()
               if key not in ('machine_id', 'support')}
    return {name: {support: {key: value[rows] for key, value in columns.items()}
                   for support, rows in supports.items()}
            for name, supports in out.items()}


def bearing_trends(supports):
    """Return [BearingTrend] of one machine's bearings ({support: columns})."""
    trends = []
    for support, series in supports.items():
        used = np.nan_to_num(series['life_used'].astype(float))
        hours = np.nan_to_num(series['hours'].astype(float))
        times = series['t'].astype(np.int64)
        digests = series['layout_digest']
        latest = np.ones(len(times), dtype=bool)
        changes = np.flatnonzero(digests[1:] != digests[:-1]) + 1
        if len(changes):
            latest[:changes[-1]] = False
        trend = BearingTrend(str(support), len(times), int(series['measured'].sum()),
                             float(used.sum()), float(hours.sum()))
        recent_used, recent_hours = float(used[latest].sum()), float(hours[latest].sum())
        if recent_hours > 0.0 and recent_used > 0.0:
            trend.duty_per_hour = recent_used / recent_hours
            trend.left_hours = max(1.0 - trend.life_used, 0.0) / trend.duty_per_hour
        span = (times[latest][-1] - times[latest][0]) / DAY_NS
        if latest.sum() > 1 and span > 0.0 and recent_used > 0.0:
            # Each run's life over the days from the first run of the epoch to the last.
            trend.duty_per_day = float(used[latest][1:].sum()) / span
            days = max(1.0 - trend.life_used, 0.0) / trend.duty_per_day \
                if trend.duty_per_day > 0.0 else math.inf
            if days <= HORIZON_DAYS:
                trend.worn_out = _date(times[-1] + days * DAY_NS)
        trends.append(trend)
    return trends


def fit_machine(name, series, now=None):
    """Fit every plane of one machine's series (see the module's description)."""
    times = series['t'].astype(np.int64)
    digests = series['layout_digest']
    epoch = np.concatenate([[0], np.cumsum(digests[1:] != digests[:-1])]).astype(int)
    planes = []
    for p in PLANES:
        amount = series[f'amount_{p}'].astype(float)
        keep = np.isfinite(amount)
        if not keep.any():
            continue
        trend = PlaneTrend(p, times[keep], amount[keep], series[f'ci95_{p}'][keep],
                           series[f'permissible_{p}'][keep].astype(float), epoch[keep],
                           series[f'identified_{p}'][keep].astype(bool))
        _fit(trend, now)
        planes.append(trend)
    changes = []
    for k in np.flatnonzero(np.diff(epoch)) + 1:
        change = LayoutChange(_date(times[k]), str(digests[k - 1]), str(digests[k]))
        for trend in planes:
            change.steps[trend.plane] = _step(trend, epoch[k - 1], epoch[k])
        changes.append(change)
    result = MachineTrend(name, len(times), _date(times[0]), _date(times[-1]),
                          str(series['layout_name'][-1]), float(series['grade'][-1]),
                          planes, changes)
    _urgency(result)
    return result


def _fit(trend, now):
    # Epochs renumbered to those this plane has (a plane may miss runs).
    trend.epoch_ids, trend.epoch = np.unique(trend.epoch, return_inverse=True)
    epochs = len(trend.epoch_ids)
    n = len(trend.times)
    trend.origin_ns = int(trend.times[0])
    days = (trend.times - trend.origin_ns) / DAY_NS
    dof = n - epochs - 1
    if dof < 1 or np.ptp(days) <= 0:
        trend.status = FEW
        trend.now_fraction = float(trend.amount[-1] / trend.permissible[-1])
        return
    design = np.zeros((n, epochs + 1))
    design[np.arange(n), trend.epoch] = 1.0
    design[:, -1] = days
    coefficients, *_ = np.linalg.lstsq(design, trend.amount, rcond=None)
    residual = trend.amount - design @ coefficients
    variance = float(residual @ residual) / dof
    unscaled = np.linalg.pinv(design.T @ design)
    trend.covariance = variance * unscaled
    from scipy import stats       # here: scipy.stats costs every command ~1 s to import
    trend.t_quantile = float(stats.t.ppf(0.975, dof))
    trend.levels = list(coefficients[:-1])
    trend.drift = float(coefficients[-1])
    trend.drift_ci95 = trend.t_quantile * math.sqrt(max(trend.covariance[-1, -1], 0.0))
    start = int(trend.times[-1]) if now is None else int(now.timestamp() * 1e9)
    limit = float(trend.permissible[-1])
    level = float(trend.line([start])[0])
    trend.now_fraction = level / limit
    if level > limit:
        trend.status = OUT
        return
    if not trend.drift - trend.drift_ci95 > 0.0:
        trend.status = STABLE
        return
    trend.status = LEAVES
    grid = start + np.arange(HORIZON_DAYS + 1) * DAY_NS
    line, half = trend.line(grid), trend.band(grid)
    trend.leaves = _crossing(grid, line, limit)
    trend.leaves_earliest = _crossing(grid, line + half, limit)
    trend.leaves_latest = _crossing(grid, line - half, limit)
    if trend.leaves is None:          # a drift too slow to matter within the horizon
        trend.status = STABLE


def _crossing(grid, values, limit):
    """Return the first date of ``grid`` where ``values`` reach ``limit`` (None: never)."""
    above = np.flatnonzero(values >= limit)
    return _date(grid[above[0]]) if len(above) else None


def _step(trend, before, after):
    """(a_after - a_before, its 95 % half-width) in g mm; nan when not fitted."""
    if trend.levels is None:
        return math.nan, math.nan
    present = [int(e) for e in trend.epoch_ids]
    if before not in present or after not in present:
        return math.nan, math.nan
    before, after = present.index(before), present.index(after)
    c = trend.covariance
    step = trend.levels[after] - trend.levels[before]
    spread = c[after, after] + c[before, before] - 2 * c[after, before]
    return float(step), trend.t_quantile * math.sqrt(max(spread, 0.0))


def _urgency(machine):
    """Set the machine's status, worst plane, projected date and ranking key."""
    if not machine.planes:
        machine.urgency = (3, 0.0, machine.machine_id)
        return
    worst = max(machine.planes, key=lambda t: t.now_fraction)
    out = [t for t in machine.planes if t.status == OUT]
    leaving = [t for t in machine.planes if t.status == LEAVES and t.leaves is not None]
    if out:
        worst = max(out, key=lambda t: t.now_fraction)
        machine.status, machine.urgency = OUT, (0, -worst.now_fraction, machine.machine_id)
    elif leaving:
        worst = min(leaving, key=lambda t: t.leaves)
        machine.status, machine.leaves = LEAVES, worst.leaves
        machine.urgency = (1, worst.leaves.timestamp(), machine.machine_id)
    else:
        machine.status = STABLE if any(t.status != FEW for t in machine.planes) else FEW
        machine.urgency = (2, -worst.now_fraction, machine.machine_id)
    machine.worst_plane = worst.plane


def _date(ns):
    return datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=int(ns) // 1000)


def trend_summary(machine):
    """Return a MachineTrend as JSON-able data (dates ISO 8601 UTC; g mm, g mm/day)."""
    def iso(when):
        return when.isoformat().replace('+00:00', 'Z') if when is not None else None

    def number(value):
        return float(value) if value is not None and math.isfinite(value) else None
    return {
        'machine_id': machine.machine_id, 'status': machine.status,
        'runs': machine.runs, 'first_run': iso(machine.first), 'last_run': iso(machine.last),
        'layout': machine.layout, 'grade': machine.grade, 'worst_plane': machine.worst_plane,
        'leaves_grade': iso(machine.leaves),
        'planes': [{
            'plane': t.plane, 'status': t.status, 'runs': len(t.times),
            'identified_runs': int(t.identified.sum()),
            'last_g_mm': float(t.amount[-1]), 'permissible_g_mm': float(t.permissible[-1]),
            'fraction_now': number(t.now_fraction),
            'drift_g_mm_per_day': number(t.drift), 'drift_ci95_g_mm_per_day':
            number(t.drift_ci95),
            'leaves_grade': iso(t.leaves), 'leaves_grade_earliest': iso(t.leaves_earliest),
            'leaves_grade_latest': iso(t.leaves_latest)} for t in machine.planes],
        'layout_changes': [{
            'at': iso(c.when), 'from_digest': c.before, 'to_digest': c.after,
            'steps': {p: {'g_mm': number(s), 'ci95_g_mm': number(h)}
                      for p, (s, h) in c.steps.items()}} for c in machine.changes],
        'bearings': [{
            'support': b.support, 'runs': b.runs, 'measured_runs': b.measured_runs,
            'life_used': b.life_used, 'running_hours': b.hours,
            'life_per_running_hour': number(b.duty_per_hour),
            'life_per_day': number(b.duty_per_day), 'hours_left': number(b.left_hours),
            'rating_life_reached': iso(b.worn_out)} for b in machine.bearings],
    }
