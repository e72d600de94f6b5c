"""
Double-double arithmetic and its program tracer against exact rational arithmetic.

Every result of :mod:`cvc_balance.physics.compensated` is compared with Python's
``fractions.Fraction`` (exact sums and products of the float64 inputs): the scalar
double-double operations (two-sum, two-product, add, mul, scale, negate), the power of two
above a value, the exactly rounded total (also where its cut would overflow), and a
program recorded with the :class:`Tracer` (every operator, views, rows reused by liveness)
against the same numpy expressions evaluated directly.
"""

from fractions import Fraction
import math

import numpy as np
import pytest

from cvc_balance.physics import compensated as dd


def exact(*parts):
    """Return the exact rational sum of float64 values."""
    return sum((Fraction(float(p)) for p in parts), Fraction(0))


def double_doubles(rng, count, spread=30):
    """Return ``count`` normalised double-doubles (hi, lo): hi random, |lo| <= ulp(hi) / 2."""
    hi = rng.normal(size=count) * np.exp2(rng.integers(-spread, spread, count))
    lo = hi * rng.uniform(-1, 1, count) * 2.0 ** -54
    return [(float(h), float(h2)) for h, h2 in zip(hi, lo)]


def test_error_free_transformations_are_exact():
    rng = np.random.default_rng(1)
    values = rng.normal(size=400) * np.exp2(rng.integers(-40, 40, 400))
    for a, b in zip(values[::2], values[1::2]):
        s, e = dd.two_sum(a, b)
        assert s == a + b and exact(s, e) == exact(a, b)
        p, e = dd.two_prod(a, b)
        assert p == a * b and Fraction(p) + Fraction(e) == Fraction(a) * Fraction(b)
        hi, lo = dd.split(a)
        assert exact(hi, lo) == Fraction(a)
        assert all(math.frexp(part)[0] * 2 ** 26 == int(math.frexp(part)[0] * 2 ** 26)
                   for part in (hi, lo) if part)             # at most 26 bits each
        big, small = (a, b) if abs(a) >= abs(b) else (b, a)
        s, e = dd._quick_two_sum(big, small)
        assert s == big + small and exact(s, e) == exact(big, small)


def test_double_double_add_mul_scale_negate_to_2_to_the_minus_100():
    """Each within 2^-100 of the exact result's size, and normalised (hi = fl(hi + lo))."""
    rng = np.random.default_rng(2)
    xs, ys = double_doubles(rng, 300), double_doubles(rng, 300)
    floats = rng.normal(size=300) * np.exp2(rng.integers(-20, 20, 300))
    for x, y, b in zip(xs, ys, floats):
        fx, fy = exact(*x), exact(*y)
        results = [(dd.add(x, y), fx + fy, abs(fx) + abs(fy)),
                   (dd.mul(x, y), fx * fy, abs(fx * fy)),
                   (dd.scale(x, float(b)), fx * Fraction(float(b)), abs(fx * Fraction(float(b))))]
        for (hi, lo), want, size in results:
            assert abs(exact(hi, lo) - want) <= size * Fraction(1, 2 ** 100), (x, y, b)
            assert hi == hi + lo
        assert dd.negate(x) == (-x[0], -x[1])
    # Cancellation: the sum of x and nearly -x keeps the difference of the low parts.
    x = (1.0, 2.0 ** -60)
    y = (-1.0, 2.0 ** -70)
    assert exact(*dd.add(x, y)) == Fraction(1, 2 ** 60) + Fraction(1, 2 ** 70)


@pytest.mark.parametrize('value, want', [
    (0.0, 0.0), (-3.0, 0.0), (1.0, 1.0), (0.75, 1.0), (0.5, 0.5), (3.0, 4.0), (4.0, 4.0),
    (4.000000000000001, 8.0), (5e-324, 5e-324), (1e300, 2.0 ** 997), (2.0 ** 1023, 2.0 ** 1023),
    (1.5e308, math.inf)])
def test_power_of_two_above(value, want):
    assert dd.power_of_two_above(value) == want
    if 0 < value and want < math.inf:
        assert Fraction(want) >= Fraction(value) > Fraction(want) / 2


def test_total_is_the_exact_sum_rounded_once_even_near_the_largest_float():
    """Where sigma = 2^64 of the bound would overflow the sum goes another way: also exact."""
    rng = np.random.default_rng(3)
    for scale in (1.0, 1e-300, 1e290, 2.0 ** 1015, 1e307):    # 2^1015: sigma of 2^13 the bound
        hi = rng.normal(size=5000) * scale / 8
        hi[::2] = -hi[1::2] * (1 + 2.0 ** -40)           # pairs that nearly cancel
        lo = hi * 2.0 ** -60 * rng.uniform(-1, 1, hi.size)
        want = float(exact(*hi, *lo))
        assert dd.total((hi, lo)) == want, scale
        assert dd.total((list(hi), list(lo))) == want        # lists as arrays
    assert dd.total((np.zeros(0), np.zeros(0))) == 0.0
    # Terms beyond 2^1023 (their power of two above is not a float): raised OverflowError.
    assert dd.total(([1.5e308, -1.5e308, 3.0], [0.0, 0.0, 1e-20])) == 3.0


def test_sigma_for_is_the_documented_cut():
    """The cut: sigma = 2^ceil(log2(n + 2)) bound, then 2^-53 of the gain lower a level."""
    got = dd.sigma_for(1000, [4.0, 0.5], 3)
    gain = 1024.0                                            # 2^10 >= 1002
    want = np.array([[gain * 4.0 * (gain * 2.0 ** -53) ** k for k in range(3)],
                     [gain * 0.5 * (gain * 2.0 ** -53) ** k for k in range(3)]])
    assert np.array_equal(got, want)
    assert dd.sigma_for(1022, [1.0], 1)[0, 0] == 1024.0 and \
        dd.sigma_for(1023, [1.0], 1)[0, 0] == 2048.0


def test_a_traced_program_with_every_operator_equals_numpy_directly():
    """Every operator of Ref, in place and swapped, views, int64 bits; rows reused by liveness."""
    t = dd.Tracer()
    x, y = t.external('x'), t.external('y')
    pair = t.external('pair', 2)
    out = t.external('out', 2)
    a = x + y                        # add
    b = 2.0 + a                      # radd
    c = b - x                        # sub
    d = 10.0 - c                     # rsub
    e = d * y                        # mul
    f = 3.0 * e                      # rmul
    g = -f                           # neg
    g += x                           # iadd
    g -= y                           # isub
    g *= 0.5                         # imul
    h = pair[0] * pair[1] + g        # rows of a stacked array
    t.call(np.add, h, pair[1], out[0])
    wide = pair + g                  # (2, n) + (n,): two rows
    t.call(np.multiply, wide[1], 1.0, out[1])
    other = t.external('other', 2)
    for value in (g, other[0]):      # a new array; another array's row at the same place
        with pytest.raises(TypeError) as refused:
            pair[0] = value
        assert str(refused.value) == 'assign to a traced array with Tracer.call'
    program = t.compile()
    # Temporaries that are dead are reused: never more rows than are live at once.
    assert program.total_rows == 3, program.total_rows
    rng = np.random.default_rng(4)
    arrays = {'x': rng.normal(size=7), 'y': rng.normal(size=7), 'pair': rng.normal(size=(2, 7)),
              'out': np.empty((2, 7))}
    program.bind(7, arrays)()
    x_, y_, p_ = arrays['x'], arrays['y'], arrays['pair']
    g_ = (-(3.0 * ((10.0 - ((2.0 + (x_ + y_)) - x_)) * y_)) + x_ - y_) * 0.5
    assert np.array_equal(arrays['out'][0], p_[0] * p_[1] + g_ + p_[1])
    assert np.array_equal(arrays['out'][1], p_[1] + g_)


def test_the_tracers_views_and_bits():
    """A row, a slice of rows, a new axis and the int64 view resolve to numpy's views."""
    t = dd.Tracer()
    stack = t.external('stack', 3)
    assert stack[0].rows is None and stack[1:3].rows == 2 and stack[None].rows == 1
    assert stack[0:3:2].rows == 2 and stack[(slice(0, 2), 0)].rows == 2
    assert stack[1:3].bits().rows == 2 and stack[1:3].bits().path == (slice(1, 3), 'int')
    bits = stack[2].bits()
    assert bits.path == (2, 'int') and bits.rows is None and bits.tracer is t
    ones = t.external('ones')
    t.call(np.add, bits, 1, ones.bits())
    t.call(np.copyto, stack[0], stack[1:3][1])
    program = t.compile()
    arrays = {'stack': np.array([[0.0, 0.0], [1.0, 2.0], [1.0, -2.0]]), 'ones': np.empty(2)}
    program.bind(2, arrays)()
    assert np.array_equal(arrays['ones'], np.nextafter([1.0, -2.0], [np.inf, -np.inf]))
    assert np.array_equal(arrays['stack'][0], [1.0, -2.0])


def test_cos_sin_program_cache_keeps_the_eight_latest_block_sizes():
    """Each block length binds its own arrays; the cache holds the 8 most recent."""
    cache = {}
    made = []

    def program():
        made.append(1)
        return dd._cos_sin_program(True)
    for n in range(1, 11):
        dd.bound(cache, (True, n), program)
    assert [key[1] for key in cache] == list(range(3, 11)) and len(made) == 10
    dd.bound(cache, (True, 5), program)                   # a hit: no new binding
    assert len(made) == 10 and list(cache)[-1] == (True, 5)
    for angles in (np.array([0.3, -2.0, 1e6]), np.array([[0.1, 7.0], [400.0, 5e9]])):
        (c_hi, c_lo), (s_hi, s_lo) = dd.cos_sin(angles)
        assert c_hi.shape == s_hi.shape == angles.shape
        assert np.array_equal(c_hi, np.cos(angles)) or \
            np.max(np.abs(c_hi - np.cos(angles))) <= 2.3e-16
        assert np.max(np.abs(s_hi - np.sin(angles))) <= 2.3e-16


def test_cos_sin_of_more_than_a_block_is_each_angles_own():
    """Angles over several blocks (and a short last one), fast and general, as one at a time."""
    rng = np.random.default_rng(5)
    angles = np.concatenate([rng.uniform(-400.0, 400.0, 2 * dd.BLOCK + 7),
                             rng.uniform(-3e9, 3e9, 5)])
    (c_hi, c_lo), (s_hi, s_lo) = dd.cos_sin(angles)
    for k in list(range(0, angles.size, 997)) + [angles.size - 6, angles.size - 1]:
        (c1, c1_lo), (s1, s1_lo) = dd.cos_sin(angles[k:k + 1])
        assert (c_hi[k], c_lo[k], s_hi[k], s_lo[k]) == (c1[0], c1_lo[0], s1[0], s1_lo[0]), k
    assert np.max(np.abs(c_hi - np.cos(angles))) <= 2.3e-16
    assert np.max(np.abs(s_hi - np.sin(angles))) <= 2.3e-16


def significant_bits(value):
    """Return the number of significant bits of a float (0 for 0)."""
    numerator = abs(Fraction(float(value)).numerator)
    while numerator and not numerator % 2:
        numerator //= 2
    return numerator.bit_length()


def test_double_double_add_where_the_high_parts_cancel_is_exact_to_3_u_squared():
    """
    Keep the low parts' exact sum where the high parts cancel.

    The add is Joldes, Muller and Popescu's AccurateDWPlusDW (2017), relative error at most
    3 u^2 / (1 - 4 u), u = 2^-53, of the result itself, however much x and y cancel.
    """
    x, y = (1.0, 2.0 ** -60), (-1.0, 3.0 * 2.0 ** -115)     # 2^-60 + 3 2^-115: 56 bits
    assert exact(*dd.add(x, y)) == Fraction(1, 2 ** 60) + Fraction(3, 2 ** 115)
    rng = np.random.default_rng(6)
    u = Fraction(1, 2 ** 53)
    for x in double_doubles(rng, 300):       # y = (-x_hi, a normalised low part of its own)
        y = (-x[0], x[0] * float(rng.uniform(-1, 1)) * 2.0 ** -float(rng.integers(54, 114)))
        want = exact(*x) + exact(*y)
        assert abs(exact(*dd.add(x, y)) - want) <= 3 * u * u / (1 - 4 * u) * abs(want), (x, y)


def test_a_one_row_array_and_a_flat_one_make_one_row():
    """(1, n) with (n,) gives (1, n), as numpy's broadcasting does, in one row."""
    t = dd.Tracer()
    x, one, out = t.external('x'), t.external('one', 1), t.external('out', 1)
    total = one + x
    assert total.rows == 1
    t.call(np.copyto, out, total * x)
    program = t.compile()
    arrays = {'x': np.array([1.0, 2.0, -3.0]), 'one': np.array([[0.5, 0.25, 4.0]]),
              'out': np.empty((1, 3))}
    program.bind(3, arrays)()
    assert arrays['out'].tolist() == [[1.5, 4.5, -3.0]]         # (0.5 + 1) 1, (0.25 + 2) 2, 1 (-3)


def test_the_traced_split_and_two_product_are_exact():
    """Halves of at most 26 significant bits adding up to the value; a b = p + e (Fraction)."""
    t = dd.Tracer()
    a, b = t.external('a'), t.external('b')
    a_parts, b_parts = dd.trace_split(t, a), dd.trace_split(t, b)
    p, e = dd.trace_two_prod(t, a, a_parts, b, b_parts)
    names = ('hi', 'lo', 'p', 'e')
    for name, ref in zip(names, (*a_parts, p, e)):
        t.call(np.copyto, t.external(name), ref)
    rng = np.random.default_rng(7)
    n = 2000
    arrays = {'a': rng.normal(size=n) * np.exp2(rng.integers(-300, 300, n)),
              'b': rng.normal(size=n) * np.exp2(rng.integers(-300, 300, n)),
              **{name: np.empty(n) for name in names}}
    arrays['a'][:4] = [1.0, -3.0, 2.0 ** 27 - 1.0, 0.0]     # the last: 27 bits, rounded up
    t.compile().bind(n, arrays)()
    for k in range(n):
        a_k, b_k, hi, lo, p_k, e_k = (float(arrays[name][k]) for name in ('a', 'b') + names)
        assert Fraction(hi) + Fraction(lo) == Fraction(a_k), k
        assert significant_bits(hi) <= 26 and significant_bits(lo) <= 26, (k, hi, lo)
        assert p_k == a_k * b_k and Fraction(p_k) + Fraction(e_k) == Fraction(a_k) * Fraction(b_k)
