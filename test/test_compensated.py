"""
The exact aggregation's arithmetic, each result against an independent reference.

* cos and sin (table, reduction, polynomials) against 60-digit mpmath over many angles:
  seeded random ones at every scale, and the hard cases of a table-driven reduction
  (multiples of pi/2 and their neighbours, table points and the half-steps between
  them, the limits of each reduction path, the double nearest a multiple of pi/2);
  a hypothesis search over all finite doubles;
* the table itself, entry by entry, against mpmath;
* exact sums against ``math.fsum`` / ``Fraction`` on sums that cancel;
* :func:`place` on layouts of tens of thousands of components (several blocks, both
  worker threads, every reduction path, own tensors with products of inertia, mirrored
  pairs that cancel to ~1e-19) against aggregates summed exactly: dyadic masses,
  lengths and tensor elements on a few angles make every aggregate an integer sum per
  angle times 60-digit cosines and sines.
"""

from fractions import Fraction
import math

from hypothesis import given, settings, strategies as st
import mpmath as mp
import numpy as np
import pytest

from cvc_balance.physics import compensated
from cvc_balance.physics.inertia import place

STEP = math.pi / 8192                   # the table's step (as a float: for placing angles)


def cos_sin_errors(angles):
    """Largest |error| of cos and sin of each angle against mpmath at 60 digits."""
    (c_hi, c_lo), (s_hi, s_lo) = compensated.cos_sin(angles)
    errors = np.empty(len(angles))
    with mp.workdps(60):
        for k, angle in enumerate(angles):
            x = mp.mpf(float(angle))
            errors[k] = max(abs(mp.mpf(float(c_hi[k])) + mp.mpf(float(c_lo[k])) - mp.cos(x)),
                            abs(mp.mpf(float(s_hi[k])) + mp.mpf(float(s_lo[k])) - mp.sin(x)))
    return errors


def neighbours(values, ulps=2):
    """Return the values and the floats up to ``ulps`` steps either side of each."""
    values = np.asarray(values, dtype=float)
    out = [values]
    up, down = values.copy(), values.copy()
    for _ in range(ulps):
        up, down = np.nextafter(up, np.inf), np.nextafter(down, -np.inf)
        out += [up, down]
    return np.concatenate(out)


def hard_angles():
    k = np.arange(-40, 41)
    j = np.arange(-300, 301)
    return np.concatenate([
        neighbours(k * (math.pi / 2)),                   # cos or sin crosses zero
        neighbours(j * STEP),                            # on a table point: r ~ 0
        neighbours((j + 0.5) * STEP),                    # half-way: |r| = h/2, index flips
        neighbours(np.arange(8100, 8300) * STEP),        # around pi: the index wraps
        neighbours([402.1, 402.15, -402.12, 2.0 ** 31, -(2.0 ** 31), 2.0 ** 30, 1e9, -1e9]),
        [0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e-200, 1e-20, 1e-9, 2.0 ** -26],
        # beyond the split constants: reduced in integers
        [1e12, -3.3e15, 1e18, 2.0 ** 60, 1e100, 1e300, 1.7976931348623157e308,
         6381956970095103 * 2.0 ** 797],            # the double nearest a multiple of pi/2
    ])


def random_angles():
    rng = np.random.default_rng(11)
    magnitude = 10.0 ** rng.uniform(-12, 9, 1500) * rng.choice([-1.0, 1.0], 1500)
    return np.concatenate([rng.uniform(-7, 7, 1500), rng.uniform(-402, 402, 500),
                           rng.uniform(-1e9, 1e9, 500), magnitude])


def test_cos_sin_random_angles_to_6e_32():
    errors = cos_sin_errors(random_angles())
    assert errors.max() < 6e-32             # measured 2.2e-32 (4000 angles, 1e-12 to 1e9)


def test_cos_sin_hard_angles_to_6e_32():
    angles = hard_angles()
    errors = cos_sin_errors(angles)
    assert errors.max() < 6e-32             # measured 3.4e-32 over 7472 angles
    # The paths meet without a seam: every angle near a limit is as good as the rest.
    tiny = (angles != 0) & (np.abs(angles) < 1e-8)
    (_, _), (s_hi, s_lo) = compensated.cos_sin(angles[tiny])
    with mp.workdps(60):
        for angle, hi, lo in zip(angles[tiny], s_hi, s_lo):
            exact = mp.sin(mp.mpf(float(angle)))
            # sin x = x: relative error, down to the smallest subnormal (measured 0)
            assert abs((mp.mpf(float(hi)) + mp.mpf(float(lo))) / exact - 1) < 1e-31


def test_cos_sin_at_half_steps_of_every_scale_to_4e_32():
    """The largest remainders, |r| = h/2, at angles up to 2e9 rad: the documented ~4e-32."""
    rng = np.random.default_rng(21)
    angles = np.concatenate([(np.floor(rng.uniform(1e3, 2e9, 600) / STEP) + 0.5) * STEP,
                             (np.arange(-500, 500) + 0.5) * STEP])
    assert cos_sin_errors(angles).max() < 4e-32      # measured 3.3e-32


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=8))
def test_cos_sin_any_finite_double(angles):
    assert cos_sin_errors(np.array(angles)).max() < 6e-32


def test_cos_sin_of_nan_and_infinity_is_nan():
    (c, c_lo), (s, s_lo) = compensated.cos_sin([np.nan, np.inf, -np.inf, 1.0])
    assert np.isnan(c[:3]).all() and np.isnan(s[:3]).all()
    assert abs(c[3] - math.cos(1.0)) < 1e-16


def test_cos_sin_is_normalised_and_keeps_the_shape():
    angles = random_angles().reshape(2, -1)
    (c, c_lo), (s, s_lo) = compensated.cos_sin(angles)
    assert c.shape == s_lo.shape == angles.shape
    for hi, lo in ((c, c_lo), (s, s_lo)):
        assert np.all(np.abs(lo) <= np.spacing(np.abs(hi)) / 2)
        assert np.all(hi == hi + lo)


def test_the_table_entry_by_entry():
    tables = compensated._tables()
    worst = 0
    with mp.workdps(60):
        for j in range(0, 16384, 3):
            angle = mp.pi * j / 8192
            worst = max(worst,
                        abs(mp.mpf(tables.cos_hi[j]) + mp.mpf(tables.cos_lo[j]) - mp.cos(angle)),
                        abs(mp.mpf(tables.sin_hi[j]) + mp.mpf(tables.sin_lo[j]) - mp.sin(angle)))
    assert worst < 4e-33                    # measured 3.1e-33: the double-double's rounding
    # Quarter turns exact: cos(pi/2) is 0, not ~1e-17.
    assert tables.cos_hi[4096] == tables.cos_lo[4096] == 0.0 == tables.sin_hi[0]
    assert tables.sin_hi[4096] == 1.0 and tables.cos_hi[8192] == -1.0


def test_total_of_terms_that_cancel_is_correctly_rounded():
    rng = np.random.default_rng(12)
    hi = rng.normal(size=70001) * 10.0 ** rng.integers(-20, 20, 70001)
    hi = np.concatenate([hi, -hi[:-1] * (1 + 2.0 ** -40)])      # cancels to ~2^-40 of it
    lo = hi * 2.0 ** -60 * rng.normal(size=hi.size)
    exact = sum(map(Fraction, hi)) + sum(map(Fraction, lo))
    assert compensated.total((hi, lo)) == float(exact)          # measured: exact
    assert compensated.total((hi[:0], lo[:0])) == 0.0
    huge = np.array([1e300, 1.0, -1e300])                        # beyond the extraction
    assert compensated.total((huge, np.zeros(3))) == 1.0


# --- Aggregates of large layouts, against sums done exactly.

def exact_layout(seed, groups, per_group, angle_of_group):
    """
    Dyadic components on a few angles, each group mirrored by one half a turn away.

    Masses k/64 kg, R and z k/1024 m, own tensor elements k/2^20 kg m^2 (products of
    inertia too): every aggregate is a sum over groups of integers times 60-digit
    cos, sin, cos^2, sin^2 or cos sin of the group's angle. Returns place()'s arrays,
    the exact aggregates (mass, S, the 3x3 tensor of elements) and each one's sum of
    |terms|.
    """
    rng = np.random.default_rng(seed)
    half = groups * per_group
    group = np.repeat(np.arange(groups), per_group)
    k_m = rng.integers(1, 3840, half)
    k_r = rng.integers(0, 800, half)
    k_z = rng.integers(-300, 300, half)
    k_own = rng.integers(-2000, 2000, (half, 6))
    k_own[:, :3] = rng.integers(0, 60000, (half, 3))          # the diagonal
    # The mirror: the same components half a turn away (as floats: not exactly).
    group = np.concatenate([group, group + groups])
    k_m, k_r, k_z, k_own = (np.concatenate([v, v]) for v in (k_m, k_r, k_z, k_own))
    angles = np.concatenate([angle_of_group, angle_of_group + math.pi])

    def per(values):
        return [sum(int(v) for v in values[group == g]) for g in range(2 * groups)]

    m_r, m_rz, m_rr = per(k_m * k_r), per(k_m * k_r * k_z), per(k_m * k_r * k_r)
    o = [per(k_own[:, i]) for i in range(6)]                 # xx yy zz xy xz yz
    scale_m, scale_l, scale_o = Fraction(1, 64), Fraction(1, 1024), Fraction(1, 1 << 20)
    with mp.workdps(60):
        c = [mp.cos(mp.mpf(float(a))) for a in angles]
        s = [mp.sin(mp.mpf(float(a))) for a in angles]

        def total(weights, trig):
            return mp.fsum(mp.mpf(w) * t for w, t in zip(weights, trig))

        def rational(value):
            return mp.mpf(value.numerator) / value.denominator

        mr_f, mrz_f, mrr_f = (rational(scale_m * scale_l ** k) for k in (1, 2, 2))
        of = rational(scale_o)
        cc = [x * x for x in c]
        ss = [x * x for x in s]
        cs = [x * y for x, y in zip(c, s)]
        mzz = rational(sum(Fraction(int(a * b * b)) for a, b in zip(k_m, k_z)) * scale_m
                       * scale_l ** 2)
        exact = {
            'mass': rational(int(k_m.sum()) * scale_m),
            's_x': total(m_r, c) * mr_f, 's_y': total(m_r, s) * mr_f,
            's_z': rational(int((k_m * k_z).sum()) * scale_m * scale_l),
            'i_xx': total(m_rr, ss) * mrr_f + mzz
            + (total(o[0], cc) + total(o[1], ss) - 2 * total(o[3], cs)) * of,
            'i_yy': total(m_rr, cc) * mrr_f + mzz
            + (total(o[0], ss) + total(o[1], cc) + 2 * total(o[3], cs)) * of,
            'i_zz': rational(sum(Fraction(int(v)) for v in k_m * k_r * k_r) * scale_m
                             * scale_l ** 2) + mp.mpf(int(k_own[:, 2].sum())) * of,
            'i_xy': -total(m_rr, cs) * mrr_f
            + (total(o[0], cs) - total(o[1], cs) + total(o[3], cc)
               - total(o[3], ss)) * of,
            'i_xz': -total(m_rz, c) * mrr_f + (total(o[4], c) - total(o[5], s)) * of,
            'i_yz': -total(m_rz, s) * mrr_f + (total(o[4], s) + total(o[5], c)) * of,
        }
    # Sum of |terms| of each aggregate (|cos|, |sin| <= 1): what its rounding scales with.
    o_abs = np.abs(k_own).sum(axis=0) / 2.0 ** 20
    m_r, m_rr = float((k_m * k_r).sum()) / 2 ** 16, float((k_m * k_r * k_r).sum()) / 2 ** 26
    m_rz, m_zz = float(np.abs(k_m * k_r * k_z).sum()) / 2 ** 26, float(mzz)
    magnitude = {'mass': float(exact['mass']), 's_x': m_r, 's_y': m_r,
                 's_z': float(np.abs(k_m * k_z).sum()) / 2 ** 16,
                 'i_xx': m_rr + m_zz + o_abs[0] + o_abs[1] + 2 * o_abs[3],
                 'i_yy': m_rr + m_zz + o_abs[0] + o_abs[1] + 2 * o_abs[3],
                 'i_zz': m_rr + o_abs[2], 'i_xy': m_rr + o_abs[0] + o_abs[1] + 2 * o_abs[3],
                 'i_xz': m_rz + o_abs[4] + o_abs[5], 'i_yz': m_rz + o_abs[4] + o_abs[5]}
    own = np.zeros((k_m.size, 3, 3))
    places = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    for value, (i, j) in zip(k_own.T / 2.0 ** 20, places):
        own[:, i, j] = own[:, j, i] = value
    arrays = (k_m / 64.0, own, k_r / 1024.0, angles[group], k_z / 1024.0)
    return arrays, exact, magnitude


def aggregate_errors(arrays, exact, magnitude):
    """
    Each aggregate's |got - exact| in ulps of the exact value, and over its sum of |terms|.

    Rounded to a float, an exact sum is within half an ulp; summed to ~2^-100 of its
    sum of |terms| first, an aggregate that cancels below ~1e-14 of its terms may be
    off by more ulps of itself, never by more than ~1e-30 of its terms.
    """
    body = place(*arrays)
    got = {'mass': body.mass, 's_x': body.first_moment[0], 's_y': body.first_moment[1],
           's_z': body.first_moment[2], 'i_xx': body.inertia[0, 0],
           'i_yy': body.inertia[1, 1], 'i_zz': body.inertia[2, 2],
           'i_xy': body.inertia[0, 1], 'i_xz': body.inertia[0, 2], 'i_yz': body.inertia[1, 2]}
    ulps, relative = {}, {}
    with mp.workdps(60):
        for name, want in exact.items():
            error = abs(mp.mpf(float(got[name])) - want)
            ulps[name] = float(error / np.spacing(abs(float(want))))
            relative[name] = float(error / magnitude[name])
    return ulps, relative


@pytest.mark.parametrize('reduction', ['split', 'general', 'integer'])
def test_large_layouts_every_aggregate_is_its_exact_value_rounded(reduction):
    """
    49,152 components (three blocks: both worker threads), 24 angles.

    The mirrored groups cancel the first moments and products to ~1e-17 of sum |terms|
    (the angles theta and fl(theta + pi) are not exactly half a turn apart); each
    aggregate must still be its exact value rounded, unless it cancels so far that
    the ~2^-100 of its terms the double-double sum keeps is more than half an ulp.
    """
    rng = np.random.default_rng(13)
    angle = {'split': rng.uniform(-7, 7, 12),
             'general': rng.uniform(-1e9, 1e9, 12),
             'integer': np.concatenate([rng.uniform(-7, 7, 11), [3.0e12]])}[reduction]
    angle[:3] = [0.0, math.pi / 2, 100.5 * STEP]
    arrays, exact, magnitude = exact_layout(14, 12, 2048, angle)
    assert arrays[0].size == 49152
    ulps, relative = aggregate_errors(arrays, exact, magnitude)
    # Measured: correctly rounded (<= 0.5 ulp), but for aggregates that cancel beyond
    # 1e-17 of their terms (split case: S_x 1.9 ulps, I_xz 1.3, I_yz 3.8, cancelled to
    # 4e-18, 3e-19, 9e-20), which stay within 1.4e-33 of their sum of |terms|.
    for name in exact:
        assert ulps[name] <= 0.5 or relative[name] < 1e-32, (name, ulps, relative)
    if reduction == 'split':
        # What float64 sums give here (numpy's pairwise): S_y (8e-12 kg m) is lost.
        mass, _, radius, angle, _ = arrays
        naive = float(np.sum(mass * radius * np.sin(angle)))
        assert abs(naive - float(exact['s_y'])) >= 0.5 * abs(float(exact['s_y']))  # naive: 0


def test_small_layouts_and_edge_cases():
    empty = place([], None, [], [], [])
    assert empty.mass == 0.0 and not empty.first_moment.any() and not empty.inertia.any()
    one = place(2.0, np.diag([1.0, 2.0, 3.0]), 0.5, 0.3, 0.1)
    # One body: the parallel-axis theorem by hand, own frame turned by 0.3 rad (mpmath).
    with mp.workdps(40):
        c, s = mp.cos(0.3), mp.sin(0.3)
        turn = mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        r = mp.matrix([mp.mpf(0.5) * c, mp.mpf(0.5) * s, mp.mpf(0.1)])
        shift = 2 * ((r.T * r)[0] * mp.eye(3) - r * r.T)
        want = turn * mp.diag([1, 2, 3]) * turn.T + shift
        for i in range(3):
            assert abs(one.first_moment[i] - 2 * r[i]) <= 1e-16 * abs(2 * r[i])
            for j in range(3):
                assert abs(one.inertia[i, j] - want[i, j]) <= 2.3e-16 * abs(want[i, j])
    assert np.isnan(place([1.0, np.nan], None, [0.5, 0.2], [0.1, 0.2], [0.0, 0.1]).mass)


def exact_place(mass, own, radius, angle, z):
    """mass, S and the tensor of elements, term by term in 40-digit mpmath."""
    with mp.workdps(40):
        total_mass, first, tensor = mp.mpf(0), [mp.mpf(0)] * 3, mp.zeros(3, 3)
        for k in range(len(mass)):
            m, c, s = mp.mpf(mass[k]), mp.cos(mp.mpf(angle[k])), mp.sin(mp.mpf(angle[k]))
            r = [mp.mpf(radius[k]) * c, mp.mpf(radius[k]) * s, mp.mpf(z[k])]
            turn = mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            inertia = (turn * mp.matrix(own[k].tolist()) * turn.T if own is not None
                       else mp.zeros(3, 3))
            total_mass += m
            for i in range(3):
                first[i] += m * r[i]
                for j in range(3):
                    inertia[i, j] += m * ((r[0] ** 2 + r[1] ** 2 + r[2] ** 2 if i == j else 0)
                                          - r[i] * r[j])
            tensor += inertia
        return total_mass, first, tensor


def test_many_layouts_in_a_row_each_rounded_right():
    """
    Aggregate layouts of 28 sizes and three kinds, each size twice, in a row.

    Layouts of 28 sizes and three kinds one after another, each size twice (blocks
    of many lengths, their arrays and programs made, dropped and made again), each
    against a 40-digit sum term by term.
    """
    rng = np.random.default_rng(15)
    sizes = np.concatenate([np.arange(1, 26), [100, 300, 1000]])
    for n in np.concatenate([rng.permutation(sizes), rng.permutation(sizes)]):
        kind = ('points', 'shapes', 'products')[n % 3]
        mass, radius = rng.uniform(0.1, 60, n), rng.uniform(0, 0.8, n)
        angle, z = rng.uniform(-7, 7, n), rng.uniform(-0.3, 0.3, n)
        own = None
        if kind != 'points':
            own = np.zeros((n, 3, 3))
            own[:, [0, 1, 2], [0, 1, 2]] = rng.uniform(0.01, 2, (n, 3))
            if kind == 'products':
                for i, j in ((0, 1), (0, 2), (1, 2)):
                    own[:, i, j] = own[:, j, i] = rng.uniform(-0.005, 0.005, n)
        body = place(mass, own, radius, angle, z)
        want_mass, want_first, want_tensor = exact_place(mass, own, radius, angle, z)
        got = [body.mass, *body.first_moment, *body.inertia.ravel()]
        want = [want_mass, *want_first, *(want_tensor[i, j] for i in range(3)
                                          for j in range(3))]
        for value, exact in zip(got, want):
            # Correctly rounded: within half an ulp (measured: all).
            assert abs(mp.mpf(float(value)) - exact) <= np.spacing(abs(float(exact))) / 2, \
                (n, kind)


def test_aggregations_at_once_from_any_threads_agree_bit_for_bit():
    """
    Aggregate in the pool's threads and others at once: the same bits as alone.

    Layouts aggregated off the input path run in workers.pool()'s threads: place() must
    not wait there for the pool (both busy: for ever), nor mix threads' arrays.
    """
    from concurrent.futures import ThreadPoolExecutor
    from cvc_balance.physics.workers import pool
    rng = np.random.default_rng(16)
    layouts = []
    for n in (70_000, 50_001):                      # several blocks: threaded when it may
        own = np.zeros((n, 3, 3))
        own[:, [0, 1, 2], [0, 1, 2]] = rng.uniform(0.01, 2, (n, 3))
        layouts.append((rng.uniform(1, 2, n), own, rng.uniform(0, 1, n),
                        rng.uniform(-1e3, 1e3, n), rng.uniform(-1, 1, n)))
    alone = [place(*layout) for layout in layouts]
    with ThreadPoolExecutor(2) as others:
        jobs = [executor.submit(place, *layouts[k % 2]) for k in range(8)
                for executor in (pool(), others)]
        for k, job in enumerate(jobs):
            got, want = job.result(timeout=120), alone[(k // 2) % 2]
            assert got.mass == want.mass
            assert np.array_equal(got.first_moment, want.first_moment)
            assert np.array_equal(got.inertia, want.inertia)
