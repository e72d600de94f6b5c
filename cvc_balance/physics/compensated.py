"""
Double-double arithmetic on numpy arrays: sums and products that keep ~32 digits.

A double-double is a pair (hi, lo) of float64 arrays whose exact sum is the value,
|lo| <= ulp(hi) / 2. The layout's aggregates are summed this way so that a rotor
balanced to 1e-9 of its mass moment keeps the residual's digits: summed in float64,
each term's rounding (1e-16 of a term) would be 1e-7 of such a residual.

The error-free transformations are Knuth's two-sum and Dekker's two-product (with
Veltkamp's split: numpy has no fused multiply-add); cos and sin of a float64 angle
are reduced by a three-part pi/2 and summed as Taylor series in double-double.
numpy and the standard library only.
"""

from fractions import Fraction
import math

import numpy as np

_SPLITTER = 134217729.0            # 2^27 + 1: splits a float64 into two 26-bit halves

# pi/2 = _PIO2[0] + _PIO2[1] + _PIO2[2] to ~1e-49 (each part the float nearest the rest).
_PIO2 = (1.5707963267948966, 6.123233995736766e-17, -1.4973849048591698e-33)

_TAYLOR_TERMS = 14                 # (pi/4)^28 / 28! < 1e-32: past double-double's digits


def _reciprocal_factorial(n):
    exact = Fraction(1, math.factorial(n))
    hi = float(exact)
    return hi, float(exact - Fraction(hi))


# Taylor coefficients in x^2 of sin(x)/x and cos(x): (-1)^k / (2k+1)!, (-1)^k / (2k)!.
_SIN_COEFFICIENTS = [tuple((-1) ** k * v for v in _reciprocal_factorial(2 * k + 1))
                     for k in range(_TAYLOR_TERMS)]
_COS_COEFFICIENTS = [tuple((-1) ** k * v for v in _reciprocal_factorial(2 * k))
                     for k in range(_TAYLOR_TERMS)]


def two_sum(a, b):
    """Return (s, e) with s = fl(a + b) and s + e = a + b exactly."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _quick_two_sum(a, b):
    # Needs |a| >= |b| (or a = 0).
    s = a + b
    return s, b - (s - a)


def _split(a):
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


def two_prod(a, b):
    """Return (p, e) with p = fl(a b) and p + e = a b exactly (no overflow assumed)."""
    p = a * b
    a_hi, a_lo = _split(a)
    b_hi, b_lo = _split(b)
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


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


def total(x):
    """
    Sum of a 1-D double-double array, rounded to one float.

    Pairwise, so the error stays ~log2(n) double-double roundings of the
    terms' magnitudes: ~1e-30 of sum |terms| for a million terms.
    """
    hi, lo = np.asarray(x[0], float).ravel(), np.asarray(x[1], float).ravel()
    if hi.size == 0:
        return 0.0
    while hi.size > 1:
        if hi.size % 2:
            hi, lo = np.append(hi, 0.0), np.append(lo, 0.0)
        hi, lo = add((hi[0::2], lo[0::2]), (hi[1::2], lo[1::2]))
    return float(hi[0] + lo[0])


def _series(coefficients, r2):
    acc = (np.full_like(r2[0], coefficients[-1][0]), np.full_like(r2[0], coefficients[-1][1]))
    for hi, lo in reversed(coefficients[:-1]):
        acc = add(mul(acc, r2), (hi, lo))
    return acc


def cos_sin(angle):
    """
    Return (cos, sin) of float64 angles (rad) as double-doubles, error < ~1e-31.

    Reduced by the nearest multiple k of pi/2 (exact products with a three-part
    pi/2; good for |angle| up to ~1e9 rad), then Taylor series on |r| <= pi/4.
    """
    angle = np.asarray(angle, float)
    k = np.rint(angle / _PIO2[0])
    r = (angle, np.zeros_like(angle))
    for part in _PIO2[:2]:
        r = add(r, negate(two_prod(k, part)))
    r = add(r, (-k * _PIO2[2], np.zeros_like(angle)))
    r2 = mul(r, r)
    sin_r = mul(r, _series(_SIN_COEFFICIENTS, r2))
    cos_r = _series(_COS_COEFFICIENTS, r2)
    quadrant = np.mod(k, 4).astype(int)
    # Quadrant q: cos(r + q pi/2), sin(r + q pi/2) from cos r, sin r.
    cos_hi = np.choose(quadrant, [cos_r[0], -sin_r[0], -cos_r[0], sin_r[0]])
    cos_lo = np.choose(quadrant, [cos_r[1], -sin_r[1], -cos_r[1], sin_r[1]])
    sin_hi = np.choose(quadrant, [sin_r[0], cos_r[0], -sin_r[0], -cos_r[0]])
    sin_lo = np.choose(quadrant, [sin_r[1], cos_r[1], -sin_r[1], -cos_r[1]])
    return (cos_hi, cos_lo), (sin_hi, sin_lo)
