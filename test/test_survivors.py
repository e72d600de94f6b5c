"""
Bugs that once passed every test (issue 29), each caught here against an independent reference.

Each test names the bug it catches; each was seen to fail with that bug put in by hand and
to pass without it. The references: load-cell readings made by Pinocchio's RNEA
(test/independent.py) and the unbalance of a layout's point masses by hand; the vector
split solved as a 2x2 linear system by numpy; the fewest weights by enumerating every
loading; a trend's step and its 95 % half-width from a least squares written the other
way round (the step a coefficient of its own); the rows of a Parquet table read back by
pyarrow; the messages of a cut recording counted by the ``mcap`` library's own reader.
"""

import cmath
import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from cvc_balance.identify.live import SlidingFit
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from independent import PinocchioRotor
from reference import planes_by_hand, shares_by_hand

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())


# -- identify/live: the sliding fit ------------------------------------------------------

def aggregates_by_hand(layout):
    """
    Return S = sum m R e^{i theta} (kg m) and P = sum m R z e^{i theta} (kg m^2) by hand.

    Every body of config/ct_gantry.yaml has an axis along the rotor's Z (radial,
    tangential and axial own axes): no own products xz, yz.
    """
    s = p = 0j
    for c in layout['components']:
        u = c['mass'] * c['radius'] * cmath.exp(1j * math.radians(c['angle_deg']))
        s, p = s + u, p + u * c.get('z', 0.0)
    return s, p


def spin_up(t, alpha=6.0):
    """Exact motion at constant ``alpha`` rad/s^2 from rest: angle (wrapped), omega, alpha."""
    angle = 0.5 * alpha * t * t
    return (math.remainder(angle, 2 * math.pi), alpha * t, alpha)


def cell_readings(layout, times, motion=spin_up):
    """[(time, support, force x, y)] by Pinocchio's RNEA, split over the supports by statics."""
    rotor = PinocchioRotor(layout)
    out = []
    for k, support in enumerate(layout['supports']):
        for t in times + 0.37e-3 * (k + 1):       # each cell on its own clock
            q, w, a = motion(t)
            force = rotor.loads(q, w, a)['supports'][support['name']][0]
            out.append((t, support['name'], force[0], force[1]))
    return sorted(out)


def feed(live, readings, motion_times, motion=spin_up, offset=0.0, after_close=None):
    """Feed motion samples and readings in time order; call ``after_close`` at each revolution."""
    k = 0
    for t, name, fx, fy in readings:
        while k < len(motion_times) and motion_times[k] <= t:
            before = live.revolutions
            live.motion(offset + motion_times[k], *motion(motion_times[k]))
            if after_close is not None and live.revolutions != before:
                after_close(live, offset + motion_times[k])
            k += 1
        live.reading(name, offset + t, (fx, fy))


def with_mass(layout, mass, radius, angle_deg, z):
    out = copy.deepcopy(layout)
    out['components'].append({'name': 'hidden', 'mass': mass, 'radius': radius,
                              'angle_deg': angle_deg, 'z': z})
    return out


def test_live_readings_between_motion_samples_take_the_speed_at_their_own_stamp():
    """
    Bug: the speed not advanced to a reading between motion samples (omega += alpha dt gone).

    A spin-up at 6 rad/s^2, encoder at 500 Hz, cells at 400 Hz on their own clocks (every
    reading between two motion samples), no noise: the live fit must give the true rotor's
    S and P (by hand). Measured: 2.2e-14 and 5.1e-14 relative; with the bug 7.0e-4 and
    4.0e-4 (the batch fit, interpolating linearly: 1.9e-6).
    """
    true_layout = with_mass(GANTRY, 0.5, 0.62, 40.0, 0.05)
    s_true, p_true = aggregates_by_hand(true_layout)
    declared = RotorModel.from_layout(parse_layout(GANTRY))
    live = SlidingFit(declared.supports, declared.gravity[2], window_revs=1000)
    motion_times = np.arange(0.0, 3.0, 1 / 500)
    feed(live, cell_readings(true_layout, np.arange(0.001, 2.99, 1 / 400)), motion_times)
    found = live.estimate()
    assert live.dropped == 0 and found.identifiable
    assert abs(found.static - s_true) <= 1e-11 * abs(s_true), found.static
    assert abs(found.products - p_true) <= 1e-11 * abs(p_true), found.products


def test_the_live_window_holds_exactly_window_revs_whole_revolutions():
    """
    Bug: the window keeps one revolution too many (``> window_revs + 1``).

    Exact readings of one rotor, then of a rotor 0.5 kg heavier (at a time that is no
    revolution's start). After each revolution closes, the window (the last 3 whole
    revolutions and the one under way) still holds readings of the first rotor until 3
    whole revolutions of the second have closed after the one the change fell in: then,
    and only then, the fit is the second rotor exactly (by hand). Measured: 4.9e-14
    relative from the 4th close on, 0.18 to 1.04 before; with the bug 0.14 at the 4th.
    """
    window = 3
    light, heavy = with_mass(GANTRY, 0.0, 0.0, 0.0, 0.0), with_mass(GANTRY, 0.5, 0.62, 40, 0.05)
    s_heavy, p_heavy = aggregates_by_hand(heavy)
    declared = RotorModel.from_layout(parse_layout(GANTRY))
    live = SlidingFit(declared.supports, declared.gravity[2], window_revs=window)

    def steady(t):                            # 23.27 rad/s from angle 0.1: 0.27 s a turn
        return math.remainder(0.1 + 23.27 * t, 2 * math.pi), 23.27, 0.0
    change = 1.2                              # s: the heavier rotor's readings from here
    readings = [r for r in cell_readings(light, np.arange(0.0, change, 1 / 400), steady)
                if r[0] < change] \
        + cell_readings(heavy, np.arange(change, 3.2, 1 / 400), steady)
    errors = []

    def after_close(fit, when):
        estimate = fit.estimate()
        if when > change:
            errors.append(max(abs(estimate.static - s_heavy) / abs(s_heavy),
                              abs(estimate.products - p_heavy) / abs(p_heavy)))
    feed(live, sorted(readings), np.arange(0.0, 3.2, 1 / 500), steady, after_close=after_close)
    assert len(errors) >= window + 3
    # Close 1 ends the revolution the change fell in (both rotors); closes 2..window still
    # hold it; from close window + 1 on, only the heavy rotor.
    assert all(e > 1e-3 for e in errors[:window]), errors
    assert all(e < 1e-11 for e in errors[window:]), errors


# -- field/plan: the vector split and the fewest weights --------------------------------

def test_the_vector_split_wraps_round_past_the_last_site():
    """
    Bug: the site before a correction past the last site taken as angles[-1], not - 2 pi.

    Sites at 45, 165 and 285 deg (R 0.5 m): a correction of 0.06 kg m at 10 deg lies
    between 285 (= -75) and 45 deg, and one at 300 deg between 285 and 405 (= 45). Each
    share from the 2x2 linear system m_a R e^{i phi_a} + m_b R e^{i phi_b} = U, solved by
    numpy. With the bug the 10 deg correction went whole to 285 deg.
    """
    from cvc_balance.field.plan import vector_split
    from cvc_balance.physics.layout import WeightSites
    sites = WeightSites('I', tuple(np.radians([45.0, 165.0, 285.0])), 0.5, (0.01,), 1)
    for degrees, pair in ((10.0, (285.0, 45.0)), (300.0, (285.0, 45.0)),
                          (100.0, (45.0, 165.0)), (200.0, (165.0, 285.0))):
        correction = 0.06 * cmath.exp(1j * math.radians(degrees))
        shares = vector_split(correction, sites)
        got = {round(math.degrees(a), 9): m for a, m in shares}
        phi = np.radians(pair)
        system = 0.5 * np.array([np.cos(phi), np.sin(phi)])
        masses = np.linalg.solve(system, [correction.real, correction.imag])
        assert set(got) == set(pair), (degrees, got)
        assert masses.min() > 0.0
        for angle, mass in zip(pair, masses):
            assert abs(got[angle] - mass) <= 1e-15, (degrees, angle, got[angle], mass)


def test_the_fewest_weights_keep_every_residual_within_its_limit():
    """
    Bug: the fewest-weights plan's polygon about the limit's circle (cos(pi/K) -> 1.0).

    One plane, two sites 90 deg apart at pi/K (R 0.5 m, one 0.1 kg weight each), the
    unbalance -(U_a + U_b) of both weights: no weight leaves |r| = 1.41 of the limit, one
    weight 1.002 of it (at a vertex of the 32-gon, where the polygon about the circle
    reaches 1/cos(pi/32) = 1.0048), both weights 0. Enumerating the four loadings, the
    fewest weights with |r| within the limit is 2: with the bug the plan took one, 0.2 %
    over the limit, and called it optimal.
    """
    from cvc_balance.field import optimal_plan, problem_from_unbalance
    from cvc_balance.physics.layout import WeightSites
    polygon = 32
    first = math.pi / polygon
    sites = {'I': WeightSites('I', (first, first + math.pi / 2), 0.5, (0.1,), 1)}
    each = [0.05 * cmath.exp(1j * a) for a in sites['I'].angles]
    unbalance = -(each[0] + each[1])
    limit = 0.05 / 1.002
    problem = problem_from_unbalance(('I',), [unbalance], permissible=[limit])
    loadings = ((0j, 0), (each[0], 1), (each[1], 1), (each[0] + each[1], 2))
    reach = [abs(unbalance + u) / limit for u, _ in loadings]
    assert abs(reach[1] - 1.002) < 1e-12 and abs(reach[2] - 1.002) < 1e-12
    within = [n for (u, n), r in zip(loadings, reach) if r <= 1.0]
    plan = optimal_plan(problem, sites, 'fewest', polygon=polygon)
    after = abs(problem.residual(plan.corrections)[0])
    assert plan.status == 'optimal' and plan.count == min(within) == 2, plan
    assert after <= limit and plan.residual.within_limits, after / limit


# -- fleet: discovery, failures, trends --------------------------------------------------

def test_db3_files_and_rosbag2_directories_are_found_and_nothing_else(tmp_path):
    """
    Bug: ``.db3`` bags never found (the suffix dropped from the list).

    A tree made by hand: its bags, by hand, in name order: a bare SQLite bag, MCAP
    files, a rosbag2 directory (whose split files are not bags of their own); not a text
    file, a hidden file or a staging folder.
    """
    from cvc_balance.fleet import find_bags
    (tmp_path / 'a').mkdir()
    for name in ('a/run_1.db3', 'a/run_2.mcap', 'a/notes.txt', 'a/.hidden.mcap',
                 'b.DB3.txt', 'c.db3'):
        (tmp_path / name).write_bytes(b'x')
    split = tmp_path / 'a' / 'split'
    split.mkdir()
    (split / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    (split / 'split_0.db3').write_bytes(b'x')
    (tmp_path / 'out.partial').mkdir()
    (tmp_path / 'out.partial' / 'x.db3').write_bytes(b'x')
    found = [(str(bag.relative_to(tmp_path)), root) for bag, root in find_bags([tmp_path])]
    assert sorted(found) == [('a/run_1.db3', tmp_path), ('a/run_2.mcap', tmp_path),
                             ('a/split', tmp_path), ('c.db3', tmp_path)]
    # A bag given by itself is taken whatever its suffix.
    assert find_bags([tmp_path / 'c.db3']) == [(tmp_path / 'c.db3', tmp_path)]


def test_a_broken_link_gets_a_failure_row(tmp_path):
    """
    Bug: an unreadable bag (a broken symbolic link) skipped without a failure row.

    The tables read back by pyarrow: no result, one failure naming the link and why.
    """
    import pyarrow.parquet as pq
    from cvc_balance.fleet import run_fleet
    runs = tmp_path / 'runs'
    runs.mkdir()
    (runs / 'lost.mcap').symlink_to(tmp_path / 'gone.mcap')
    report = run_fleet([runs], tmp_path / 'fleet.parquet', engine='local', progress=False)
    assert (report.found, report.analysed, report.failed) == (1, 0, 1)
    failures = pq.read_table(tmp_path / 'fleet.failures.parquet').to_pylist()
    assert [(row['bag'], row['reason']) for row in failures] == [
        (str(runs / 'lost.mcap'), f'a symbolic link to {tmp_path / "gone.mcap"}, which does '
         'not exist (a broken link): not read')]
    assert pq.read_table(tmp_path / 'fleet.parquet').num_rows == 0


def series_of(days, amounts, digests, permissible=1000.0):
    """Return a machine's series as :func:`cvc_balance.fleet.trends.read_series` gives it."""
    n = len(days)
    day_ns = 86_400 * 10**9
    return {'t': (1_760_000_000 * 10**9 + np.asarray(days) * day_ns).astype(np.int64),
            'layout_digest': np.array(digests, dtype=object),
            'layout_name': np.array(['gantry'] * n, dtype=object),
            'grade': np.full(n, 6.3),
            'amount_I': np.asarray(amounts, float), 'ci95_I': np.full(n, np.nan),
            'permissible_I': np.full(n, permissible), 'identified_I': np.zeros(n, bool),
            'amount_II': np.full(n, np.nan), 'ci95_II': np.full(n, np.nan),
            'permissible_II': np.full(n, permissible), 'identified_II': np.zeros(n, bool)}


def test_a_layout_changes_step_and_its_half_width_against_least_squares_by_hand():
    """
    Bug: a step's half-width with the wrong sign of its covariance term (+2 c_ab).

    The reference fits the same runs with the step a coefficient of its own (columns 1,
    after-the-change, days): its estimate and its 95 % half-width t_{0.975, n-3}
    sqrt(s^2 [(X^T X)^-1]_11) by numpy and scipy's t. Measured: the step to 1.3e-14, its
    half-width to 5.7e-14 relative; with the bug 91.7 g mm against 60.9.
    """
    from scipy import stats
    from cvc_balance.fleet.trends import fit_machine
    days = np.array([0.0, 9.0, 21.0, 30.0, 44.0, 60.0, 71.0, 85.0, 98.0, 120.0])
    after = days >= 50.0
    noise = np.array([12.0, -30.0, 8.0, 25.0, -14.0, 3.0, -22.0, 17.0, -6.0, 9.0])
    amounts = 400.0 + 1.5 * days + 150.0 * after + noise
    machine = fit_machine('m', series_of(days, amounts, np.where(after, 'new', 'old')))
    (change,) = machine.changes
    step, half = change.steps['I']
    design = np.column_stack([np.ones(len(days)), after.astype(float), days])
    coefficients, *_ = np.linalg.lstsq(design, amounts, rcond=None)
    residual = amounts - design @ coefficients
    dof = len(days) - 3
    variance = residual @ residual / dof
    half_by_hand = stats.t.ppf(0.975, dof) * math.sqrt(
        variance * np.linalg.inv(design.T @ design)[1, 1])
    assert abs(step - coefficients[1]) <= 1e-12 * abs(coefficients[1]), (step, coefficients)
    assert abs(half - half_by_hand) <= 1e-12 * half_by_hand, (half, half_by_hand)


def test_a_run_analysed_again_counts_by_its_latest_row(tmp_path):
    """
    Bug: a re-analysed run keeping its OLDEST row (``analysed_at`` ascending).

    A results table written by hand: one run analysed twice (the later row says 700 g mm,
    the earlier 500), one other run. The series must hold 700 for that run, once.
    """
    import pyarrow.parquet as pq
    from cvc_balance.fleet.rows import RESULT_SCHEMA, table
    from cvc_balance.fleet.trends import read_series
    day = 86_400 * 10**9
    start = 1_760_000_000 * 10**9

    def row(when, analysed, amount):
        return {'machine_id': 'm1', 'segment_start': when, 'layout_digest': 'd1',
                'layout_name': 'gantry', 'grade': 6.3, 'segment_samples': 100,
                'plane_I_permissible_g_mm': 1000.0, 'plane_II_permissible_g_mm': 1000.0,
                'plane_I_g_mm': amount, 'plane_II_g_mm': 1.0, 'verdict_source': 'layout',
                'analysed_at': analysed}
    rows = [row(start, start + 5 * day, 500.0), row(start, start + 9 * day, 700.0),
            row(start + day, start + 6 * day, 600.0)]
    for order in (rows, rows[::-1]):
        path = tmp_path / 'fleet.parquet'
        pq.write_table(table(order, RESULT_SCHEMA), path)
        series = read_series(path)['m1']
        assert series['amount_I'].tolist() == [700.0, 600.0]
        assert (series['t'] - start).tolist() == [0, day]


# -- bag: a recording cut at a chunk's end; samples before the first layout --------------

def test_a_recording_cut_exactly_at_a_chunks_end_keeps_that_chunk(tmp_path):
    """
    Bug: a record ending exactly at the file's end taken as torn (``>`` -> ``>=``).

    A bag from the project's writer (messages serialised by rosbags), cut right after its
    third chunk record (its message indexes gone with the rest). The ``mcap`` library's
    own stream reader gives the messages of the whole records; ours must give the same,
    byte for byte, and say the recording is truncated. With the bug the third chunk's
    messages were lost (206 messages whole; the bug kept 2 chunks' worth).
    """
    import io
    import struct
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    from cvc_balance.bag.mcap_reader import Bag
    from cvc_balance.bag.replay import replay
    from independent import ramp, write_input_bag
    stamps, angle, omega = ramp(1.0, 2.0, rate=200.0, seconds=3.0)
    whole = write_input_bag(tmp_path / 'whole.mcap', stamps, angle, omega,
                            [(stamps[0] - 1000, yaml.safe_dump(GANTRY))])
    data = whole.read_bytes()
    position, chunk_ends = 8, []
    while position + 9 <= len(data):            # the top-level records, walked by hand
        opcode, length = struct.unpack_from('<BQ', data, position)
        position += 9 + length
        if opcode == 0x06:
            chunk_ends.append(position)
    assert len(chunk_ends) >= 4
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:chunk_ends[2]])
    theirs, topics = [], {}
    try:
        for record in StreamReader(io.BytesIO(cut.read_bytes())).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message) and topics[record.channel_id] == '/joint_states':
                theirs.append((record.log_time, bytes(record.data)))
    except Exception as error:                  # the end of the cut file
        assert type(error).__name__ == 'EndOfFile', error
    bag = Bag(cut)
    ours = bag.messages(bag.channel('/joint_states', 'sensor_msgs/msg/JointState'))
    assert len(theirs) > 200 and ours == theirs
    assert bag.problems == ['file has no end of data (truncated recording?)']
    summary = replay(cut)
    assert (summary.samples, summary.accepted) == (len(theirs), len(theirs))


def test_a_sample_rejected_before_the_first_layout_is_not_also_dropped(tmp_path):
    """
    Bug: a sample rejected before the first layout counted as dropped too.

    20 samples before the layout (log time), 2 of them not finite; 30 after, 1 of them
    not finite. By hand: 47 good, 3 rejected; of the good, 18 before the layout are
    dropped and 29 used; every sample counted once.
    """
    from cvc_balance.bag.replay import replay
    from independent import ramp, write_input_bag
    stamps, angle, omega = ramp(5.0, 0.0, rate=100.0, seconds=0.5)
    omega = omega.copy()
    omega[[3, 11, 33]] = math.nan
    layout_at = int(stamps[20]) - 5_000_000
    bag = write_input_bag(tmp_path / 'early.mcap', stamps, angle, omega,
                          [(layout_at, yaml.safe_dump(GANTRY))])
    summary = replay(bag)
    assert (summary.samples, summary.rejected, summary.dropped, summary.accepted) == \
        (50, 3, 18, 29)
    assert summary.samples == summary.rejected + summary.dropped + summary.accepted
    (segment,) = summary.segments
    assert segment.samples == 29


# -- the verdict of record: when rotor and layout disagree -------------------------------


def test_a_residual_beyond_residual_warn_raises_ok_to_warn():
    """
    Bug: a residual beyond ``residual_warn`` never raising OK to WARN.

    The cells measure the declared gantry plus 0.6 of plane II's permissible share at right
    angles to its unbalance (a point mass in plane II; exact, radius tiny). By hand: the
    measured plane II is sqrt(0.352^2 + 0.6^2) = 0.696 of its share, plane I 0.397: the
    measured rotor is OK (G 4.38, under 0.8 G); its residual, 0.6 of the share, is beyond
    residual_warn = 0.5: the verdict of record is WARN, and says where.
    """
    from cvc_balance.identify.evidence import verdict_of_record
    from cvc_balance.identify.fit import Estimate
    model = RotorModel.from_layout(parse_layout(GANTRY))
    declared, shares = planes_by_hand(GANTRY), shares_by_hand(GANTRY)
    z_ii = GANTRY['balancing']['planes'][1]
    extra = 0.6 * shares[1] * 1j * declared[1] / abs(declared[1])
    s, p = aggregates_by_hand(GANTRY)
    estimate = Estimate(s + extra, p + extra * z_ii, (0j, 0j), 1e-3, np.eye(2) * 1e-12, 1000,
                        True)
    fractions = [abs(declared[0]) / shares[0], abs(declared[1] + extra) / shares[1]]
    grade = 6.3 * max(fractions)
    assert grade < 0.8 * 6.3                    # by hand: the measured rotor alone is OK
    verdict = verdict_of_record(model, estimate, top_speed=23.27)
    assert verdict.source == 'measured' and verdict.measured.level == 'OK'
    assert abs(verdict.equivalent_grade - grade) <= 1e-9 * grade, verdict.equivalent_grade
    (plane,) = verdict.disagreements
    assert plane.plane == 'II' and abs(plane.fraction - 0.6) < 1e-9
    assert verdict.level == 'WARN'
    assert verdict.headline.startswith('WARN: ') and 'the rotor is not what its layout says: ' \
        'plane II' in verdict.text


def test_a_residual_inside_its_own_95_percent_circle_is_no_disagreement():
    """
    Bug: warnings for residuals inside their own 95 % circle.

    Rows by hand (plane, z, residual, its 95 % radius, permissible share), residual_warn
    0.5: a residual differs only when beyond BOTH its radius and half its share.
    """
    from cvc_balance.identify.evidence import disagreeing
    rows = [('I', -0.12, 0.030 + 0.040j, 0.060, 0.08),   # 0.05: beyond 0.04, inside 0.06
            ('II', 0.12, 0.050j, 0.050, 0.08),            # exactly on its circle: inside
            ('I', -0.12, -0.030, 0.010, 0.08),            # outside its circle, under 0.04
            ('II', 0.12, 0.041, 0.040, 0.08)]             # beyond both
    found = disagreeing(rows, residual_warn=0.5)
    assert [(d.plane, d.residual, d.ci95) for d in found] == [('II', 0.041, 0.040)]
    assert disagreeing(rows[:1], residual_warn=0.5) == ()


# -- assertions that could not fail, made two-sided -------------------------------------

def test_the_worst_case_is_its_bound_by_hand_not_just_above_every_draw():
    """
    The tolerance stack's worst case, to the bit of its definition, not only >= the draws.

    Three point masses (no own products), each plane's bound by hand (design/stack.py's
    description): |U_nominal| + sum_k max over the corners of the (m, R, z) box of
    |f - f_0| + |f_0| 2 sin(t_theta / 2), with f = m R (z_II - z) / b in plane I and
    m R (z - z_I) / b in plane II. And it is reached where it must be: one mass off by
    its radius tolerance alone leaves exactly |U_nominal| + m t_R (its share).
    """
    import itertools
    from cvc_balance.design.stack import analyse
    from cvc_balance.design.tolerances import Tolerances
    parts = [(2.0, 0.5, 30.0, -0.05), (3.0, 0.4, 200.0, 0.08), (1.5, 0.6, 300.0, 0.02)]
    layout = {'name': 'three', 'components': [
        {'name': f'p{k}', 'mass': m, 'radius': r, 'angle_deg': a, 'z': z}
        for k, (m, r, a, z) in enumerate(parts)],
        'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.2, 'axial': True}],
        'balancing': {'planes': [-0.1, 0.1], 'correction_radius': 0.5}}
    model = RotorModel.from_layout(parse_layout(layout))
    t = np.array([[0.01, 0.002, math.radians(2.0), 0.003],
                  [0.03, 0.001, math.radians(0.5), 0.001],
                  [0.0, 0.004, math.radians(4.0), 0.0]])
    result = analyse(model, Tolerances(t, np.zeros(3, bool)), 2000, seed=4)
    z_i, z_ii = layout['balancing']['planes']
    levers = (lambda z: (z_ii - z) / (z_ii - z_i), lambda z: (z - z_i) / (z_ii - z_i))
    for plane, lever in zip(result.planes, levers):
        nominal = abs(sum(m * r * lever(z) * cmath.exp(1j * math.radians(a))
                          for m, r, a, z in parts))
        bound = nominal
        for (m, r, _, z), (tm, tr, ta, tz) in zip(parts, t):
            f0 = m * r * lever(z)
            bound += max(abs((m + sm * tm) * (r + sr * tr) * lever(z + sz * tz) - f0)
                         for sm, sr, sz in itertools.product((-1, 1), repeat=3))
            bound += abs(f0) * 2 * math.sin(ta / 2)
        assert plane.worst_case == pytest.approx(bound, rel=1e-12), (plane.worst_case, bound)
        assert plane.max_drawn <= plane.worst_case
    # Reached: the radius of the second mass alone, at its tolerance.
    only = np.zeros((3, 4))
    only[1, 1] = 0.001
    reached = analyse(model, Tolerances(only, np.zeros(3, bool)), 10, seed=4)
    for plane, lever in zip(reached.planes, levers):
        nominal = abs(sum(m * r * lever(z) * cmath.exp(1j * math.radians(a))
                          for m, r, a, z in parts))
        assert plane.worst_case == pytest.approx(nominal + 3.0 * 0.001 * abs(lever(0.08)),
                                                 rel=1e-12)
