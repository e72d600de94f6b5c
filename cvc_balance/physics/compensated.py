"""
Double-double arithmetic on numpy arrays: sums and products that keep ~32 digits.

A double-double is a pair (hi, lo) of float64 arrays whose exact sum is the value,
|lo| small against |hi| (about ulp(hi), not always normalised inside a computation).
The layout's aggregates are summed this way so that a rotor balanced to 1e-9 of its
mass moment keeps the residual's digits: summed in float64, each term's rounding
(1e-16 of a term) would be 1e-7 of such a residual.

The error-free transformations are Knuth's two-sum and Dekker's two-product (on
factors split in halves of 26 bits: numpy has no fused multiply-add). Sums of many
terms are exact: Rump's extraction cuts each term at a power of two chosen so that
the pieces above it add without rounding (:func:`trace_partial_sums`), and the few
partial sums are rounded once by ``math.fsum``. cos and sin of a float64 angle come
from a table of cos and sin at multiples of h = pi/8192 (double-double, made from
integer arithmetic on first use) and short polynomials in the remainder |r| <= h/2
where only r, r^2/2 and r^3/6 need exact products; the reduction by h is exact for
every finite angle (split constants up to 2^31 rad, integer arithmetic beyond).

The vectorised kernels (cos and sin here, the layout's aggregates in
:mod:`cvc_balance.physics.inertia`) are written as plain numpy expressions on a
:class:`Tracer`, which records them once, lays their arrays out by liveness in a few
cache-sized rows and runs them block after block (:data:`BLOCK` elements) with nothing
left to look up: fresh memory costs page faults on this machine and a numpy call
~0.4 us, so both are spent once. numpy and the standard library only.
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
    """Smallest power of two >= ``value`` (a float >= 0; 0 gives 0; inf beyond 2^1023)."""
    if value <= 0.0:
        return 0.0
    mantissa, exponent = math.frexp(value)
    exponent = exponent - 1 if mantissa == 0.5 else exponent
    return math.ldexp(1.0, exponent) if exponent < 1024 else math.inf


def total(x):
    """
    Sum of a 1-D double-double array, rounded to one float.

    Exact to ~2^-100 of sum |terms| whatever the number of terms (two levels of
    Rump's extraction, see :func:`trace_partial_sums`), then correctly rounded by
    ``math.fsum``.
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
        rest, rest_lo = hi[start:start + BLOCK], lo[start:start + BLOCK]
        for sigma in sigma_for(rest.size, [bound], 2)[0]:
            q = (rest + sigma) - sigma
            sums.append(float(np.sum(q)))
            rest = rest - q
        sums.append(float(np.sum(rest + rest_lo)))
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
    """Return pi * 2^bits to within a few units (Machin's formula, 16 guard bits)."""
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


# --- Straight-line kernels, traced once and run block after block.

BLOCK = 16384
"""Elements per block of the vectorised kernels (their working arrays stay in cache)."""


class Ref:
    """
    A symbolic array of a :class:`Tracer`: (n,) or (rows, n), or a view of one.

    Arithmetic on Refs records numpy calls; ``a += b`` records an in-place one.
    """

    __slots__ = ('tracer', 'base', 'path', 'rows')

    def __init__(self, tracer, base, path, rows):
        """Make the view ``path`` (indexing keys, or 'int': as int64) of ``base``."""
        self.tracer, self.base, self.path, self.rows = tracer, base, path, rows

    def __getitem__(self, key):
        """
        Select rows of a stacked array.

        ``key``: an int (one row), a slice, None (a new axis), or a tuple (rows
        first) for the caller's small arrays.
        """
        first = key[0] if isinstance(key, tuple) else key
        if first is None:
            rows = 1
        elif isinstance(first, int):
            rows = None
        else:
            rows = len(range(*first.indices(self.rows)))
        return Ref(self.tracer, self.base, self.path + (key,), rows)

    def __setitem__(self, key, value):
        # After ``a[k] += b`` (already recorded in place on the view a[k]): nothing to do.
        if not (isinstance(value, Ref) and value.base == self.base
                and value.path == self.path + (key,)):
            raise TypeError('assign to a traced array with Tracer.call')

    def bits(self):
        """Return the same memory seen as int64."""
        return Ref(self.tracer, self.base, self.path + ('int',), self.rows)

    def _binary(self, function, other, swap=False):
        a, b = (other, self) if swap else (self, other)
        return self.tracer.apply(function, a, b)

    def __add__(self, other):
        return self._binary(np.add, other)

    def __radd__(self, other):
        return self._binary(np.add, other, True)

    def __sub__(self, other):
        return self._binary(np.subtract, other)

    def __rsub__(self, other):
        return self._binary(np.subtract, other, True)

    def __mul__(self, other):
        return self._binary(np.multiply, other)

    def __rmul__(self, other):
        return self._binary(np.multiply, other, True)

    def __neg__(self):
        return self.tracer.apply(np.negative, self)

    def __iadd__(self, other):
        self.tracer.call(np.add, self, other, self)
        return self

    def __isub__(self, other):
        self.tracer.call(np.subtract, self, other, self)
        return self

    def __imul__(self, other):
        self.tracer.call(np.multiply, self, other, self)
        return self


class Tracer:
    """
    Records a straight-line numpy program on :class:`Ref` arrays.

    :meth:`compile` then gives each temporary array rows of one (rows, n) array by
    liveness (first fit), so the program's working set is what is live at once;
    :meth:`Program.bind` resolves every view for a block length n. Run, the program
    is a list of (function, arguments) calls with nothing left to look up: numpy's
    ufuncs, whose per-call cost then dominates the Python side.
    """

    def __init__(self):
        """Start an empty program."""
        self.ops = []
        self.rows = []               # internal arrays: rows (None: one row, 1-D)
        self.span = []               # [first, last] op using each internal array
        self.externals = {}          # name -> rows; bound to the caller's arrays

    def new(self, rows=None):
        """Return a fresh internal array of n (or rows x n) elements."""
        self.rows.append(rows)
        self.span.append([len(self.ops), len(self.ops)])
        return Ref(self, len(self.rows) - 1, (), rows)

    def external(self, name, rows=None, shape=None):
        """
        Return an array the caller binds: inputs, results.

        n or (rows, n) elements, or of ``shape`` (small arrays: sums, sigmas);
        read and written in place.
        """
        self.externals[name] = shape or rows
        return Ref(self, name, (), rows)

    def call(self, function, *args):
        """Record function(*args) (an output array, if any, among the args)."""
        for arg in args:
            if isinstance(arg, Ref) and isinstance(arg.base, int):
                span = self.span[arg.base]
                span[0], span[1] = min(span[0], len(self.ops)), len(self.ops)
        self.ops.append((function, args))

    def apply(self, function, *args):
        """Record function(*args, out) into a new array of the operands' shape."""
        rows = [a.rows for a in args if isinstance(a, Ref)]
        out = self.new(None if all(r is None for r in rows) else max(r or 1 for r in rows))
        self.call(function, *args, out)
        return out

    def compile(self):
        """Return the :class:`Program`, its internal arrays laid out by liveness."""
        free_after = []              # per row: the last op of its current array
        start = [0] * len(self.rows)
        for base in sorted(range(len(self.rows)), key=lambda b: self.span[b][0]):
            first, last = self.span[base]
            size = self.rows[base] or 1
            row = 0
            while any(free_after[r] >= first for r in range(row, min(row + size,
                                                                     len(free_after)))):
                row += 1
            free_after += [-1] * max(row + size - len(free_after), 0)
            free_after[row:row + size] = [last] * size
            start[base] = row
        return Program(self.ops, self.rows, start, len(free_after), dict(self.externals))


class Program:
    """A compiled :class:`Tracer` program; :meth:`bind` it to run it."""

    def __init__(self, ops, rows, start, total_rows, externals):
        """See :meth:`Tracer.compile`."""
        self.ops, self.rows, self.start = ops, rows, start
        self.total_rows, self.externals = total_rows, externals

    def bind(self, n, arrays):
        """
        Return the program's calls resolved for blocks of n elements, as a callable.

        ``arrays``: name -> the caller's array for each external (kept, reused run
        after run: write inputs into them, read results from them).
        """
        space = np.empty((self.total_rows, n))

        def resolve(arg):
            if not isinstance(arg, Ref):
                return arg
            if isinstance(arg.base, str):
                view = arrays[arg.base]
            else:
                first = self.start[arg.base]
                view = (space[first] if self.rows[arg.base] is None
                        else space[first:first + self.rows[arg.base]])
            for key in arg.path:
                view = view.view(np.int64) if key == 'int' else view[key]
            return view

        calls = [(function, tuple(resolve(a) for a in args)) for function, args in self.ops]

        def run():
            for function, args in calls:
                function(*args)
        return run


def trace_split(t, a):
    """
    Split ``a`` into hi (26 significant bits) + lo (26 bits and a sign), exactly.

    As Veltkamp's split, in three operations: round the bit pattern at bit 27 (an
    integer add), clear the 27 low bits, subtract.
    """
    hi = t.new(a.rows)
    t.call(np.add, a.bits(), 1 << 26, hi.bits())
    t.call(np.bitwise_and, hi.bits(), _HIGH_BITS, hi.bits())
    return hi, a - hi


def trace_two_prod(t, a, a_parts, b, b_parts, out=None):
    """
    (p, e), p = fl(a b), p + e = a b exactly (Dekker), from split factors.

    ``out``: two arrays (views) to write p and e to, else new ones.
    """
    (a1, a2), (b1, b2) = a_parts, b_parts
    if out is None:
        p = a * b
        return p, (((a1 * b1 - p) + a1 * b2) + a2 * b1) + a2 * b2
    p, e = out
    t.call(np.multiply, a, b, p)
    t.call(np.add, ((a1 * b1 - p) + a1 * b2) + a2 * b1, a2 * b2, e)
    return p, e


def trace_two_sum(t, a, b):
    """(s, e), s = fl(a + b), s + e = a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def trace_quick_two_sum(t, a, b):
    """(s, e), s + e = a + b exactly, for |a| >= |b| (or a = 0)."""
    s = a + b
    return s, b - (s - a)


def trace_partial_sums(t, hi, lo, sigma, levels, sums):
    """
    Per row of ``hi``, levels + 1 floats whose exact sum is the row's sum(hi + lo).

    ``hi`` (rows, n), ``lo`` the same or None; ``sigma`` an external (rows, levels)
    array (:func:`sigma_for`); ``sums`` an external (rows, levels + 1) array the
    results are written to. Rump's extraction (AccSum): with sigma = 2^ceil(log2(n +
    2)) times a power of two >= max |hi| of the row, q = (hi + sigma) - sigma keeps
    the bits of each term above ulp(sigma) / 2 and those pieces sum exactly in any
    order; the remainders go through the same cut again, 2^-53 lower. Two levels
    leave remainders below ~2^-78 of the bound, summed in float64 with ``lo``:
    ~2^-100 of sum |terms| whatever the cancellation. One level suffices for terms of
    one sign, where the float64 sum of the remainders (each below 2^-38 of the bound)
    cannot cancel. Partial sums of different blocks add up exactly with ``math.fsum``.
    """
    rest = hi
    for level in range(levels):
        cut = sigma[:, level:level + 1]
        q = (rest + cut) - cut
        t.call(np.add.reduce, q, -1, None, sums[:, level])
        rest = rest - q
    if lo is not None:
        rest = rest + lo
    t.call(np.add.reduce, rest, -1, None, sums[:, levels])


def sigma_for(n, bounds, levels):
    """
    Return the (rows, levels) sigma of :func:`trace_partial_sums` for blocks of n.

    ``bounds``: powers of two >= max |term| of each row, below 2^960.
    """
    gain = power_of_two_above(n + 2.0)
    first = gain * np.asarray(bounds, dtype=float)[:, None]
    return first * (gain * 2.0 ** -53) ** np.arange(levels)


# --- cos and sin.

def cos_sin_fast_limit():
    """|angle| (rad) up to which the direct reduction applies (402 rad)."""
    return _tables().fast_limit


def trace_reduction(t, angle):
    """
    (index, r_hi, r_lo): angle = index h + r_hi + r_lo (mod 2 pi) to ~2^-110.

    For |angle| <= :func:`cos_sin_fast_limit`: Cody and Waite's reduction with h in
    split parts, each product of an integer and a part exact, so the only roundings
    are in the last, smallest parts. (Larger angles: :func:`reduce_angles`.)
    """
    tables = _tables()
    h1, h2, h3 = tables.step
    shifted = angle * tables.inverse_step + _MAGIC          # rounded to an integer
    index = t.new()
    t.call(np.bitwise_and, shifted.bits(), _TABLE_SIZE - 1, index.bits())
    j = shifted - _MAGIC
    r_hi, e = trace_two_sum(t, angle - j * h1, -(j * h2))   # angle - j h1 is exact
    return index, r_hi, e - j * h3


def reduce_angles(angle):
    """
    (index, r_hi, r_lo) of :func:`trace_reduction` for any angles, as new arrays.

    Up to 2^31 rad: k turns of 2 pi (in six parts of 24 bits) off first, the first
    two differences exact; beyond, in integers (a few microseconds an angle).
    """
    tables = _tables()
    h1, h2, h3 = tables.step
    p1, p2, p3, p4, p5, p6 = tables.turn
    index = np.empty(angle.shape, np.int64)
    with np.errstate(invalid='ignore', over='ignore'):
        k = np.rint(angle * tables.inverse_turn)
        k[~(np.abs(angle) < _GENERAL_LIMIT)] = 0.0      # huge or not finite: see below
        t = (angle - k * p1) - k * p2
        shifted = t * tables.inverse_step + _MAGIC
        np.bitwise_and(shifted.view(np.int64), _TABLE_SIZE - 1, out=index)
        j = shifted - _MAGIC
        s1, e1 = two_sum(t - j * h1, -k * p3)
        s2, e2 = two_sum(s1, -j * h2)
        r_hi, e3 = two_sum(s2, -k * p4)
        r_lo = ((e1 + e2) + e3) - j * h3 - k * p5 - k * p6
    for i in np.flatnonzero(np.isfinite(angle) & ~(np.abs(angle) < _GENERAL_LIMIT)):
        index[i], r_hi[i], r_lo[i] = _reduce_exactly(float(angle[i]), tables)
    return index, r_hi, r_lo


def _reduce_exactly(angle, tables):
    """One huge angle reduced in integers: (index, r_hi, r_lo), r exact to ~2^-250."""
    step = tables.big_reduction()
    numerator, denominator = angle.as_integer_ratio()
    fixed = (numerator << _BIG_BITS) // denominator            # exact: |angle| >= 2^31
    j = (2 * fixed + step) // (2 * step)
    r = Fraction(fixed - j * step, 1 << _BIG_BITS)
    r_hi = float(r)
    return j % _TABLE_SIZE, r_hi, float(r - Fraction(r_hi))


def trace_cos_sin(t, index, a, b):
    """
    (cos, sin) of index h + a + b as unnormalised double-doubles, rows [cos, sin].

    ``index``: int64 (as floats' bits), |a + b| <= h/2 (1.9e-4 rad). hi + lo is within
    ~4e-32 of the value; lo is not always below ulp(hi), which products and sums
    that follow do not need.
    """
    tables = _tables()
    # The table's cos and sin at index h, rows [C, S].
    table, table_lo = t.new(2), t.new(2)
    for values, out in ((tables.cos_hi, table[0]), (tables.sin_hi, table[1]),
                        (tables.cos_lo, table_lo[0]), (tables.sin_lo, table_lo[1])):
        t.call(values.take, index.bits(), None, out, 'clip')
    # r = a + b: r^2 = p + pl and r^3 = q + ql exactly enough.
    a_parts = trace_split(t, a)
    p, pl = trace_two_prod(t, a, a_parts, a, a_parts)
    pl += (a + a) * b
    p_parts = trace_split(t, p)
    q, ql = trace_two_prod(t, p, p_parts, a, a_parts)
    ql += pl * a
    ql += p * b
    # v = r^3/6 with v_hi of 51 bits (Veltkamp with 2^2 + 1), so that 6 v_hi and
    # q - 6 v_hi are exact.
    v0 = q * (1.0 / 6.0)
    c5 = v0 * 5.0
    v_hi = c5 - (c5 - v0)
    v_lo = ((q - v_hi * 6.0) + ql) * (1.0 / 6.0)
    # sin r = r - r^3/6 + r^5/120 - r^7/5040 = sin_hi + sin_lo (|a| >= |v_hi|).
    sin_hi, sin_e = trace_quick_two_sum(t, a, -v_hi)
    sin_lo = ((sin_e + b) - v_lo) + q * (p * (1.0 / 120.0 - p * (1.0 / 5040.0)))
    # 1 - cos r = r^2/2 - r^4/24 + r^6/720 = vers_hi + vers_lo, with r^4 = p^2 + 2 p pl
    # (pl reaches ~1e-22 when r_lo ~ 1e-19 after reducing a large angle).
    vers_hi = p * 0.5
    vers_lo = pl * 0.5 - p * (p * (1.0 / 24.0 - p * (1.0 / 720.0)) + pl * (1.0 / 12.0))
    vers_parts = (p_parts[0] * 0.5, p_parts[1] * 0.5)
    sin_parts = trace_split(t, sin_hi)
    # Turned by the table's angle: [cos, sin] = [C, S] - [C, S] vers + [-S, C] sin r.
    table_parts = trace_split(t, table)
    turn, turn_lo = trace_two_prod(t, table, table_parts, sin_hi, sin_parts)
    turn_lo += table * sin_lo
    turn_lo += table_lo * sin_hi
    t.call(np.negative, turn[1], turn[1])           # rows [C sin r, -S sin r]
    t.call(np.negative, turn_lo[1], turn_lo[1])
    vers_t, vers_t_lo = trace_two_prod(t, table, table_parts, vers_hi, vers_parts)
    vers_t_lo += table * vers_lo
    vers_t_lo += table_lo * vers_hi
    # |C vers| <= |C|: a quick two-sum; the turn can outweigh what is left: a full one.
    middle, middle_lo = trace_quick_two_sum(t, table, -vers_t)
    out, out_lo = trace_two_sum(t, middle, turn[::-1])
    # The low parts, smallest first: three of them reach ulp(hi) / 2, each sum rounds.
    out_lo = ((turn_lo[::-1] - vers_t_lo) + table_lo) + (middle_lo + out_lo)
    return out, out_lo


_COS_SIN = {}
_LOCAL = threading.local()


def bound(cache, key, program, shared=None):
    """
    (arrays, run) of ``program()`` bound for blocks of key[-1] elements, cached.

    ``cache``: a thread's dict; the few most recent keys are kept (a layout of
    every size has one short last block). The externals are new arrays of n or
    (rows, n) elements (or their shape), but those in ``shared`` (name -> array).
    """
    if key in cache:
        cache[key] = cache.pop(key)                 # most recent last
        return cache[key]
    compiled, n = program(), key[-1]
    arrays = {name: (shared[name] if shared and name in shared
                     else np.empty(size) if isinstance(size, tuple)
                     else np.empty((size, n)) if size else np.empty(n))
              for name, size in compiled.externals.items()}
    cache[key] = (arrays, compiled.bind(n, arrays))
    while len(cache) > 8:
        cache.pop(next(iter(cache)))
    return cache[key]


def _cos_sin_program(fast):
    """Return the cos/sin program: from angles (fast) or from reduced angles."""
    if fast not in _COS_SIN:
        t = Tracer()
        if fast:
            index, a, b = trace_reduction(t, t.external('angle'))
        else:
            index, a, b = (t.external(name) for name in ('index', 'r_hi', 'r_lo'))
        value, value_lo = trace_cos_sin(t, index, a, b)
        # Normalised, |lo| <= ulp(hi) / 2 (quick two-sum: |value| >= |value_lo|).
        hi, lo = t.external('hi', 2), t.external('lo', 2)
        t.call(np.add, value, value_lo, hi)
        t.call(np.subtract, value_lo, hi - value, lo)
        _COS_SIN[fast] = t.compile()
    return _COS_SIN[fast]


def cos_sin(angle):
    """
    Return (cos, sin) of float64 angles (rad) as double-doubles, error < ~4e-32.

    Any finite angle: the reduction by pi/8192 is exact (split constants up to
    2^31 rad, integer arithmetic beyond); not finite gives nan. Measured against
    60-digit mpmath: test/test_compensated.py and benchmarks/aggregation.py.
    """
    angle = np.asarray(angle, dtype=float)
    flat = np.ascontiguousarray(angle.ravel())
    hi, lo = np.empty((2, flat.size)), np.empty((2, flat.size))
    fast_limit = cos_sin_fast_limit()
    runs = getattr(_LOCAL, 'cos_sin', None)
    if runs is None:
        runs = _LOCAL.cos_sin = {}
    for start in range(0, flat.size, BLOCK):
        stop = min(start + BLOCK, flat.size)
        block = flat[start:stop]
        fast = bool(np.max(np.abs(block)) <= fast_limit)
        arrays, run = bound(runs, (fast, stop - start), lambda: _cos_sin_program(fast))
        if fast:
            arrays['angle'][:] = block
        else:
            index, arrays['r_hi'][:], arrays['r_lo'][:] = reduce_angles(block)
            arrays['index'].view(np.int64)[:] = index
        run()
        hi[:, start:stop], lo[:, start:stop] = arrays['hi'], arrays['lo']
    return ((hi[0].reshape(angle.shape), lo[0].reshape(angle.shape)),
            (hi[1].reshape(angle.shape), lo[1].reshape(angle.shape)))
