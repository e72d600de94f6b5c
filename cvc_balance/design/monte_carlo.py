"""
Monte Carlo of a layout's unbalance under its tolerances: exact per draw, vectorised.

Each draw sets every toleranced component's mass, radius, angle and z to its
nominal value plus an independent deviation within its tolerance (uniform, or
normal with sigma = tolerance / 3 truncated there), and evaluates the first
moment S and the products P about O exactly (no linearisation): component k
adds (m R + p' / ...) e^{i theta} terms, taken as deviations from the nominal,

    dS_k = e0 [da + a (e^{i dtheta} - 1)],       a = m R,  da = m dR + R0 dm
    dP_k = e0 [dq + (q + p') (e^{i dtheta} - 1)], q = a z,  dq = a dz + da z0

with e^{i dtheta} - 1 = -2 sin^2(dtheta / 2) + i sin(dtheta). The deviations
are small numbers, so they are computed in float32 (relative error ~1e-7 of
each deviation) and summed over the components by one matrix product per
block; the nominal S, P (double-double aggregates) are added in float64, so a
balanced rotor keeps its residual.

Random numbers: each block of draws has its own SFC64 stream, seeded from
(seed, block number), so a seed gives the same draws on any number of threads.
A deviation is drawn at 16-bit resolution: one of 65536 equally likely values,
the midpoint quantiles of its distribution (1.5e-5 of the distribution
function, far below the Monte Carlo's own error), four per 64 random bits.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from cvc_balance.design.parameters import own_products
from cvc_balance.design.tolerances import TRUNCATION
from cvc_balance.physics.workers import pool

LEVELS = 1 << 16
"""Values a deviation can take (16-bit draws)."""
BLOCK_ELEMENTS = 1 << 15
"""Draws x components per block: the float32 work arrays stay in the core's cache."""


@lru_cache(maxsize=1)
def quantile_tables():
    """
    Deviations per unit of tolerance at the midpoint quantiles: (uniform, normal), float32.

    Uniform on (-1, 1); the normal with sigma 1/3 truncated at +-1 (3 sigma).
    """
    from scipy.special import ndtr, ndtri    # here: scipy costs every command 1-2 s to import
    u = (np.arange(LEVELS) + 0.5) / LEVELS
    uniform = 2.0 * u - 1.0
    below = ndtr(-TRUNCATION)
    normal = ndtri(below + u * (1.0 - 2.0 * below)) / TRUNCATION
    return uniform.astype(np.float32), normal.astype(np.float32)


@dataclass(frozen=True)
class Draws:
    """
    Monte-Carlo draws of a layout's first moment and products about O (rotor frame).

    ``first_moment`` (N, 2) kg m and ``products`` (N, 2) kg m^2 (P_xz, P_yz),
    float64; ``deviations`` (N, n_components, 4) SI, when asked for (checks).
    """

    first_moment: np.ndarray
    products: np.ndarray
    deviations: np.ndarray = None


def simulate(model, tolerances, samples, seed, keep_deviations=False):
    """
    Draw ``samples`` layouts around ``model`` (a RotorModel) within ``tolerances``.

    Returns :class:`Draws`. ``seed`` (int >= 0) fixes every draw.
    """
    layout = model.layout
    mass, radius, angle, z = layout.placement
    active = np.flatnonzero(np.any(tolerances.values > 0.0, axis=1))
    # Uniform components first: one table lookup per distribution and parameter.
    active = active[np.argsort(tolerances.normal[active], kind='stable')]
    n_uniform = int(np.count_nonzero(~tolerances.normal[active]))
    k = len(active)
    nominal_s = np.array((model.s_x, model.s_y))
    nominal_p = np.array((model.p_xz, model.p_yz))
    first_moment = np.empty((samples, 2))
    products = np.empty((samples, 2))
    deviations = np.zeros((samples, len(mass), 4)) if keep_deviations else None
    if k == 0:
        first_moment[:] = nominal_s
        products[:] = nominal_p
        return Draws(first_moment, products, deviations)
    own = own_products(layout)[active]
    block = _Block(mass[active], radius[active], angle[active], z[active], own,
                   tolerances.values[active], n_uniform)
    per_block = max(64, BLOCK_ELEMENTS // k)
    starts = range(0, samples, per_block)

    def run(number):
        start = starts[number]
        stop = min(start + per_block, samples)
        d_s, d_p, dev = block.deviations(stop - start, np.random.SeedSequence(
            seed, spawn_key=(number,)), keep_deviations)
        first_moment[start:stop] = nominal_s + d_s.T
        products[start:stop] = nominal_p + d_p.T
        if keep_deviations:
            deviations[start:stop, active] = dev

    if len(starts) > 1:
        # numpy and BLAS release the GIL: blocks run on every core.
        list(pool().map(run, range(len(starts))))
    else:
        run(0)
    return Draws(first_moment, products, deviations)


class _Block:
    """The per-component constants of :func:`simulate` and one block's arithmetic."""

    def __init__(self, mass, radius, angle, z, own, tolerance, n_uniform):
        column = (lambda v: np.asarray(v, dtype=np.float32)[:, None])
        self.mass, self.radius, self.z = column(mass), column(radius), column(z)
        self.a = column(mass * radius)
        self.q = column(mass * radius * z)
        self.tolerance = [column(tolerance[:, j]) for j in range(4)]
        # value v of 16 bits -> t (2 (v + 1/2) / LEVELS - 1) = v scale + offset.
        uniform = tolerance[:n_uniform]
        self.uniform_scale = [column(2.0 * uniform[:, j] / LEVELS) for j in range(4)]
        self.uniform_offset = [column(uniform[:, j] * (1.0 / LEVELS - 1.0)) for j in range(4)]
        self.n_uniform = n_uniform
        c, s = np.cos(angle), np.sin(angle)
        # Sums over components of e0 (re + i im): [x; y] = turn_re @ re + turn_im @ im.
        self.turn_re = np.array([c, s], dtype=np.float32)
        self.turn_im = np.array([-s, c], dtype=np.float32)
        # Own products p' turned by theta0: e0 p' = o_x + i o_y, times (e^{i dtheta} - 1).
        self.own = None
        if np.any(own != 0.0):
            o_x, o_y = own[:, 0] * c - own[:, 1] * s, own[:, 0] * s + own[:, 1] * c
            self.own = (np.array([o_x, o_y], dtype=np.float32),
                        np.array([-o_y, o_x], dtype=np.float32))

    def deviations(self, n, seed_sequence, keep):
        """Deviations (dS, dP) of n draws, each (2, n) float32, and the parameters' (n, k, 4)."""
        k = self.mass.shape[0]
        bits = np.random.SFC64(seed_sequence).random_raw(n * k)
        index = bits.view(np.uint16).reshape(4, k, n)
        x = np.empty((4, k, n), dtype=np.float32)
        u = self.n_uniform
        for j in range(4):
            if u:
                # Uniform: the midpoint quantile is affine in the 16-bit value.
                np.copyto(x[j, :u], index[j, :u], casting='unsafe')
                x[j, :u] *= self.uniform_scale[j]
                x[j, :u] += self.uniform_offset[j]
            if u < k:
                np.take(quantile_tables()[1], index[j, u:], out=x[j, u:], mode='clip')
                x[j, u:] *= self.tolerance[j][u:]
        kept = x.transpose(2, 1, 0).astype(float) if keep else None
        half = np.multiply(x[2], np.float32(0.5))
        d_mass, d_radius, d_angle, d_z = x
        # a = m R: da = m dR + R0 dm (m the drawn mass), exact.
        d_a = np.add(d_mass, self.mass)
        d_a *= d_radius
        term = np.multiply(d_mass, self.radius)
        d_a += term
        a = np.add(d_a, self.a)
        # e^{i dtheta} - 1 = -2 w + i sin(dtheta), w = sin^2(dtheta / 2): no cancellation.
        w = np.sin(half, out=half)
        w *= w
        sin_d = np.sin(d_angle, out=d_angle)
        re, im = self._rotated(d_a, a, w, sin_d, term)
        d_s = self.turn_re @ re + self.turn_im @ im
        # q = a z: dq = a dz + da z0.
        d_q = np.multiply(a, d_z, out=d_z)
        d_a *= self.z
        d_q += d_a
        q = np.add(d_q, self.q, out=a)
        re, im = self._rotated(d_q, q, w, sin_d, term)
        d_p = self.turn_re @ re + self.turn_im @ im
        if self.own is not None:
            w *= -2.0
            d_p += self.own[0] @ w + self.own[1] @ sin_d
        return d_s.astype(float), d_p.astype(float), kept

    @staticmethod
    def _rotated(delta, value, w, sin_d, scratch):
        """(delta + value (e^{i dtheta} - 1)) as (real, imaginary) arrays."""
        re = np.multiply(value, w, out=scratch)
        re *= -2.0
        re += delta
        return re, value * sin_d
