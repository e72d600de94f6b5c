"""
Double-double arithmetic on numpy arrays: sums and products that keep ~32 digits.

A double-double is a pair (hi, lo) of float64 arrays whose exact sum is the value,
|lo| small against |hi| (about ulp(hi), not always normalised inside a computation).
The layout's aggregates are summed this way so that a rotor balanced to 1e-9 of its
mass moment keeps the residual's digits: summed in float64, each term's rounding
(1e-16 of a term) would be 1e-7 of such a residual.

The error-free transformations are Knuth's two-sum and Dekker's two-product (with
Veltkamp's split: numpy has no fused multiply-add). Sums of many terms are exact:
Rump's extraction cuts each term at a power of two chosen so that the pieces above it
add without rounding (:func:`partial_sums_into`), and the few partial sums are rounded once
by ``math.fsum``. cos and sin of a float64 angle come from a table of cos and sin at
multiples of h = pi/8192 (double-double, made from integer arithmetic on first use)
and short polynomials in the remainder |r| <= h/2 where only r, r^2/2 and r^3/6 need
exact products; the reduction by h is exact for every finite angle (split constants
up to 2^31 rad, integer arithmetic beyond). numpy and the standard library only.
"""

from fractions import Fraction
import math
import threading

import numpy as np

_SPLITTER = 134217729.0            # 2^27 + 1: splits a float64 into two 26-bit halves
_MAGIC = 6755399441055744.0        # 1.5 * 2^52: x + _MAGIC rounds x to an integer
_HIGH_BITS = -(1 << 27)            # sign, exponent and the top 25 stored bits of a float64

_QUADRANT = 4096                   # table points per quarter turn
_TABLE_SIZE = 4 * _QUADRANT        # one turn; indices are taken mod this (a power of 2)
_FIXED_BITS = 320                  # fixed-point bits of the table's integer arithmetic
_FAST_INDEX = 2 ** 20              # |angle / h| below this: reduced by h directly
_GENERAL_LIMIT = 2.0 ** 31         # |angle| below this: 2 pi taken off first, split
_BIG_BITS = 1400                   # fixed-point bits of the integer reduction beyond


def two_sum(a, b):
    """Return (s, e) with s = fl(a + b) and s + e = a + b exactly."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _quick_two_sum(a, b):
    # Needs |a| >= |b| (or a = 0).
    s = a + b
    return s, b - (s - a)


def split(a):
    """Veltkamp's split: (hi, lo) = a exactly, each with at most 26 significant bits."""
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


def two_prod_split(a, a_parts, b, b_parts):
    """
    Return (p, e) with p = fl(a b) and p + e = a b exactly, from split factors.

    ``a_parts`` = :func:`split` (a): a value used in several products is split once.
    """
    a_hi, a_lo = a_parts
    b_hi, b_lo = b_parts
    p = a * b
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


def two_prod(a, b):
    """Return (p, e) with p = fl(a b) and p + e = a b exactly (no overflow assumed)."""
    return two_prod_split(a, split(a), b, split(b))


def add(x, y):
    """Sum of two double-doubles (relative error ~1e-32)."""
    s, e = two_sum(x[0], y[0])
    t, f = two_sum(x[1], y[1])
    s, e = _quick_two_sum(s, e + t)
    return _quick_two_sum(s, e + f)


def mul(x, y):
    """Product of two double-doubles."""
    p, e = two_prod(x[0], y[0])
    return _quick_two_sum(p, e + (x[0] * y[1] + x[1] * y[0]))


def scale(x, b):
    """Product of a double-double and a float64 (array)."""
    p, e = two_prod(x[0], b)
    return _quick_two_sum(p, e + x[1] * b)


def negate(x):
    """Return -x."""
    return -x[0], -x[1]


def power_of_two_above(value):
    """Smallest power of two >= ``value`` (a float >= 0; 0 gives 0)."""
    if value <= 0.0:
        return 0.0
    mantissa, exponent = math.frexp(value)
    return math.ldexp(1.0, exponent - 1 if mantissa == 0.5 else exponent)


def total(x):
    """
    Sum of a 1-D double-double array, rounded to one float.

    Exact to ~2^-100 of sum |terms| whatever the number of terms (see
    :func:`partial_sums_into`), then correctly rounded by ``math.fsum``.
    """
    hi = np.array(x[0], dtype=float).ravel()
    lo = np.array(x[1], dtype=float).ravel()
    if not hi.size:
        return 0.0
    bound = power_of_two_above(float(np.max(np.abs(hi))))
    if not bound * 2.0 ** 64 < math.inf:            # sigma would overflow: rare, slow
        return math.fsum(np.concatenate([hi, lo]).tolist())
    sums = []
    for start in range(0, hi.size, BLOCK):
        stop = min(start + BLOCK, hi.size)
        rows = hi[None, start:stop], lo[None, start:stop]
        sums += partial_sums_into(*rows, [bound], 2, np.empty_like(rows[0]),
                                  np.empty_like(rows[0]))[0].tolist()
    return math.fsum(sums)


# --- The table and the reduction constants, made once (integers: exact, no download).

def _atan_of_inverse(k, bits):
    """atan(1/k) * 2^bits, truncated (Gregory's series in integers)."""
    power = (1 << bits) // k
    result, n, sign = power, 1, -1
    while power:
        power //= k * k
        result += sign * (power // (2 * n + 1))
        n, sign = n + 1, -sign
    return result


def _pi_fixed(bits):
    """pi * 2^bits to within a few units (Machin's formula, 16 guard bits)."""
    guard = bits + 16
    return (4 * (4 * _atan_of_inverse(5, guard) - _atan_of_inverse(239, guard))) >> 16


def _double_double(value, bits):
    """(hi, lo) floats nearest value / 2^bits (an int): hi correctly rounded, then lo."""
    hi = value / (1 << bits)
    numerator, denominator = hi.as_integer_ratio()
    return hi, (value - (numerator << bits) // denominator) / (1 << bits)


def _parts(value, bits, count, width):
    """Floats, each of at most ``width`` significant bits but the last, adding up to value."""
    parts = []
    for _ in range(count - 1):
        shift = max(abs(value).bit_length() - width, 0)
        part = ((abs(value) + (1 << shift >> 1)) >> shift << shift) * (1 if value > 0 else -1)
        parts.append(Fraction(part, 1 << bits))
        value -= part
    parts.append(Fraction(value, 1 << bits))
    return tuple(float(p) for p in parts)


class _Tables:
    """cos and sin at j h (j mod 16384, h = pi/8192) as double-doubles, and split constants."""

    def __init__(self):
        bits, n = _FIXED_BITS, _QUADRANT
        pi = _pi_fixed(bits)
        step = pi // (2 * n)
        one = 1 << bits
        # cos h and sin h by their Taylor series, then the turn by j h by repeated rotation
        # up to pi/4 (error ~2^-300), the rest of the quarter by symmetry.
        cos_h, sin_h, term, k = one, 0, one, 1
        while term:
            term = term * step // (k << bits)
            if k % 2:
                sin_h += term if k % 4 == 1 else -term
            else:
                cos_h += term if k % 4 == 0 else -term
            k += 1
        cos_q, sin_q = [one], [0]
        for _ in range(n // 2):
            c, s = cos_q[-1], sin_q[-1]
            cos_q.append((c * cos_h - s * sin_h) >> bits)
            sin_q.append((s * cos_h + c * sin_h) >> bits)
        cos_q += sin_q[n // 2 - 1::-1]
        sin_q += cos_q[n // 2 - 1::-1]
        quarter = np.array([[*_double_double(c, bits), *_double_double(s, bits)]
                            for c, s in zip(cos_q[:n], sin_q[:n])]).T
        c_hi, c_lo, s_hi, s_lo = quarter
        # Quarter turns: (cos, sin)(x + pi/2) = (-sin, cos)(x).
        self.cos_hi = np.concatenate([c_hi, -s_hi, -c_hi, s_hi])
        self.cos_lo = np.concatenate([c_lo, -s_lo, -c_lo, s_lo])
        self.sin_hi = np.concatenate([s_hi, c_hi, -s_hi, -c_hi])
        self.sin_lo = np.concatenate([s_lo, c_lo, -s_lo, -c_lo])
        # h in three parts (32, 32, 53 bits): j h1 and j h2 exact for |j| < 2^20.
        self.inverse_step = float(Fraction(2 * n << bits, pi))
        self.step = _parts(step, bits, 3, 32)
        # 2 pi in six parts of 24 bits: k p_i exact for |k| < 2^29 (|angle| < 2^31).
        self.inverse_turn = float(Fraction(1 << bits, 2 * pi))
        self.turn = _parts(2 * pi, bits, 6, 24)
        self.fast_limit = (_FAST_INDEX - 1) * float(Fraction(step, 1 << bits))
        self._big = None

    def big_reduction(self):
        """pi/8192 * 2^_BIG_BITS for the integer reduction of huge angles, made on use."""
        if self._big is None:
            self._big = _pi_fixed(_BIG_BITS + 20) // (2 * _QUADRANT << 20)
        return self._big


_TABLES = []
_TABLES_LOCK = threading.Lock()


def _tables():
    if not _TABLES:
        with _TABLES_LOCK:
            if not _TABLES:
                _TABLES.append(_Tables())
    return _TABLES[0]


# --- Blocks of work in reused arrays.

BLOCK = 16384
"""Elements per block of the vectorised kernels: their scratch arrays stay in cache."""


class Scratch:
    """
    Named arrays reused from block to block (one per thread: see :func:`scratch`).

    Fresh memory costs page faults (~2 ms per MB on the project's virtual machine)
    and cache misses; a kernel that writes its intermediate values into the same
    few arrays block after block runs several times faster.
    """

    def __init__(self):
        """Start with no arrays."""
        self._arrays = {}
        self._views = {}

    def __call__(self, name, n, dtype=float, rows=None):
        """Return the array ``name`` of n elements, or (rows, n); contents undefined."""
        key = (name, n, rows)
        view = self._views.get(key)
        if view is None:
            size = n * (rows or 1)
            array = self._arrays.get(name)
            if array is None or array.size < size:
                array = self._arrays[name] = np.empty(max(size, BLOCK), dtype)
                self._views = {k: v for k, v in self._views.items() if k[0] != name}
            view = self._views[key] = (array[:size] if rows is None
                                       else array[:size].reshape(rows, n))
        return view


_LOCAL = threading.local()


def scratch():
    """Return this thread's :class:`Scratch`."""
    if not hasattr(_LOCAL, 'scratch'):
        _LOCAL.scratch = Scratch()
    return _LOCAL.scratch


def split_into(a, hi, lo):
    """
    Split ``a`` into ``hi`` (26 significant bits) + ``lo`` (26 bits and a sign), exactly.

    As Veltkamp's split, in three operations: round the bit pattern at bit 27 (an
    integer add), clear the 27 low bits, subtract. ``hi``, ``lo`` distinct from ``a``.
    """
    bits = hi.view(np.int64)
    np.add(a.view(np.int64), 1 << 26, out=bits)
    np.bitwise_and(bits, _HIGH_BITS, out=bits)
    np.subtract(a, hi, out=lo)


def two_prod_into(a, a_parts, b, b_parts, p, e, work):
    """:func:`two_prod_split` written into ``p``, ``e`` (broadcasting); ``work`` overwritten."""
    multiply, add = np.multiply, np.add
    multiply(a, b, p)
    multiply(a_parts[0], b_parts[0], e)
    np.subtract(e, p, e)
    multiply(a_parts[0], b_parts[1], work)
    add(e, work, e)
    multiply(a_parts[1], b_parts[0], work)
    add(e, work, e)
    multiply(a_parts[1], b_parts[1], work)
    add(e, work, e)


def add_product(e, a, b, work):
    """e += a b (rounded), ``work`` overwritten."""
    np.multiply(a, b, work)
    np.add(e, work, e)


def two_sum_into(a, b, s, e, work, subtract=False):
    """:func:`two_sum` of a and b (a - b if ``subtract``) into s, e; all distinct arrays."""
    if subtract:
        np.subtract(a, b, out=s)
    else:
        np.add(a, b, out=s)
    np.subtract(s, a, out=work)              # b as it went into s
    np.subtract(s, work, out=e)
    np.subtract(a, e, out=e)                 # what of a did not
    if subtract:
        work += b
        e -= work
    else:
        np.subtract(b, work, out=work)
        e += work


def partial_sums_into(hi, lo, bounds, levels, work, rest):
    """
    Per row of a block, levels + 1 floats whose exact sum is the row's sum(hi + lo).

    ``hi``, ``work``, ``rest``: (rows, n) (work and rest overwritten); ``lo`` the same
    or None; ``bounds``: (rows,) powers of two >= max |hi| of each row, below 2^960.
    Rump's extraction (AccSum): with sigma = 2^ceil(log2(n + 2)) bound, q = (hi +
    sigma) - sigma keeps the bits of each term above ulp(sigma) / 2 and those pieces
    sum exactly in any order; the remainders go through the same cut again at
    2^-53 sigma. Two levels leave remainders below ~2^-78 of the bound, summed in
    float64 with ``lo``: ~2^-100 of sum |terms| whatever the cancellation. One level
    suffices for terms of one sign, where the float64 sum of the remainders (each
    below 2^-38 of the bound) cannot cancel. Partial sums of different blocks add
    up exactly with ``math.fsum``.
    """
    gain = power_of_two_above(hi.shape[-1] + 2.0)
    sigma = (gain * np.asarray(bounds, dtype=float))[:, None]
    sums = np.empty((hi.shape[0], levels + 1))
    for level in range(levels):
        np.add(rest if level else hi, sigma, out=work)
        work -= sigma                           # the bits above ulp(sigma) / 2
        np.sum(work, axis=1, out=sums[:, level])     # exact
        if level:
            rest -= work                        # exact, |rest| <= ulp(sigma) / 2
        else:
            np.subtract(hi, work, out=rest)
        sigma = sigma * (gain * 2.0 ** -53)
    if lo is not None:
        rest += lo
    np.sum(rest, axis=1, out=sums[:, levels])
    return sums


# --- cos and sin.

def _reduce_into(angle, tables, index, r_hi, r_lo, s, fast=None):
    """
    Write index, r_hi, r_lo: angle = index h + r_hi + r_lo (mod 2 pi) to ~2^-110.

    Cody and Waite's reduction with split constants: each product of an integer and a
    part is exact, so the only roundings are in the last, smallest parts.
    """
    n = angle.size
    h1, h2, h3 = tables.step
    if fast is None:
        fast = not n or float(np.max(np.abs(angle))) <= tables.fast_limit
    j, t, u = s('reduce_j', n), s('reduce_t', n), s('reduce_u', n)
    if fast:
        np.multiply(angle, tables.inverse_step, out=j)
        j += _MAGIC                                 # rounds to an integer
        np.bitwise_and(j.view(np.int64), _TABLE_SIZE - 1, out=index)
        j -= _MAGIC
        np.multiply(j, h1, out=t)
        np.subtract(angle, t, out=t)                # exact
        np.multiply(j, h2, out=u)
        two_sum_into(t, u, r_hi, r_lo, s('reduce_w', n), subtract=True)
        np.multiply(j, h3, out=u)
        r_lo -= u
        return
    # Up to 2^31: k turns of 2 pi off first (the first two differences are exact).
    p1, p2, p3, p4, p5, p6 = tables.turn
    with np.errstate(invalid='ignore', over='ignore'):
        k = np.rint(angle * tables.inverse_turn)
        k[~(np.abs(angle) < _GENERAL_LIMIT)] = 0.0      # huge or not finite: see below
        t = (angle - k * p1) - k * p2
        shifted = t * tables.inverse_step + _MAGIC
        np.bitwise_and(shifted.view(np.int64), _TABLE_SIZE - 1, out=index)
        j = shifted - _MAGIC
        s1, e1 = two_sum(t - j * h1, -k * p3)
        s2, e2 = two_sum(s1, -j * h2)
        r_hi[:], e3 = two_sum(s2, -k * p4)
        r_lo[:] = ((e1 + e2) + e3) - j * h3 - k * p5 - k * p6
    for i in np.flatnonzero(np.isfinite(angle) & ~(np.abs(angle) < _GENERAL_LIMIT)):
        index[i], r_hi[i], r_lo[i] = _reduce_exactly(float(angle[i]), tables)


def cos_sin_fast_limit():
    """|angle| (rad) up to which :func:`cos_sin_into` may be told ``fast``."""
    return _tables().fast_limit


def _reduce_exactly(angle, tables):
    """One huge angle reduced in integers: (index, r_hi, r_lo), r exact to ~2^-250."""
    step = tables.big_reduction()
    numerator, denominator = angle.as_integer_ratio()
    fixed = (numerator << _BIG_BITS) // denominator            # exact: |angle| >= 2^31
    j = (2 * fixed + step) // (2 * step)
    r = Fraction(fixed - j * step, 1 << _BIG_BITS)
    r_hi = float(r)
    return j % _TABLE_SIZE, r_hi, float(r - Fraction(r_hi))


def cos_sin_into(angle, s, fast=None):
    """
    (cos, sin) of one block of float64 angles as unnormalised double-doubles.

    ``angle`` is 1-D and contiguous; ``s`` a :class:`Scratch`; ``fast``: True if
    the caller knows every |angle| <= 402 rad (skips a pass). Returns (hi, lo), two
    (2, n) scratch arrays (rows cos, sin; named 'cos_sin', 'cos_sin_lo'), valid until
    the next call: hi + lo is within ~3e-32 of the value; lo is not always below
    ulp(hi), which products and sums that follow do not need.
    """
    n = angle.size
    tables = _tables()
    index = s('index', n, np.int64)
    a, b = s('r', n), s('r_lo', n)
    _reduce_into(angle, tables, index, a, b, s, fast)
    w = s('work', n)
    # The table's cos and sin at index h, rows [C, S].
    table, table_lo = s('table', n, rows=2), s('table_lo', n, rows=2)
    for values, out in ((tables.cos_hi, table[0]), (tables.sin_hi, table[1]),
                        (tables.cos_lo, table_lo[0]), (tables.sin_lo, table_lo[1])):
        np.take(values, index, out=out, mode='clip')
    # r = a + b, |r| <= h/2 = 1.9e-4: r^2 = p + pl, r^3 = q + ql exactly enough.
    a_parts = (s('r_1', n), s('r_2', n))
    split_into(a, *a_parts)
    p, pl = s('p', n), s('p_lo', n)
    two_prod_into(a, a_parts, a, a_parts, p, pl, w)
    np.add(a, a, out=w)
    w *= b
    pl += w
    p_parts = (s('p_1', n), s('p_2', n))
    split_into(p, *p_parts)
    q, ql = s('q', n), s('q_lo', n)
    two_prod_into(p, p_parts, a, a_parts, q, ql, w)
    add_product(ql, pl, a, w)
    add_product(ql, p, b, w)
    # v = r^3/6 with v_hi of 51 bits (Veltkamp with 2^2 + 1), so that 6 v_hi and
    # q - 6 v_hi are exact.
    v_hi, v_lo = s('v', n), s('v_lo', n)
    np.multiply(q, 1.0 / 6.0, out=v_lo)
    np.multiply(v_lo, 5.0, out=v_hi)
    np.subtract(v_hi, v_lo, out=w)
    v_hi -= w
    np.multiply(v_hi, -6.0, out=v_lo)
    v_lo += q
    v_lo += ql
    v_lo *= 1.0 / 6.0
    # sin r = r - r^3/6 + r^5/120 - r^7/5040 = sin_hi + sin_lo.
    sin_hi, sin_lo = s('sin_r', n), s('sin_r_lo', n)
    np.subtract(a, v_hi, out=sin_hi)                # |a| >= |v_hi|: quick two-sum
    np.subtract(a, sin_hi, out=sin_lo)
    sin_lo -= v_hi
    sin_lo += b
    sin_lo -= v_lo
    np.multiply(p, -1.0 / 5040.0, out=w)
    w += 1.0 / 120.0
    w *= p
    w *= q
    sin_lo += w
    # 1 - cos r = r^2/2 - r^4/24 + r^6/720 = vers_hi + vers_lo, with r^4 = p^2 + 2 p pl
    # (pl reaches ~1e-22 when r_lo ~ 1e-19 after reducing a large angle).
    vers_hi, vers_lo = s('vers', n), s('vers_lo', n)
    np.multiply(p, -1.0 / 720.0, out=vers_lo)
    vers_lo += 1.0 / 24.0
    vers_lo *= p
    add_product(vers_lo, pl, 1.0 / 12.0, w)
    vers_lo *= p
    np.multiply(pl, 0.5, out=w)
    np.subtract(w, vers_lo, out=vers_lo)
    np.multiply(p, 0.5, out=vers_hi)
    vers_parts = p_parts                            # halved: p's split is no longer needed
    for part in vers_parts:
        part *= 0.5
    sin_parts = a_parts                             # r's split is no longer needed
    split_into(sin_hi, *sin_parts)
    # Turned by the table's angle: [cos, sin] = [C, S] - [C, S] vers + [-S, C] sin r.
    w2 = s('work2', n, rows=2)
    table_parts = (s('table_1', n, rows=2), s('table_2', n, rows=2))
    split_into(table, *table_parts)
    turn, turn_lo = s('turn', n, rows=2), s('turn_lo', n, rows=2)
    two_prod_into(table, table_parts, sin_hi, sin_parts, turn, turn_lo, w2)
    add_product(turn_lo, table, sin_lo, w2)
    add_product(turn_lo, table_lo, sin_hi, w2)
    turn, turn_lo = turn[::-1], turn_lo[::-1]       # rows [S sin r, C sin r]
    np.negative(turn[0], out=turn[0])
    np.negative(turn_lo[0], out=turn_lo[0])
    vers_t, vers_t_lo = s('vers_t', n, rows=2), s('vers_t_lo', n, rows=2)
    two_prod_into(table, table_parts, vers_hi, vers_parts, vers_t, vers_t_lo, w2)
    add_product(vers_t_lo, table, vers_lo, w2)
    add_product(vers_t_lo, table_lo, vers_hi, w2)
    middle, middle_lo = table_parts                 # free now
    two_sum_into(table, vers_t, middle, middle_lo, w2, subtract=True)
    out, out_lo = s('cos_sin', n, rows=2), s('cos_sin_lo', n, rows=2)
    two_sum_into(middle, turn, out, out_lo, w2)
    # The low parts, smallest first: three of them reach ulp(hi) / 2, each sum rounds.
    turn_lo -= vers_t_lo
    turn_lo += table_lo
    middle_lo += out_lo
    np.add(turn_lo, middle_lo, out=out_lo)
    return out, out_lo


def cos_sin(angle):
    """
    Return (cos, sin) of float64 angles (rad) as double-doubles, error < ~3e-32.

    Any finite angle: the reduction by pi/8192 is exact (split constants up to
    2^31 rad, integer arithmetic beyond); not finite gives nan. Measured against
    60-digit mpmath: see test/test_stability.py and benchmarks/aggregation.py.
    """
    angle = np.asarray(angle, dtype=float)
    flat = np.ascontiguousarray(angle.ravel())
    hi, lo = np.empty((2, flat.size)), np.empty((2, flat.size))
    s = scratch()
    for start in range(0, flat.size, BLOCK):
        stop = min(start + BLOCK, flat.size)
        value, value_lo = cos_sin_into(flat[start:stop], s)
        # Normalised, |lo| <= ulp(hi) / 2 (quick two-sum: |value| >= |value_lo|).
        np.add(value, value_lo, out=hi[:, start:stop])
        np.subtract(hi[:, start:stop], value, out=lo[:, start:stop])
        np.subtract(value_lo, lo[:, start:stop], out=lo[:, start:stop])
    return ((hi[0].reshape(angle.shape), lo[0].reshape(angle.shape)),
            (hi[1].reshape(angle.shape), lo[1].reshape(angle.shape)))
