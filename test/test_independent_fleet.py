"""
The fleet's rows against what each simulated run really was, not against the same analysis.

A small simulated fleet (6 machines x 4 runs: every history, files and rosbag2 directories)
through ``run_fleet`` in this process. Each row is checked against the simulation's plan
of its bag (:func:`cvc_balance.fleet.simulate_fleet` returns the declared layout and the
true components of every run) worked out here by hand: the two-plane split of point masses
(ISO 21940-2: U_I = sum U_i (z_II - z_i) / b, U_II = sum U_i (z_i - z_I) / b; every body of
config/ct_gantry.yaml has its own axes radial, tangential and axial, so no own products xz,
yz), ISO 21940-11's permissible shares (U_per = G m / Omega, each plane's share the lever
of the other about the centre of mass, kept within 0.3-0.7) and the grade they imply; the
counts, times and speeds against the bag's messages read by rosbags.
"""

import cmath
from datetime import datetime, timedelta, timezone
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from rosbags.highlevel import AnyReader
import yaml

from cvc_balance.fleet import run_fleet, simulate_fleet
from reference import component_planes_by_hand, shares_by_hand

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / 'config' / 'ct_gantry.yaml'
MACHINES, RUNS = 6, 4
CHI2_95 = 5.991464547107979


def vector(row, prefix, angle=None):
    """Return the row's vector ``prefix`` (g mm, its angle in degrees) as complex kg m."""
    degrees = row[angle or f'{prefix}_angle_deg']
    return row[prefix] * 1e-6 * cmath.exp(1j * math.radians(degrees))


def messages(bag):
    """Read a bag with rosbags: joint states (log ns, velocity), cell count, layout times."""
    joints, cells, layouts = [], 0, []
    with AnyReader([Path(bag)]) as reader:
        for connection, log_time, raw in reader.messages():
            if connection.topic == '/joint_states':
                msg = reader.deserialize(raw, connection.msgtype)
                joints.append((log_time, float(msg.velocity[0])))
            elif connection.topic.endswith('/measured_load'):
                cells += 1
            elif connection.topic == '/layout':
                layouts.append(log_time)
    return joints, cells, layouts


@pytest.fixture(scope='module')
def fleet(tmp_path_factory):
    base = tmp_path_factory.mktemp('independent_fleet')
    plans = simulate_fleet(LAYOUT, base / 'runs', machines=MACHINES, runs=RUNS, days=120.0,
                           seed=29)
    report = run_fleet([base / 'runs'], base / 'fleet.parquet', engine='local', progress=False)
    rows = pq.read_table(base / 'fleet.parquet').to_pylist()
    return plans, report, {row['bag']: row for row in rows}


def test_a_row_per_run_with_its_machine_date_and_counts(fleet):
    plans, report, rows = fleet
    runs = {str(run.path): (plan, run) for plan in plans for run in plan.runs}
    assert (report.found, report.analysed, report.failed) == (MACHINES * RUNS,) * 2 + (0,)
    assert set(rows) == set(runs)
    assert any(Path(bag).is_dir() for bag in rows)            # rosbag2 directories too
    for bag, row in rows.items():
        plan, run = runs[bag]
        joints, cells, layouts = messages(bag)
        before_layout = sum(1 for log_time, _ in joints if log_time < min(layouts))
        assert (row['machine_id'], row['machine_source']) == (plan.machine_id, 'bag')
        assert abs(row['run_start'].timestamp() - run.when.timestamp()) < 1e-6
        assert (row['samples'], row['rejected'], row['dropped'], row['skipped']) == \
            (len(joints), 0, before_layout, 0)
        assert row['accepted'] == row['segment_samples'] == len(joints) - before_layout
        assert row['top_speed'] == max(abs(w) for _, w in joints)
        # Every cell reading lies inside the motion's span: all are used.
        assert row['identified_readings'] == cells
        assert row['problems'] == [] and row['layout_name'] == run.declared['name']


def test_the_layout_digest_changes_exactly_when_the_declared_layout_does(fleet):
    plans, _, rows = fleet
    for plan in plans:
        declared = [yaml.safe_dump(run.declared, sort_keys=True) for run in plan.runs]
        digests = [rows[str(run.path)]['layout_digest'] for run in plan.runs]
        for a in range(RUNS):
            for b in range(RUNS):
                assert (digests[a] == digests[b]) == (declared[a] == declared[b]), plan.kind
        assert (len(set(digests)) == 2) == (plan.swap is not None)


def test_the_layouts_planes_shares_and_grade_by_hand(fleet):
    plans, _, rows = fleet
    for plan in plans:
        for run in plan.runs:
            row = rows[str(run.path)]
            layout = run.declared
            planes = component_planes_by_hand(layout['components'], layout['balancing']['planes'])
            shares = shares_by_hand(layout)
            for p, u, share in zip(('I', 'II'), planes, shares):
                # Measured: 1.1e-13 relative (the engine sums compensated, these plainly).
                assert abs(vector(row, f'plane_{p}_g_mm', f'plane_{p}_angle_deg') - u) \
                    <= 1e-12 * abs(u), p
                assert row[f'plane_{p}_permissible_g_mm'] == pytest.approx(share * 1e6,
                                                                           rel=1e-12)
            grade = 6.3 * max(abs(u) / s for u, s in zip(planes, shares))
            assert row['layout_equivalent_grade'] == pytest.approx(grade, rel=1e-12)   # 5.8e-14
            assert row['layout_level'] == ('OK' if grade <= 0.8 * 6.3 else 'WARN'
                                           if grade <= 6.3 else 'ERROR')


def test_the_identified_rotor_is_the_true_one_within_its_circles(fleet):
    """
    Each run's identified planes against the true rotor's by hand, and the residual.

    Each within twice its 95 % radius (the 99.9999 % circle; measured at most 1.13 of
    it), 90 % within the radius itself (measured 45 of 48); the verdict of record the
    measured rotor's, its grade from the identified planes by hand (5.8e-14) and within the
    noise of the true rotor's grade (measured 0.24 mm/s off).
    """
    plans, _, rows = fleet
    inside = checked = 0
    for plan in plans:
        for run in plan.runs:
            row = rows[str(run.path)]
            layout = run.declared
            planes = layout['balancing']['planes']
            true = component_planes_by_hand(run.true_components, planes)
            declared = component_planes_by_hand(layout['components'], planes)
            shares = shares_by_hand(layout)
            assert row['identifiable'] and row['verdict_source'] == 'measured'
            found = []
            for k, p in enumerate(('I', 'II')):
                got = vector(row, f'identified_plane_{p}_g_mm')
                ci95 = row[f'identified_plane_{p}_g_mm_ci95'] * 1e-6
                off = vector(row, f'residual_plane_{p}_g_mm')
                assert abs(got - true[k]) <= 2 * ci95, (plan.machine_id, p, got, true[k])
                assert abs(off - (got - declared[k])) <= 1e-12 * (abs(got) + abs(declared[k]))
                assert ci95 <= 0.25 * shares[k]               # why the cells can tell
                inside += abs(got - true[k]) <= ci95
                checked += 1
                found.append(abs(got))
            grade = 6.3 * max(u / s for u, s in zip(found, shares))
            assert row['equivalent_grade'] == pytest.approx(grade, rel=1e-12)
            true_grade = 6.3 * max(abs(u) / s for u, s in zip(true, shares))
            noise = 6.3 * max(2 * row[f'identified_plane_{p}_g_mm_ci95'] * 1e-6 / s
                              for p, s in zip(('I', 'II'), shares))
            assert abs(row['equivalent_grade'] - true_grade) <= noise
    assert inside >= 0.9 * checked, (inside, checked)


def test_the_residual_is_what_the_layout_misses(fleet):
    """
    The residual (measured - layout) against the true - declared rotor, by hand.

    The steady machines' residual is their as-built mass; a slipping counterweight's grows
    with it. Each within twice its 95 % radius.
    """
    plans, _, rows = fleet
    for plan in plans:
        for run in plan.runs:
            row = rows[str(run.path)]
            planes = run.declared['balancing']['planes']
            true = component_planes_by_hand(run.true_components, planes)
            declared = component_planes_by_hand(run.declared['components'], planes)
            missed = [t - d for t, d in zip(true, declared)]
            if plan.kind == 'steady':
                as_built = component_planes_by_hand([plan.as_built], planes)
                assert np.allclose(missed, as_built, rtol=0, atol=1e-15)
            for k, p in enumerate(('I', 'II')):
                off = vector(row, f'residual_plane_{p}_g_mm')
                ci95 = row[f'residual_plane_{p}_g_mm_ci95'] * 1e-6
                assert abs(off - missed[k]) <= 2 * ci95, (plan.machine_id, p, off, missed[k])


# -- trends: the fitted line, its band and the date it leaves the grade, by hand ---------------

DAY_NS = 86_400 * 10**9
START_NS = 1_760_000_000 * 10**9


def series(days, amounts, digests=None, permissible=1000.0, measured=None):
    """Return one machine's series as read_series gives it (plane II absent)."""
    n = len(days)
    digests = ['d1'] * n if digests is None else digests
    measured = np.zeros(n, bool) if measured is None else np.asarray(measured)
    return {'t': (START_NS + np.asarray(days, float) * DAY_NS).astype(np.int64),
            'layout_digest': np.array(digests, dtype=object),
            'layout_name': np.array(['gantry'] * n, dtype=object), 'grade': np.full(n, 6.3),
            'amount_I': np.asarray(amounts, float),
            'ci95_I': np.where(measured, 30.0, np.nan),
            'permissible_I': np.full(n, permissible), 'identified_I': measured,
            'amount_II': np.full(n, np.nan), 'ci95_II': np.full(n, np.nan),
            'permissible_II': np.full(n, permissible), 'identified_II': np.zeros(n, bool)}


def first_day(values, limit):
    """Index of the first value >= limit, None if none."""
    above = [k for k, v in enumerate(values) if v >= limit]
    return above[0] if above else None


def test_a_drifting_plane_its_drift_band_and_the_day_it_leaves_by_hand():
    """
    One layout, a plane drifting ~4 g mm/day: the textbook straight line by hand.

    b = S_td / S_tt, a = mean(U) - b mean(t), s^2 = sum r^2 / (n - 2), the drift's 95 %
    half-width t_{0.975, n-2} s / sqrt(S_tt), the line's t s sqrt(1/n + (d - mean t)^2 /
    S_tt); the day it reaches the permissible share (1000 g mm) counted on whole days from
    the last run, and the band's days likewise.
    """
    from scipy import stats
    from cvc_balance.fleet.trends import fit_machine, LEAVES
    days = np.array([0.0, 11.0, 19.0, 33.0, 40.0, 52.0, 61.0, 75.0])
    noise = np.array([9.0, -14.0, 6.0, 11.0, -17.0, 3.0, 8.0, -6.0])
    amounts = 300.0 + 4.0 * days + noise
    machine = fit_machine('m', series(days, amounts))
    (plane,) = machine.planes
    n, mean_t = len(days), days.mean()
    s_tt = np.sum((days - mean_t) ** 2)
    b = np.sum((days - mean_t) * (amounts - amounts.mean())) / s_tt
    a = amounts.mean() - b * mean_t
    s2 = np.sum((amounts - a - b * days) ** 2) / (n - 2)
    t = stats.t.ppf(0.975, n - 2)
    assert plane.drift == pytest.approx(b, rel=1e-12)
    assert plane.drift_ci95 == pytest.approx(t * math.sqrt(s2 / s_tt), rel=1e-12)
    assert plane.levels[0] == pytest.approx(a, rel=1e-12)
    assert plane.now_fraction == pytest.approx((a + b * days[-1]) / 1000.0, rel=1e-12)
    grid = days[-1] + np.arange(3651)
    line = a + b * grid
    half = t * np.sqrt(s2 * (1 / n + (grid - mean_t) ** 2 / s_tt))
    leaves, earliest, latest = (first_day(line, 1000.0), first_day(line + half, 1000.0),
                                first_day(line - half, 1000.0))
    assert plane.status == LEAVES and machine.status == LEAVES
    for got, want in ((plane.leaves, leaves), (plane.leaves_earliest, earliest),
                      (plane.leaves_latest, latest)):
        assert (got.timestamp() - START_NS / 1e9) / 86400.0 == grid[want], (got, want)
    assert earliest < leaves < latest
    assert plane.band([START_NS], 0)[0] == pytest.approx(
        t * math.sqrt(s2 * (1 / n + mean_t ** 2 / s_tt)), rel=1e-12)


def test_the_status_of_a_plane_out_stable_or_with_too_few_runs():
    """OUT OF GRADE above its share now; no significant drift; too few runs: by hand."""
    from cvc_balance.fleet.trends import fit_machine, FEW, OUT, STABLE
    days = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    flat = np.array([500.0, 520.0, 480.0, 510.0, 490.0])       # drift 0 within its band
    assert fit_machine('m', series(days, flat)).planes[0].status == STABLE
    over = fit_machine('m', series(days, flat + 600.0))        # 1100 of 1000 now
    assert over.planes[0].status == OUT and over.status == OUT
    assert over.planes[0].now_fraction == pytest.approx(
        (np.polyval(np.polyfit(days, flat + 600.0, 1), 40.0)) / 1000.0, rel=1e-12)
    few = fit_machine('m', series(days[:2], flat[:2]))          # n - 2 = 0 dof
    assert few.planes[0].status == FEW and few.status == FEW
    assert few.planes[0].now_fraction == flat[1] / 1000.0
    # Urgency: out of grade first, worst first; then by date; then the rest.
    ranked = sorted([fit_machine('a', series(days, flat)), over,
                     fit_machine('c', series(days, flat + 700.0))], key=lambda m: m.urgency)
    assert [m.machine_id for m in ranked] == ['c', 'm', 'a']


def test_trend_series_take_the_measured_plane_where_the_cells_could_tell(tmp_path):
    """read_series: the identified plane where the verdict is measured, else the layout's."""
    from cvc_balance.fleet.rows import RESULT_SCHEMA, table
    from cvc_balance.fleet.trends import read_series
    rows = []
    for k, (source, samples, permissible) in enumerate(
            (('measured', 100, 1000.0), ('layout', 100, 1000.0), ('measured', 0, 1000.0),
             ('measured', 100, None))):
        rows.append({'machine_id': 'm', 'segment_start': START_NS + k * DAY_NS,
                     'layout_digest': 'd', 'layout_name': 'g', 'grade': 6.3,
                     'segment_samples': samples, 'plane_I_permissible_g_mm': permissible,
                     'plane_II_permissible_g_mm': permissible, 'plane_I_g_mm': 100.0 + k,
                     'plane_II_g_mm': 200.0 + k, 'identified_plane_I_g_mm': 300.0 + k,
                     'identified_plane_II_g_mm': 400.0 + k,
                     'identified_plane_I_g_mm_ci95': 7.0, 'identified_plane_II_g_mm_ci95': 8.0,
                     'verdict_source': source, 'analysed_at': START_NS})
    rows.append(dict(rows[0], machine_id='other'))
    path = tmp_path / 'fleet.parquet'
    pq.write_table(table(rows, RESULT_SCHEMA), path)
    both = read_series(path)
    assert sorted(both) == ['m', 'other']
    got = read_series(path, machine='m')['m']          # runs without samples or a share: out
    assert got['amount_I'].tolist() == [300.0, 101.0]
    assert got['amount_II'].tolist() == [400.0, 201.0]
    assert got['identified_I'].tolist() == [True, False]
    assert got['ci95_I'][0] == 7.0 and math.isnan(got['ci95_I'][1])
    assert (got['t'] - START_NS).tolist() == [0, DAY_NS]


# -- the tables: where they go, what is merged, what is refused ---------------------------------

def test_the_tables_paths_merge_and_refusals(tmp_path):
    """By hand: the failures' name, rows merged by (digest, bag), other files refused whole."""
    import pyarrow as pa
    from cvc_balance.fleet import store
    from cvc_balance.fleet.rows import FAILURE_SCHEMA, table
    assert store.failures_path(tmp_path / 'fleet.parquet') == tmp_path / 'fleet.failures.parquet'
    assert store.failures_path(tmp_path / 'results') == tmp_path / 'results.failures.parquet'
    assert store.lock_path(tmp_path / 'f.parquet') == tmp_path / 'f.parquet.lock'

    def rows(*pairs):
        return table([{'digest': d, 'bag': b, 'reason': 'r'} for d, b in pairs], FAILURE_SCHEMA)
    current = rows(('d1', 'a'), ('d2', 'b'), ('d2', 'b2'))
    added = rows(('d2', 'b'), ('d3', 'c'), ('d1', 'a'))
    merged = store.merged(current, added)
    assert list(zip(merged.column('digest').to_pylist(), merged.column('bag').to_pylist())) \
        == [('d1', 'a'), ('d2', 'b'), ('d2', 'b2'), ('d3', 'c')]
    retried = store.merged(current, added, dropped={'d1'})
    assert list(zip(retried.column('digest').to_pylist(), retried.column('bag').to_pylist())) \
        == [('d2', 'b'), ('d2', 'b2'), ('d3', 'c'), ('d1', 'a')]
    # Written whole, read back equal; nothing left beside it.
    path = tmp_path / 'failures.parquet'
    store.write(path, merged)
    assert store.read(path, FAILURE_SCHEMA).equals(merged)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['failures.parquet']
    assert store.read(tmp_path / 'none.parquet', FAILURE_SCHEMA).num_rows == 0
    # Not a table, another table, a folder: one line naming the file, nothing overwritten.
    (tmp_path / 'text.parquet').write_text('not parquet')
    pq.write_table(pa.table({'digest': ['x']}), tmp_path / 'other.parquet')
    for name, says in (('text.parquet', 'not a readable Parquet table'),
                       ('other.parquet', 'missing or different: bag (string)'),
                       ('.', 'is a directory')):
        with pytest.raises(ValueError) as caught:
            store.read(tmp_path / name, FAILURE_SCHEMA)
        message = str(caught.value)
        assert says in message and '\n' not in message, message
        assert message.startswith(str(tmp_path / name if name != '.' else tmp_path))
    assert (tmp_path / 'text.parquet').read_text() == 'not parquet'


def test_bags_found_once_in_name_order_hidden_folders_skipped(tmp_path):
    """A file and a folder given (the file also inside it, and linked): each bag once."""
    from cvc_balance.fleet import find_bags
    runs = tmp_path / 'runs'
    (runs / '.cache').mkdir(parents=True)
    (runs / '.cache' / 'old.mcap').write_bytes(b'x')
    (runs / 'b.mcap').write_bytes(b'x')
    (runs / 'a.db3').write_bytes(b'x')
    (runs / 'link.mcap').symlink_to(runs / 'b.mcap')
    found = find_bags([runs / 'b.mcap', runs, runs / 'b.mcap'])
    assert found == [(runs / 'b.mcap', runs), (runs / 'a.db3', runs)]
    with pytest.raises(FileNotFoundError) as caught:
        find_bags([runs, tmp_path / 'nowhere'])
    assert str(caught.value) == f'{tmp_path / "nowhere"}: no such file or directory'


# -- the simulation's plan against its own description (simulate_fleet's docstrings) -----------

def test_the_simulated_histories_are_those_described(fleet):
    """
    Simulate the histories the description gives.

    Each machine's kind by its number, its slip, swap, extra tube mass and as-built mass in
    their ranges; each run's date, path, declared and true layout, by hand from the layout.
    """
    plans, _, _ = fleet
    layout = yaml.safe_load(LAYOUT.read_text())
    by_name = {c['name']: c for c in layout['components']}
    first = datetime(2026, 1, 5, 8, 0, tzinfo=timezone.utc)
    kinds = ['slipping counterweight', 'tube swap', 'both', 'steady']
    assert [p.machine_id for p in plans] == [f'gantry-000{i}' for i in range(1, MACHINES + 1)]
    assert [p.kind for p in plans] == [kinds[i % 4] for i in range(MACHINES)]
    offsets = []             # minutes past 08:00 + 7 i: uniform over [0, 90)
    for i, plan in enumerate(plans):
        slips, swaps = plan.kind in kinds[0:3:2], plan.kind in kinds[1:3]
        assert (0.005 <= plan.slip_mm_per_day < 0.025) if slips else plan.slip_mm_per_day == 0
        if swaps:
            assert 0.35 * 120 <= (plan.swap - first).total_seconds() / 86400 < 0.65 * 120
            assert 0.2 <= plan.tube_extra_kg < 0.6
        else:
            assert (plan.swap, plan.tube_extra_kg) == (None, 0.0)
        built = plan.as_built
        assert sorted(built) == ['angle_deg', 'mass', 'name', 'radius', 'z']
        assert (built['name'], built['radius']) == ('as_built', 0.6)
        assert 0.02 <= built['mass'] <= 0.1 and round(built['mass'], 4) == built['mass']
        assert 0 <= built['angle_deg'] <= 360 and -0.12 <= built['z'] <= 0.12
        assert len(plan.runs) == RUNS
        for k, run in enumerate(plan.runs):
            minutes = (run.when - first - timedelta(days=40 * k)).total_seconds() / 60
            assert 7 * i <= minutes < 7 * i + 90, (i, k, minutes)
            offsets.append(minutes - 7 * i)
            name = run.when.strftime('%Y-%m-%dT%H%M%S')
            assert run.path.parent.name == plan.machine_id
            assert run.path.name == (name if k == 2 else f'{name}.mcap')
            assert run.path.is_dir() == (k == 2)
            swapped = swaps and run.when >= plan.swap
            declared = {c['name']: c for c in run.declared['components']}
            want = dict(by_name)
            if swapped:
                tube = by_name['xray_tube']
                want['xray_tube'] = dict(tube, mass=tube['mass'] + 0.5)
                want['tube_swap_correction'] = {
                    'name': 'tube_swap_correction', 'mass': 0.5, 'radius': tube['radius'],
                    'angle_deg': tube['angle_deg'] + 180.0, 'z': tube['z']}
            assert declared == want
            assert {k: v for k, v in run.declared.items() if k != 'components'} == \
                {k: v for k, v in layout.items() if k != 'components'}
            true = {c['name']: dict(c) for c in run.true_components}   # popped below
            assert true.pop('as_built') == built
            elapsed = (run.when - first).total_seconds() / 86400
            slipped = want['counterweight_rear']['radius'] + plan.slip_mm_per_day * 1e-3 * elapsed
            assert abs(true['counterweight_rear'].pop('radius') - slipped) <= 1e-15
            heavier = want['xray_tube']['mass'] + (plan.tube_extra_kg if swapped else 0.0)
            assert abs(true['xray_tube'].pop('mass') - heavier) <= 1e-13
            for name, moved in (('counterweight_rear', 'radius'), ('xray_tube', 'mass')):
                want[name] = {k: v for k, v in want[name].items() if k != moved}
            assert true == want
    # 24 draws spread over the 90 minutes (all within 45 of each other: odds 1.5e-6).
    assert max(offsets) - min(offsets) > 45.0, offsets


def test_each_simulated_run_is_the_check_described(fleet):
    """
    Simulate each run as the check described.

    A spin-up at 12 rad/s^2 to 23.27 rad/s, 3 s there, a coast-down: 2 x 23.27 / 12 + 3 s
    at 100 samples/s, 23.27^2 / 12 + 3 x 23.27 rad turned; two cells at 100 readings/s
    with 15 N of noise on each axis (the fit's rms 15 sqrt 2 N).
    """
    plans, _, rows = fleet
    seconds = 2 * 23.27 / 12.0 + 3.0
    turns = (23.27 ** 2 / 12.0 + 3.0 * 23.27) / (2 * math.pi)
    rms = []
    for plan in plans:
        for run in plan.runs:
            row = rows[str(run.path)]
            assert row['samples'] == math.floor(seconds * 100) + 1
            assert abs((row['run_end'] - row['run_start']).total_seconds()
                       - math.floor(seconds * 100) / 100) < 1e-6
            assert abs(row['identified_readings'] - 2 * row['samples']) <= 2
            assert abs(row['identified_revolutions'] - turns) < 0.01
            assert 23.27 <= row['top_speed'] <= 23.27 + 5 * 0.005
            rms.append(row['fit_rms_N'])
    assert abs(np.mean(rms) - 15 * math.sqrt(2)) < 0.03 * 15 * math.sqrt(2), np.mean(rms)


def test_a_simulated_fleet_refuses_what_it_cannot_simulate(tmp_path):
    """No components, no counterweight or tube of the names given, no machines: the words."""
    (tmp_path / 'list.yaml').write_text('- 1\n')
    (tmp_path / 'bare.yaml').write_text(yaml.safe_dump({'components': [
        {'name': 'xray_tube', 'mass': 1.0, 'radius': 0.1}]}))
    for layout, options, says in (
            ('list.yaml', {}, f'{tmp_path / "list.yaml"}: not a layout (a mapping with a list '
                              'of components)'),
            ('bare.yaml', {}, f"{tmp_path / 'bare.yaml'}: no component 'counterweight_rear' "
                              '(the simulated fleet moves a counterweight and swaps a tube)'),
            ('bare.yaml', {'counterweight': 'xray_tube', 'tube': 'anode'},
             f"{tmp_path / 'bare.yaml'}: no component 'anode' (the simulated fleet moves a "
             'counterweight and swaps a tube)')):
        with pytest.raises(ValueError) as caught:
            simulate_fleet(tmp_path / layout, tmp_path / 'runs', **options)
        assert str(caught.value) == says
    for options in ({'machines': 0}, {'runs': 0}, {'days': 0.0}, {'steady': 0.0},
                    {'days': math.nan}):
        with pytest.raises(ValueError) as caught:
            simulate_fleet(LAYOUT, tmp_path / 'runs', **options)
        assert str(caught.value) == ('a fleet needs machines >= 1, runs >= 1, days > 0 and '
                                     'steady > 0')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bare.yaml', 'list.yaml']


def test_a_layout_without_a_service_speed_or_planes_is_checked_at_23_27_rad_s(tmp_path):
    """
    Check a layout without a service speed or planes at 23.27 rad/s.

    The simulation's defaults by hand: 23.27 rad/s; the as-built mass between -0.12 and
    0.12 m; one run of one machine (20 samples/s, 0.2 s steady).
    """
    layout = yaml.safe_load(LAYOUT.read_text())
    del layout['balancing']
    (tmp_path / 'plain.yaml').write_text(yaml.safe_dump(layout))
    (plan,) = simulate_fleet(tmp_path / 'plain.yaml', tmp_path / 'runs', machines=1, runs=1,
                             rate=20.0, cell_rate=20.0, steady=0.2, seed=5)
    assert -0.12 <= plan.as_built['z'] <= 0.12 and plan.kind == 'slipping counterweight'
    (run,) = plan.runs
    assert run.path == tmp_path / 'runs' / 'gantry-0001' / \
        f'{run.when.strftime("%Y-%m-%dT%H%M%S")}.mcap'
    joints, cells, _ = messages(run.path)
    assert 23.27 <= max(w for _, w in joints) <= 23.27 + 5 * 0.005
    assert len(joints) == math.floor((2 * 23.27 / 12.0 + 0.2) * 20) + 1


def test_the_layouts_service_speed_every_third_run_a_directory_and_a_seed_repeats(tmp_path):
    """
    Check a layout's own service speed, the runs' spacing and kinds, and the seed.

    A service speed of 20 rad/s: each run's top speed 20 rad/s within 5 times its noise
    (0.005 rad/s; 4 samples at the top at 20 samples/s);
    six runs over half a day: every 0.1 day, the third and sixth as rosbag2 directories;
    the same seed again (two runs: half a day apart): the same machine and first run.
    """
    layout = yaml.safe_load(LAYOUT.read_text())
    layout['balancing']['service_speed'] = 20.0
    (tmp_path / 'slow.yaml').write_text(yaml.safe_dump(layout))
    options = dict(machines=1, days=0.5, rate=20.0, cell_rate=20.0, steady=0.2, seed=11)
    (plan,) = simulate_fleet(tmp_path / 'slow.yaml', tmp_path / 'runs', runs=6, **options)
    first = datetime(2026, 1, 5, 8, 0, tzinfo=timezone.utc)
    for k, run in enumerate(plan.runs):
        minutes = (run.when - first - timedelta(days=0.1 * k)).total_seconds() / 60
        assert 0.0 <= minutes < 90.0, (k, minutes)
        assert run.path.is_dir() == (k % 3 == 2), k
        joints, _, _ = messages(run.path)
        assert abs(max(w for _, w in joints) - 20.0) <= 5 * 0.005
        assert len(joints) == math.floor((2 * 20.0 / 12.0 + 0.2) * 20) + 1
    (again,) = simulate_fleet(tmp_path / 'slow.yaml', tmp_path / 'again', runs=2, **options)
    assert again.as_built == plan.as_built and again.runs[0].when == plan.runs[0].when
    minutes = (again.runs[1].when - first - timedelta(days=0.5)).total_seconds() / 60
    assert 0.0 <= minutes < 90.0                        # two runs: the span apart


# -- the simulation's parts by themselves (pure: no bag written) ------------------------------

def test_each_kind_of_machine_has_its_history_by_hand():
    """
    Check each machine's history as described, from the simulation's own parts.

    Machine i's kind is KINDS[i % 4]; a slip (mm/day) in [0.005, 0.025) only for a slipping
    counterweight (and both), a swap 0.35 to 0.65 of the span after the first run and a
    tube 0.2 to 0.6 kg heavier than declared only with a tube swap (and both); the as-built
    mass 20 to 100 g at 0.6 m between the planes, at an angle of 0 to 360 degrees (to 0.01
    degree, z to 0.1 mm); its id gantry-NNNN from 1. Over 40 machines the draws spread
    over their ranges (the swaps past 0.6 of the span, the angles past 300 degrees).
    """
    from cvc_balance.fleet.simulate import _machine
    layout = yaml.safe_load(LAYOUT.read_text())
    first = datetime(2026, 1, 5, 8, 0, tzinfo=timezone.utc)
    rng = np.random.default_rng(3)
    kinds = ['slipping counterweight', 'tube swap', 'both', 'steady']
    swaps, angles, heights = [], [], []
    for i in range(40):
        plan = _machine(i, rng, first, 200.0, layout)
        built = plan.as_built
        angles.append(built['angle_deg'])
        heights.append(built['z'])
        assert round(built['angle_deg'], 2) == built['angle_deg'] and \
            round(built['z'], 4) == built['z']
        if plan.swap is not None:
            swaps.append((plan.swap - first).total_seconds() / 86400 / 200.0)
        assert (plan.machine_id, plan.kind, plan.runs) == (f'gantry-{i + 1:04d}', kinds[i % 4],
                                                           [])
        if plan.kind in kinds[0:3:2]:
            assert 0.005 <= plan.slip_mm_per_day < 0.025
        else:
            assert plan.slip_mm_per_day == 0.0
        if plan.kind in kinds[1:3]:
            assert 70.0 <= (plan.swap - first).total_seconds() / 86400 < 130.0
            assert 0.2 <= plan.tube_extra_kg < 0.6
        else:
            assert (plan.swap, plan.tube_extra_kg) == (None, 0.0)
        assert 0.02 <= plan.as_built['mass'] <= 0.1 and plan.as_built['radius'] == 0.6
        assert -0.12 <= plan.as_built['z'] <= 0.12 and 0 <= plan.as_built['angle_deg'] <= 360
    assert 0.6 < max(swaps) < 0.65 and 0.35 <= min(swaps) < 0.4
    assert 300.0 < max(angles) <= 360.0 and min(angles) < 60.0
    assert sum(a != int(a) for a in angles) > 30 and sum(z != 0.0 for z in heights) > 30
    bare = dict(layout, balancing={})                      # no planes: -+0.12 m
    heights = [_machine(i, rng, first, 10.0, bare).as_built['z'] for i in range(40)]
    assert -0.12 <= min(heights) < -0.06 and 0.06 < max(heights) <= 0.12
    wide = dict(layout, balancing=dict(layout['balancing'], planes=[-0.3, 0.5]))
    heights = [_machine(i, rng, first, 10.0, wide).as_built['z'] for i in range(40)]
    assert -0.3 <= min(heights) < -0.2 and 0.4 < max(heights) <= 0.5


def test_a_machines_declared_and_true_layouts_and_its_runs_scenario_by_hand():
    """
    Check the declared and true layouts before and after a swap, and a run's scenario.

    Before the swap: declared as the layout; true with the as-built mass and the rear
    counterweight 0.01 mm/day x 100 days further out. After: the tube 0.5 kg heavier and
    0.5 kg opposite it declared; the true tube heavier by the extra too. The scenario: a
    spin-up at 12 rad/s^2 to the speed, ``steady`` s there, a coast-down; the hidden
    changes the layout does not declare; load cells at the rate asked, 15 N of noise and
    biases of 100 (j + 1), -50 and 3 N.
    """
    from cvc_balance.fleet.simulate import _scenario, _state, MachinePlan
    layout = yaml.safe_load(LAYOUT.read_text())
    first = datetime(2026, 1, 5, tzinfo=timezone.utc)
    built = {'name': 'as_built', 'mass': 0.05, 'radius': 0.6, 'angle_deg': 30.0, 'z': 0.0}
    plan = MachinePlan('m', 'both', 0.01, first + timedelta(days=50), 0.3, built)
    by_name = {c['name']: c for c in layout['components']}
    before, true = _state(layout, plan, first + timedelta(days=20), first,
                          'counterweight_rear', 'xray_tube')
    assert before == layout and before is not layout
    true_parts = {c['name']: c for c in true['components']}
    assert true_parts.pop('as_built') == built
    assert true_parts['counterweight_rear']['radius'] == pytest.approx(0.66 + 0.01e-3 * 20,
                                                                       abs=1e-15)
    assert {k: v for k, v in true_parts.items() if k != 'counterweight_rear'} == \
        {k: v for k, v in by_name.items() if k != 'counterweight_rear'}
    after, true = _state(layout, plan, first + timedelta(days=100), first,
                         'counterweight_rear', 'xray_tube')
    declared = {c['name']: c for c in after['components']}
    assert declared['xray_tube']['mass'] == 60.5
    assert declared['tube_swap_correction'] == {'name': 'tube_swap_correction', 'mass': 0.5,
                                                'radius': 0.62, 'angle_deg': 180.0, 'z': 0.05}
    true_parts = {c['name']: c for c in true['components']}
    assert true_parts['xray_tube']['mass'] == pytest.approx(60.8, abs=1e-12)
    assert true_parts['counterweight_rear']['radius'] == pytest.approx(0.66 + 1e-3, abs=1e-15)
    assert by_name['xray_tube']['mass'] == 60.0                # the layout itself untouched
    when = first + timedelta(days=100)
    spec = _scenario(plan, after, true, when, 50.0, 40.0, 20.0, 7, 2.5)
    assert spec['profile'] == [{'type': 'spin_up', 'to': 20.0, 'alpha': 12.0},
                               {'type': 'steady', 'duration': 2.5},
                               {'type': 'coast_down', 'to': 0.0, 'alpha': -12.0}]
    assert (spec['rate'], spec['seed'], spec['start'], spec['layout']) == (
        50.0, 7, when.timestamp(), after)
    assert (spec['name'], spec['joint_name']) == (f'm {when.isoformat()}', 'gantry_joint')
    assert spec['noise'] == {'angle': 1.0e-4, 'speed': 0.005}
    assert spec['load_cells'] == {'rate': 40.0, 'noise': 15.0,
                                  'bias': {'front': [100.0, -50.0, 3.0],
                                           'rear': [200.0, -50.0, 3.0]}}
    hidden = spec['hidden']
    assert hidden[0] == {'at': 0.0, 'add': built}
    assert sorted((h['set']['component'], sorted(h['set'])) for h in hidden[1:]) == [
        ('counterweight_rear', ['component', 'radius']), ('xray_tube', ['component', 'mass'])]


def test_a_swap_at_a_runs_very_time_and_tubes_described_otherwise_by_hand():
    """
    Check the swap's correction for tubes given otherwise, and the hidden changes exactly.

    A run exactly at the swap is after it; the correction opposite a tube given in radians
    (30 degrees: at 210), in degrees, or with no angle (at 180) and no z (at 0); the new
    tube's declared mass to the microgram (60.1234567 + 0.5 kg: 60.623457); the true tube's
    extra 0.3 kg set at the start of the run as the only hidden change besides the as-built
    mass; a layout without supports: cells without biases.
    """
    import copy
    from cvc_balance.fleet.simulate import _scenario, _state, MachinePlan
    layout = yaml.safe_load(LAYOUT.read_text())
    first = datetime(2026, 1, 5, tzinfo=timezone.utc)
    swap = first + timedelta(days=50)
    built = {'name': 'as_built', 'mass': 0.05, 'radius': 0.6, 'angle_deg': 30.0, 'z': 0.0}
    plan = MachinePlan('m', 'tube swap', 0.0, swap, 0.3, built)
    declared, _ = _state(layout, plan, swap, first, 'counterweight_rear', 'xray_tube')
    assert 'tube_swap_correction' in {c['name'] for c in declared['components']}
    for tube, mass, opposite, z in (
            ({'mass': 60.1234567, 'radius': 0.62, 'angle': math.pi / 6}, 60.623457, 210.0, 0.0),
            ({'mass': 60.0, 'radius': 0.62, 'angle_deg': 30.0, 'z': 0.05}, 60.5, 210.0, 0.05),
            ({'mass': 60.0, 'radius': 0.62}, 60.5, 180.0, 0.0)):
        other = copy.deepcopy(layout)
        other['components'] = [c for c in other['components'] if c['name'] != 'xray_tube'] + \
            [dict(tube, name='xray_tube')]
        declared, true = _state(other, plan, swap + timedelta(days=1), first,
                                'counterweight_rear', 'xray_tube')
        parts = {c['name']: c for c in declared['components']}
        assert parts['xray_tube']['mass'] == mass
        correction = parts['tube_swap_correction']
        assert abs(correction.pop('angle_deg') - opposite) < 1e-12
        assert correction == {'name': 'tube_swap_correction', 'mass': 0.5, 'radius': 0.62,
                              'z': z}
        spec = _scenario(plan, declared, true, swap, 50.0, 40.0, 20.0, 7, 2.5)
        assert spec['hidden'] == [
            {'at': 0.0, 'add': built},
            {'at': 0.0, 'set': {'component': 'xray_tube', 'mass': mass + 0.3}}]
    bare = dict(declared, supports=[])
    del bare['supports']
    spec = _scenario(plan, bare, true, swap, 50.0, 40.0, 20.0, 7, 2.5)
    assert spec['load_cells']['bias'] == {}


def test_the_runs_of_machine_i_are_staggered_7_minutes_by_hand(tmp_path, monkeypatch):
    """
    Place each run at its day plus its drawn minutes plus 7 minutes a machine, by hand.

    Every draw made the middle of its range (the minutes 45 of [0, 90)), no bag written:
    six machines of three runs over 10 days start 2026-01-05 08:00 UTC, run k at day 5 k,
    machine i at 08:45 + 7 i minutes, its file named by that time.
    """
    from cvc_balance.fleet import simulate

    class Middle:
        def uniform(self, low, high):
            return (low + high) / 2.0
    monkeypatch.setattr(np.random, 'default_rng', lambda seed: Middle())
    written = []
    monkeypatch.setattr(simulate, 'dump_document', lambda spec: '')
    monkeypatch.setattr(simulate, 'load_scenario', lambda path: None)
    monkeypatch.setattr(simulate, 'write_bag',
                        lambda scenario, path, machine_id: written.append((path, machine_id)))
    plans = simulate_fleet(LAYOUT, tmp_path / 'runs', machines=6, runs=3, days=10.0)
    when = [[run.when for run in plan.runs] for plan in plans]
    assert when[0] == [datetime(2026, 1, 5, 8, 45, tzinfo=timezone.utc),
                       datetime(2026, 1, 10, 8, 45, tzinfo=timezone.utc),
                       datetime(2026, 1, 15, 8, 45, tzinfo=timezone.utc)]
    assert when[1][0] == datetime(2026, 1, 5, 8, 52, tzinfo=timezone.utc)
    assert when[5][2] == datetime(2026, 1, 15, 9, 20, tzinfo=timezone.utc)
    assert when == [[datetime(2026, 1, 5 + 5 * k, 8, 45, tzinfo=timezone.utc)
                     + timedelta(minutes=7 * i) for k in range(3)] for i in range(6)]
    assert [(path.parent.name, path.name) for path, _ in written][-3:] == [
        ('gantry-0006', '2026-01-05T092000.mcap'), ('gantry-0006', '2026-01-10T092000.mcap'),
        ('gantry-0006', '2026-01-15T092000')]
