"""
Exact derivatives of a layout's balance with respect to every design parameter.

The aggregates about O (:class:`cvc_balance.physics.engine.RotorModel`) are sums
over components; component k at (m, R, theta, z) with own products p' (own
frame, kg m^2; a given ``inertia`` only) adds, in complex form e = e^{i theta}:

    M += m,  S = S_x + i S_y += m R e,  S_z += m z,  P = P_xz + i P_yz += (m R z + p') e

so each derivative is a closed form (per component, nothing else moves):

    d/dm:     dM = 1, dS = R e,   dS_z = z, dP = R z e
    d/dR:             dS = m e,             dP = m z e
    d/dtheta:         dS = i m R e,         dP = i (m R z + p') e
    d/dz:                         dS_z = m, dP = m R e

The plane unbalances, the static unbalance and the supports' unbalance loads
are linear in (S, P) (:func:`cvc_balance.physics.unbalance.two_plane_split`,
:func:`cvc_balance.physics.engine.support_loads`), so their derivatives are the
same maps applied to (dS, dP); the couple about the centre of mass
C = P - S S_z / M (:func:`cvc_balance.physics.unbalance.couple_unbalance`) takes
the product rule. These are derivatives of the VECTORS, smooth through
balance; a norm's slopes are one-sided there (:func:`norm_slopes`).

Units: per kg, per m, per rad, per m of the parameter; vectors in the rotor
frame (x, y); kg m, kg m^2, N.
"""

from dataclasses import dataclass

import numpy as np

from cvc_balance.design.parameters import all_parameters, own_products
from cvc_balance.physics.engine import support_loads
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance, two_plane_split

AGGREGATES = ('mass', 's_x', 's_y', 's_z', 'p_xz', 'p_yz')
"""The aggregates' order in the last axis of :func:`aggregate_derivatives`."""

AT_BALANCE = 8 * np.finfo(float).eps
"""A norm is "at balance" below this fraction of the layout's size (sum of m R, kg m):
the rounding its own inputs carry (an angle of 180 deg is pi to 1.2e-16 rad)."""


def aggregate_derivatives(mass, radius, angle, z, own=None):
    """
    Return d(aggregate)/d(parameter) of components: array (..., 4, 6).

    ``mass`` (kg), ``radius`` (m), ``angle`` (rad), ``z`` (m): arrays of one
    shape (components, grid points, ...); ``own`` their own products
    (..., 2) (kg m^2) or None. Axis -2: mass, radius, angle, z; axis -1:
    :data:`AGGREGATES`.
    """
    m, r, theta, z = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                           for v in (mass, radius, angle, z)))
    c, s = np.cos(theta), np.sin(theta)
    own_x, own_y = (0.0, 0.0) if own is None else (own[..., 0], own[..., 1])
    # (m R z + p') e: the component's products about O, turned by theta.
    p_x = m * r * z * c + own_x * c - own_y * s
    p_y = m * r * z * s + own_x * s + own_y * c
    one, zero = np.ones_like(m), np.zeros_like(m)
    rows = (
        (one, r * c, r * s, z, r * z * c, r * z * s),               # d/d mass
        (zero, m * c, m * s, zero, m * z * c, m * z * s),           # d/d radius
        (zero, -m * r * s, m * r * c, zero, -p_y, p_x),             # d/d angle
        (zero, zero, zero, m, m * r * c, m * r * s),                # d/d z
    )
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def component_aggregates(mass, radius, angle, z, own=None):
    """
    Return what components add to the aggregates about O: (..., 6), :data:`AGGREGATES`.

    The point-mass terms of :func:`cvc_balance.physics.inertia.place` and the
    own products turned by theta (the layout's order of the terms above), in
    float64 per component, for grids of one component's parameters (sweeps).
    """
    m, r, theta, z = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                           for v in (mass, radius, angle, z)))
    c, s = np.cos(theta), np.sin(theta)
    own_x, own_y = (0.0, 0.0) if own is None else (own[..., 0], own[..., 1])
    return np.stack((m, m * r * c, m * r * s, m * z, m * r * z * c + own_x * c - own_y * s,
                     m * r * z * s + own_x * s + own_y * c), axis=-1)


@dataclass(frozen=True)
class Balance:
    """
    A layout's balance as vectors (rotor frame; kg m, kg m^2, N).

    ``planes`` (2, 2): U_I, U_II, or None without correction planes;
    ``static`` (2,), ``couple`` (2,) about the centre of mass; ``supports``
    (n_supports, 2): each support's unbalance load at ``omega`` (rad/s,
    gravity left out), or None without a speed.
    """

    planes: np.ndarray
    static: np.ndarray
    couple: np.ndarray
    supports: np.ndarray
    omega: float


@dataclass(frozen=True)
class Sensitivity:
    """
    Derivatives of :class:`Balance` with respect to ``parameters``.

    ``parameters``: a DesignParameter per row; ``planes`` (P, 2, 2) kg m per
    unit (None without planes); ``static`` (P, 2) kg m per unit; ``couple``
    (P, 2) kg m^2 per unit; ``supports`` (P, n_supports, 2) N per unit at
    ``nominal.omega`` (None without a speed); ``products`` (P, 2): d(P_xz,
    P_yz) about O, kg m^2 per unit. ``size`` is sum |m R| (kg m).
    """

    parameters: tuple
    nominal: Balance
    planes: np.ndarray
    static: np.ndarray
    couple: np.ndarray
    supports: np.ndarray
    products: np.ndarray
    size: float


def balance_of(model, omega=None):
    """Return the :class:`Balance` of a RotorModel (supports' loads at ``omega`` rad/s)."""
    static = np.array(static_unbalance(model))
    couple = np.array(couple_unbalance(model))
    products = np.array((model.p_xz, model.p_yz))
    return Balance(plane_vectors(model.layout, static, products), static, couple,
                   support_vectors(model.supports, static, products, omega), omega)


def sensitivities(model, omega=None):
    """
    Differentiate the balance of ``model`` (a RotorModel) by every parameter.

    Rows in the order of :func:`cvc_balance.design.parameters.all_parameters`.
    """
    layout = model.layout
    mass, radius, angle, z = layout.placement
    derivatives = aggregate_derivatives(mass, radius, angle, z, own_products(layout))
    d = derivatives.reshape(-1, 6)                  # rows: component-major, then parameter
    d_mass, d_static, d_s_z, d_products = d[:, 0], d[:, 1:3], d[:, 3], d[:, 4:6]
    d_couple = couple_derivative(model, d_mass, d_static, d_s_z, d_products)
    return Sensitivity(all_parameters(layout), balance_of(model, omega),
                       plane_vectors(layout, d_static, d_products), d_static, d_couple,
                       support_vectors(model.supports, d_static, d_products, omega),
                       d_products, float(np.sum(np.abs(mass * radius))))


def couple_derivative(model, d_mass, d_static, d_s_z, d_products):
    """
    Return d(couple about the centre of mass) from the aggregates' derivatives, (P, 2).

    The product rule on C = P - S z_c, z_c = S_z / M: dC = dP - dS z_c - S dz_c,
    dz_c = (dS_z - z_c dM) / M, at the model's aggregates.
    """
    z_com = model.s_z / model.mass
    d_z_com = (d_s_z - z_com * d_mass) / model.mass
    static = np.array((model.s_x, model.s_y))
    return d_products - d_static * z_com - d_z_com[:, None] * static


def plane_vectors(layout, first_moment, products):
    """Two-plane split of (..., 2) vectors: (..., 2 planes, 2), or None without planes."""
    planes = layout.correction_planes()
    if planes is None:
        return None
    split = two_plane_split((first_moment[..., 0], first_moment[..., 1]),
                            (products[..., 0], products[..., 1]), *planes)
    return np.stack([np.stack(plane, axis=-1) for plane in split], axis=-2)


def judged_vectors(layout, first_moment, products):
    """
    Return the judged planes' vectors (..., n, 2) from S (..., 2) and P (..., 2) about O.

    The two correction planes' (:func:`plane_vectors`), or without them the static
    unbalance alone (n = 1): what the ISO verdict judges.
    """
    planes = plane_vectors(layout, first_moment, products)
    return np.asarray(first_moment)[..., None, :] if planes is None else planes


def support_vectors(supports, first_moment, products, omega):
    """Unbalance load at each support at ``omega``, rotor frame: (..., n_supports, 2), N."""
    if omega is None:
        return None
    w2 = omega * omega
    f_x, f_y = w2 * first_moment[..., 0], w2 * first_moment[..., 1]
    # The engine's bearing moment from the products: M_x = -w^2 P_yz, M_y = w^2 P_xz.
    m_x, m_y = -w2 * products[..., 1], w2 * products[..., 0]
    per_support = support_loads(supports, f_x, f_y, 0.0, m_x, m_y)
    return np.stack([np.stack(np.broadcast_arrays(force[0], force[1]), axis=-1)
                     for force, _ in per_support], axis=-2)


def norm_slopes(vector, derivative, size):
    """
    Return the one-sided slopes (minus side, plus side) of |vector| along a parameter.

    ``vector`` (..., 2) and its ``derivative`` (..., 2); away from balance both
    are vector . derivative / |vector|; at balance (|vector| within
    :data:`AT_BALANCE` of ``size``) the norm has a kink: -|d| below, +|d| above.
    """
    vector, derivative = np.asarray(vector, float), np.asarray(derivative, float)
    amount = np.hypot(vector[..., 0], vector[..., 1])
    steep = np.hypot(derivative[..., 0], derivative[..., 1])
    kink = amount <= AT_BALANCE * size
    along = np.einsum('...i,...i->...', vector, derivative) / np.where(kink, 1.0, amount)
    return np.where(kink, -steep, along), np.where(kink, steep, along)
