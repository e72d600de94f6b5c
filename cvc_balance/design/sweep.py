"""
The thesis's charts from any layout: balance over one or two design parameters.

A sweep moves one or two parameters (of one component or two) over a grid and
evaluates, at every point, each judged plane's unbalance vector, the static
and couple unbalance, each support's unbalance load at omega (gravity left
out, as the thesis's Figs. 4.2-4.8 do) and the resultant
F_res = omega^2 |S| (thesis Eq. 4.12-4.13, 4.30-4.31). Only the swept
components change: the others are aggregated once (double-double, as the
engine does) and the swept ones added per point in closed form, vectorised.
Along one parameter it also gives the derivatives: the vectors' (smooth) and
the norms' one-sided slopes (which jump at balance: Figs. 4.3, 4.4, 4.7, 4.8).

Balance points: local minima of sum |U_plane|^2 on the grid, refined by the
smooth solve of :mod:`cvc_balance.design.balance_point` within the sweep's
range; a point is *balanced* when the planes vanish (to rounding), else it
is the least unbalance there is along the sweep.
"""

from dataclasses import dataclass

import numpy as np

from cvc_balance.design.balance_point import solve_balance
from cvc_balance.design.parameters import own_products, PARAMETERS, with_values
from cvc_balance.design.sensitivity import (aggregate_derivatives, component_aggregates,
                                            judged_vectors, norm_slopes, support_vectors)
from cvc_balance.physics import limits
from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import own_tensors_of, RotorModel
from cvc_balance.physics.frames import products_of_inertia
from cvc_balance.physics.inertia import place
from cvc_balance.physics.unbalance import couple_unbalance

MAX_POINTS = limits.POINTS.high
"""Most grid points along one parameter; a map takes at most MAX_MAP_POINTS a side."""
MAX_MAP_POINTS = limits.MAP_POINTS


@dataclass(frozen=True)
class BalancePoint:
    """A refined minimum of the sweep: ``values`` (SI, per swept parameter), planes (kg m)."""

    values: tuple
    planes: tuple
    balanced: bool


@dataclass(frozen=True)
class Sweep:
    """
    Balance over a grid of one or two parameters.

    ``axes``: each parameter's grid values (SI); arrays over the grid (shape
    of the axes, 'ij'): ``planes`` (..., n, 2) kg m (judged planes; the static
    unbalance alone without planes), ``static`` (..., 2) kg m, ``couple``
    (..., 2) kg m^2, ``supports`` (..., n_supports, 2) N and ``resultant``
    (...) N at ``omega`` (None without a speed). One parameter: ``d_planes``
    (N, n, 2) kg m per unit, ``d_resultant`` (N, 2) N per unit (vector) and
    ``resultant_slopes`` (minus, plus) (N,) each: the norm's one-sided slopes.
    """

    layout: object
    parameters: tuple
    axes: tuple
    planes: np.ndarray
    static: np.ndarray
    couple: np.ndarray
    supports: np.ndarray
    resultant: np.ndarray
    omega: float
    permissible: np.ndarray
    grade: float
    d_planes: np.ndarray
    d_resultant: np.ndarray
    resultant_slopes: tuple
    balance_points: tuple


def sweep(layout, parameters, ranges, points, omega=None):
    """
    Sweep ``parameters`` (1 or 2 DesignParameters) over ``ranges`` ((low, high) SI).

    ``points`` per parameter; ``omega`` rad/s for the loads and the grade's
    allowance (default: the layout's service speed).
    """
    if not 1 <= len(parameters) <= 2 or len(ranges) != len(parameters):
        raise ValueError('sweep one or two parameters, each with a range')
    if len(set(parameters)) != len(parameters):
        raise ValueError(f'parameter {parameters[0].label} given twice')
    most = MAX_POINTS if len(parameters) == 1 else MAX_MAP_POINTS
    if not 2 <= points <= most:
        raise ValueError(f'--points must be 2..{most} for {len(parameters)} parameter(s), '
                         f'got {points}')
    for p, (low, high) in zip(parameters, ranges):
        if not low < high:
            raise ValueError(f'{p.label}: range must go from low to high, got {low:g} {high:g}')
        if p.name == 'mass' and not low > 0.0:
            raise ValueError(f'{p.label}: masses must be > 0 kg, the range starts at {low:g}')
        if p.name == 'radius' and low < 0.0:
            raise ValueError(f'{p.label}: radii must be >= 0 m, the range starts at {low:g}')
    if omega is None:
        omega = layout.balancing.service_speed
    axes = tuple(np.linspace(low, high, points) for low, high in ranges)
    grid = np.meshgrid(*axes, indexing='ij')
    swept = sorted({p.index for p in parameters})
    # Everything else aggregated once, as the engine does (double-double sums).
    base = _aggregates_without(layout, swept)
    own = own_products(layout)
    total = np.broadcast_to(base, grid[0].shape + (6,)).copy()
    columns = {}
    for index in swept:
        component = layout.components[index]
        values = [np.full(grid[0].shape, getattr(component, name)) for name in PARAMETERS]
        for p, g in zip(parameters, grid):
            if p.index == index:
                values[p.column] = g
        columns[index] = values
        total += component_aggregates(*values, own[index])
    mass, s_x, s_y, s_z, p_xz, p_yz = np.moveaxis(total, -1, 0)
    static = np.stack((s_x, s_y), axis=-1)
    products = np.stack((p_xz, p_yz), axis=-1)
    planes = judged_vectors(layout, static, products)
    couple = np.stack(couple_unbalance(_Aggregates(mass, s_x, s_y, s_z, p_xz, p_yz)), axis=-1)
    supports = support_vectors(layout.supports, static, products, omega)
    resultant = None if omega is None else omega * omega * np.hypot(s_x, s_y)
    permissible, grade = _allowance(layout, omega)
    d_planes = d_resultant = slopes = None
    if len(parameters) == 1:
        p = parameters[0]
        d = aggregate_derivatives(*columns[p.index], own[p.index])[..., p.column, :]
        d_static, d_products = d[..., 1:3], d[..., 4:6]
        d_planes = judged_vectors(layout, d_static, d_products)
        if omega is not None:
            w2 = omega * omega
            size = w2 * float(np.sum(np.abs(layout.placement[0] * layout.placement[1])))
            d_resultant = w2 * d_static
            slopes = norm_slopes(w2 * static, d_resultant, size)
    points_found = _balance_points(layout, parameters, ranges, planes, omega)
    return Sweep(layout, tuple(parameters), axes, planes, static, couple, supports, resultant,
                 omega, permissible, grade, d_planes, d_resultant, slopes, points_found)


class _Aggregates:
    """Arrays of aggregates, read by the physics' plain formulas (couple_unbalance)."""

    def __init__(self, mass, s_x, s_y, s_z, p_xz, p_yz):
        self.mass, self.s_x, self.s_y, self.s_z = mass, s_x, s_y, s_z
        self.p_xz, self.p_yz = p_xz, p_yz


def _aggregates_without(layout, swept):
    """Aggregate every component but ``swept`` (indexes) about O: (6,)."""
    keep = [i for i in range(len(layout.components)) if i not in set(swept)]
    if not keep:
        return np.zeros(6)
    components = [layout.components[i] for i in keep]
    mass, radius, angle, z = (v[keep] for v in layout.placement)
    body = place(mass, own_tensors_of(components), radius, angle, z)
    _, p_xz, p_yz = products_of_inertia(body.inertia)
    return np.array([body.mass, *body.first_moment, p_xz, p_yz])


def _allowance(layout, omega):
    """Each judged plane's ISO allowance (kg m) at ``omega`` and the grade, or (None, None)."""
    if omega is None or not omega > 0.0:
        return None, None
    assessment = assess_balance(RotorModel.from_layout(layout), omega)
    allowed = (assessment.plane_permissible if assessment.planes
               else (assessment.permissible,))
    return np.asarray(allowed), assessment.grade


def _balance_points(layout, parameters, ranges, planes, omega, most=4):
    """Grid minima of sum |U|^2, refined by the smooth solve within the ranges."""
    residual = np.sum(planes * planes, axis=(-2, -1))
    minima = _grid_minima(residual)[:most]
    lower = np.array([low for low, _ in ranges])
    upper = np.array([high for _, high in ranges])
    found = []
    for index in minima:
        start = {p: ranges[k][0] + (ranges[k][1] - ranges[k][0]) * i / (residual.shape[k] - 1)
                 for k, (p, i) in enumerate(zip(parameters, index))}
        solution = solve_balance(with_values(layout, start), parameters, omega,
                                 bounds=(lower, upper))
        spans = upper - lower
        on_edge = np.any((solution.values <= lower + 1e-9 * spans)
                         | (solution.values >= upper - 1e-9 * spans))
        if on_edge and not solution.balanced:
            continue                    # the range cut a slope: no minimum there
        if any(np.all(np.abs(solution.values - np.array(f.values)) <= 1e-6 * spans)
               for f in found):
            continue
        found.append(BalancePoint(tuple(float(v) for v in solution.values),
                                  tuple(tuple(float(c) for c in v) for v in solution.planes),
                                  solution.balanced))
    return tuple(found)


def _grid_minima(values):
    """Indexes of the grid's local minima (no neighbour lower), least first."""
    padded = np.pad(values, 1, mode='constant', constant_values=np.inf)
    is_min = np.ones(values.shape, dtype=bool)
    for shift in np.ndindex(*(3,) * values.ndim):
        if all(s == 1 for s in shift):
            continue
        window = tuple(slice(s, s + n) for s, n in zip(shift, values.shape))
        is_min &= values <= padded[window]
    candidates = [tuple(int(i) for i in index) for index in np.argwhere(is_min)]
    return sorted(candidates, key=lambda index: values[index])
