"""
How each design parameter moves the bearings' rating life, at a steady speed.

At a constant speed omega (alpha 0, the layout's gravity) a support's force turns through
F(q) over a revolution, and its bearing's rating life is (:mod:`cvc_balance.physics.
bearing_life`)

    L_h = a1 10^6 / (mean_q (P(q) / C)^p  x  revolutions per hour)

The engine's force is linear in the aggregates (M, S_x, S_y, S_z, P_xz, P_yz) at a given
motion and gravity, so its derivative by a parameter is the same equations evaluated on
the aggregates' derivatives (:func:`cvc_balance.design.sensitivity.aggregate_derivatives`):
dFr = (F_x dF_x + F_y dF_y) / Fr, dFa = sign(F_z) dF_z, dP = X dFr + Y dFa (the branch of
ISO 281's factors the nominal load is on), d(P/C)^p = p (P/C)^(p-1) dP / C, and
dL_h = -L_h d(mean) / mean. Exact derivatives of the mean over ``points`` angles (the
trapezoid on a periodic function: converged long before 360 points for these loads).

Units: hours per kg, m, rad, m of the parameter; SI inside.
"""

from dataclasses import dataclass, replace

import numpy as np

from cvc_balance.design.parameters import all_parameters, own_products
from cvc_balance.design.sensitivity import aggregate_derivatives, AGGREGATES
from cvc_balance.physics.bearing_life import equivalent_load, steady_life_hours
from cvc_balance.physics.engine import rotor_frame_loads, support_loads
from cvc_balance.physics.frames import turn_xy

POINTS = 360
"""Angles over a revolution the mean is taken at."""


@dataclass(frozen=True)
class LifeSensitivity:
    """
    The bearings' rating life at ``omega`` (rad/s) and its derivative by every parameter.

    ``supports``: names of the supports with a bearing; ``hours``: each one's rating life
    (h; None where it bears no load); ``d_hours`` (P, supports): h per unit of each of
    ``parameters`` (:func:`cvc_balance.design.parameters.all_parameters`' order).
    """

    omega: float
    supports: tuple
    hours: tuple
    d_hours: np.ndarray
    parameters: tuple


def _forces(model, aggregates, cos_q, sin_q, omega):
    """Support forces (x, y, z per support, stator frame) of ``aggregates`` broadcast on q."""
    values = dict(zip(AGGREGATES, aggregates))
    varied = replace(model, mass=values['mass'], s_x=values['s_x'], s_y=values['s_y'],
                     s_z=values['s_z'], p_xz=values['p_xz'], p_yz=values['p_yz'], i_zz=0.0)
    f_x, f_y, f_z, m_x, m_y, _ = rotor_frame_loads(varied, cos_q, sin_q, omega, 0.0,
                                                   model.gravity)
    fs_x, fs_y = turn_xy(f_x, f_y, cos_q, sin_q)
    ms_x, ms_y = turn_xy(m_x, m_y, cos_q, sin_q)
    return [force for force, _ in support_loads(model.supports, fs_x, fs_y, f_z, ms_x, ms_y)]


def life_sensitivity(model, omega, points=POINTS):
    """
    Return the :class:`LifeSensitivity` of ``model`` (a RotorModel) at ``omega`` rad/s.

    None when no support describes its bearing.
    """
    supports = [(k, s) for k, s in enumerate(model.supports) if s.bearing is not None]
    if not supports:
        return None
    layout = model.layout
    angle = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    cos_q, sin_q = np.cos(angle), np.sin(angle)
    nominal = _forces(model, [np.float64(getattr(model, key)) for key in AGGREGATES],
                      cos_q, sin_q, omega)
    mass, radius, angle_c, z = layout.placement
    derivative = aggregate_derivatives(mass, radius, angle_c, z, own_products(layout))
    flat = derivative.reshape(-1, 6)                       # (P, 6): component-major
    changed = _forces(model, [flat[:, j][:, None] for j in range(6)], cos_q, sin_q, omega)
    hours, d_hours = [], []
    for k, support in supports:
        bearing = support.bearing
        f_x, f_y, f_z = (np.broadcast_to(v, cos_q.shape) for v in nominal[k])
        d_x, d_y, d_z = (np.broadcast_to(v, (len(flat), points)) for v in changed[k])
        radial, axial = np.hypot(f_x, f_y), np.abs(f_z)
        d_radial = (f_x * d_x + f_y * d_y) / np.where(radial > 0.0, radial, 1.0)
        d_axial = np.sign(f_z) * d_z
        load = equivalent_load(bearing, radial, axial)
        if bearing.e is None:
            beyond = np.ones(points, dtype=bool)
        else:
            beyond = axial > bearing.e * radial
        d_load = np.where(beyond, bearing.X * d_radial + bearing.Y * d_axial, d_radial)
        p = bearing.exponent
        ratio = load / bearing.C
        mean = float(np.mean(ratio ** p))
        d_mean = np.mean(p * ratio ** (p - 1.0) * d_load / bearing.C, axis=1)
        life = steady_life_hours(bearing, mean, omega)
        hours.append(life)
        d_hours.append(np.zeros(len(flat)) if life is None else -life * d_mean / mean)
    return LifeSensitivity(omega, tuple(s.name for _, s in supports), tuple(hours),
                           np.stack(d_hours, axis=-1), all_parameters(layout))


def life_stack(sensitivity, tolerances):
    """
    Return per bearing (name, hours, RSS sigma h, linear worst case h, shares (P,)).

    The linearised tolerance stack of the rating life: sigma = sqrt(sum (sigma_p dL/dp)^2)
    with each parameter's draw's sigma, the worst case sum |dL/dp| t_p, and each
    parameter's share of the variance.
    """
    sigma = tolerances.sigma().reshape(-1)
    bound = tolerances.values.reshape(-1)
    out = []
    for j, name in enumerate(sensitivity.supports):
        slope = sensitivity.d_hours[:, j]
        variance = (sigma * slope) ** 2
        total = float(variance.sum())
        out.append((name, sensitivity.hours[j], float(np.sqrt(total)),
                    float(np.sum(np.abs(slope) * bound)),
                    variance / total if total > 0.0 else np.zeros_like(variance)))
    return out
