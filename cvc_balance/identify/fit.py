"""
Least squares of the unbalance from load-cell readings: sums that add, and their solution.

Unknowns: S (kg m) and P (kg m^2), complex, and one complex bias per reading channel
(each cell's force; a single support's moment too). A reading y = c_S S + c_P P + b_k + e
adds to the normal equations; :class:`Sums` holds them as plain numbers so that the live
node adds one reading in O(1) with Python floats, a bag adds arrays at once, and a sliding
window is a difference of sums. The noise is taken as circular (the same variance sigma^2
in x and y, independent), so each estimate's error is circular too:
Cov(Re) = Cov(Im) = sigma^2 [N^-1]_kk.
"""

from dataclasses import dataclass, field
import math

import numpy as np

CHI2_2DOF_95 = 5.991464547107979
"""95 % quantile of chi-square with 2 degrees of freedom: a 2-D vector's 95 % circle."""
MAX_CONDITION = 1e12
"""Condition number of the (equilibrated) normal equations beyond which nothing is told."""


@dataclass
class Sums:
    """
    Normal-equation sums over readings (see the module's description).

    ``ss`` = sum |c_S|^2, ``sp`` = sum conj(c_S) c_P, ``pp`` = sum |c_P|^2,
    ``sb[k]``/``pb[k]`` = sum conj(c_S) / conj(c_P) over channel k's readings,
    ``count[k]`` its readings, ``ys``/``yp`` = sum conj(c_S) y / conj(c_P) y,
    ``yb[k]`` = sum y, ``yy`` = sum |y|^2.
    """

    channels: int
    ss: float = 0.0
    sp: complex = 0j
    pp: float = 0.0
    ys: complex = 0j
    yp: complex = 0j
    yy: float = 0.0
    sb: list = field(default=None)
    pb: list = field(default=None)
    yb: list = field(default=None)
    count: list = field(default=None)

    def __post_init__(self):
        """Start the per-channel sums at zero."""
        for name in ('sb', 'pb', 'yb'):
            if getattr(self, name) is None:
                setattr(self, name, [0j] * self.channels)
        if self.count is None:
            self.count = [0] * self.channels

    def add(self, channel, c_s, c_p, y):
        """Add one reading (complex numbers) of ``channel``: O(1), plain Python."""
        cs, cp = c_s.conjugate(), c_p.conjugate()
        self.ss += (cs * c_s).real
        self.sp += cs * c_p
        self.pp += (cp * c_p).real
        self.ys += cs * y
        self.yp += cp * y
        self.yy += (y.conjugate() * y).real
        self.sb[channel] += cs
        self.pb[channel] += cp
        self.yb[channel] += y
        self.count[channel] += 1

    def add_arrays(self, channel, c_s, c_p, y):
        """Add readings of ``channel`` given as complex numpy arrays."""
        cs, cp = np.conj(c_s), np.conj(c_p)
        self.ss += float(np.sum(np.abs(c_s) ** 2))
        self.sp += complex(np.sum(cs * c_p))
        self.pp += float(np.sum(np.abs(c_p) ** 2))
        self.ys += complex(np.sum(cs * y))
        self.yp += complex(np.sum(cp * y))
        self.yy += float(np.sum(np.abs(y) ** 2))
        self.sb[channel] += complex(np.sum(cs))
        self.pb[channel] += complex(np.sum(cp))
        self.yb[channel] += complex(np.sum(y))
        self.count[channel] += len(y)

    def combine(self, other, sign=1):
        """Return these sums plus ``sign`` times ``other`` (a window is a difference)."""
        out = Sums(self.channels)
        for name in ('ss', 'sp', 'pp', 'ys', 'yp', 'yy'):
            setattr(out, name, getattr(self, name) + sign * getattr(other, name))
        for name in ('sb', 'pb', 'yb', 'count'):
            pairs = zip(getattr(self, name), getattr(other, name))
            setattr(out, name, [a + sign * b for a, b in pairs])
        return out

    @property
    def readings(self):
        """Return the number of readings summed."""
        return sum(self.count)

    def solve(self):
        """Return the :class:`Estimate` (None-free: see its ``identifiable``)."""
        return Estimate.from_sums(self)


@dataclass(frozen=True)
class Estimate:
    """
    The fitted unbalance and how well it is known.

    ``static`` S (kg m) and ``products`` P about O (kg m^2), complex (x + i y, rotor
    frame); ``biases`` per channel (N or N m, stator frame); ``sigma`` the noise's
    standard deviation per component (N); ``inverse`` N^-1 restricted to (S, P), so that
    a linear combination w of (S, P) has error variance sigma^2 w^H inverse w per
    component; ``identifiable`` False when the readings cannot separate the unknowns
    (too few, no rotation, no speed): then every interval is infinite.
    """

    static: complex
    products: complex
    biases: tuple
    sigma: float
    inverse: np.ndarray
    readings: int
    identifiable: bool

    @classmethod
    def unknown(cls, channels, readings):
        """Return the estimate of readings that cannot tell: every interval inf."""
        return cls(0j, 0j, tuple(0j for _ in range(channels)), math.inf,
                   np.full((2, 2), math.inf), readings, False)

    @classmethod
    def from_sums(cls, sums):
        """Solve the normal equations in ``sums``."""
        k = sums.channels
        used = [c for c in range(k) if sums.count[c] > 0]
        size = 2 + len(used)
        matrix = np.zeros((size, size), complex)
        rhs = np.zeros(size, complex)
        matrix[0, 0], matrix[0, 1], matrix[1, 1] = sums.ss, sums.sp, sums.pp
        rhs[0], rhs[1] = sums.ys, sums.yp
        for j, c in enumerate(used, start=2):
            matrix[0, j], matrix[1, j], matrix[j, j] = sums.sb[c], sums.pb[c], sums.count[c]
            rhs[j] = sums.yb[c]
        matrix = np.triu(matrix) + np.triu(matrix, 1).conj().T
        dof = 2 * sums.readings - 2 * size          # real residual degrees of freedom
        diagonal = np.real(np.diag(matrix))
        condition = math.inf
        if np.all(diagonal > 0.0) and np.all(np.isfinite(matrix)):
            scale = np.sqrt(diagonal)
            scaled = matrix / np.outer(scale, scale)     # equilibrated: the design's condition
            condition = np.linalg.cond(scaled)
        if dof <= 0 or not condition <= MAX_CONDITION:
            return cls.unknown(k, sums.readings)
        inverse = np.linalg.inv(scaled) / np.outer(scale, scale)
        theta = inverse @ rhs
        rss = max(sums.yy - float(np.real(np.vdot(theta, rhs))), 0.0)
        sigma = math.sqrt(rss / dof)
        if not (np.all(np.isfinite(theta)) and math.isfinite(sigma)):    # sums overflowed
            return cls.unknown(k, sums.readings)
        biases = [0j] * k
        for j, c in enumerate(used, start=2):
            biases[c] = complex(theta[j])
        return cls(complex(theta[0]), complex(theta[1]), tuple(biases), sigma,
                   np.real_if_close(inverse[:2, :2]), sums.readings, True)

    def variance(self, weights):
        """
        Return the error's variance, per x and y component, of w_S S + w_P P.

        ``weights`` = (w_S, w_P), complex.
        """
        if not self.identifiable:
            return math.inf
        w = np.asarray(weights, complex)
        return float(np.real(np.conj(w) @ self.inverse @ w)) * self.sigma ** 2

    def ci95(self, weights):
        """Radius of the 95 % circle of w_S S + w_P P (its units), inf if not identifiable."""
        return math.sqrt(CHI2_2DOF_95 * self.variance(weights))
