"""
The loads in extended precision (mpmath, 40 digits): the reference the methods are judged by.

Written apart from the engine: each shape's inertia, its turn to the rotor frame and its
shift to O are evaluated in mpmath from the layout's numbers (taken as exact binary
fractions), then Newton-Euler for single-axis spin per sample. Slow (tens of us per
component and per sample): for references, not for use.
"""

import mpmath as mp

DIGITS = 40


def _own_inertia(component):
    """Diagonal and products (xx, yy, zz, xy, xz, yz) of the own tensor, mpmath."""
    m, shape = mp.mpf(component.mass), component.shape
    if component.inertia is not None:
        return [mp.mpf(v) for v in component.inertia]
    if shape is None or shape.type == 'point':
        return [mp.mpf(0)] * 6
    if shape.type == 'box':
        a, b, c = (mp.mpf(v) for v in shape.size)
        return [m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12,
                0, 0, 0]
    if shape.type == 'sphere':
        i = 2 * m * mp.mpf(shape.radius) ** 2 / 5
        return [i, i, i, 0, 0, 0]
    if shape.type == 'tube':
        r2 = mp.mpf(shape.inner_radius) ** 2 + mp.mpf(shape.outer_radius) ** 2
    else:
        r2 = mp.mpf(shape.radius) ** 2
    along, across = m * r2 / 2, m * (3 * r2 + mp.mpf(shape.length) ** 2) / 12
    diagonal = [across, across, across]
    diagonal[('radial', 'tangential', 'axial').index(shape.axis)] = along
    return diagonal + [0, 0, 0]


def aggregates(layout):
    """Return mass, first moments (x, y, z), P_xz, P_yz, I_zz about O, in mpmath."""
    with mp.workdps(DIGITS):
        mass = sx = sy = sz = pxz = pyz = izz = mp.mpf(0)
        for component in layout.components:
            m = mp.mpf(component.mass)
            c, s = mp.cos(mp.mpf(component.angle)), mp.sin(mp.mpf(component.angle))
            x, y, z = mp.mpf(component.radius) * c, mp.mpf(component.radius) * s, \
                mp.mpf(component.z)
            ixx, iyy, izz_own, ixy, ixz, iyz = _own_inertia(component)
            # Own tensor turned by theta about Z: the xz, yz elements and zz.
            txz = c * ixz - s * iyz
            tyz = s * ixz + c * iyz
            mass += m
            sx, sy, sz = sx + m * x, sy + m * y, sz + m * z
            pxz += -txz + m * x * z          # product integrals: minus the tensor elements
            pyz += -tyz + m * y * z
            izz += izz_own + m * (x * x + y * y)
        return mass, sx, sy, sz, pxz, pyz, izz


def exact_loads(layout, q, omega, alpha, gravity):
    """
    Return (force_rotor, moment_rotor, drive_torque) for each sample, as floats.

    Rounded from 40-digit values: correct to the last bit of a float64.
    """
    return exact_loads_from_aggregates(aggregates(layout), q, omega, alpha, gravity)


def exact_loads_from_aggregates(sums, q, omega, alpha, gravity):
    """
    Return the loads as :func:`exact_loads` does, from the aggregates of :func:`aggregates`.

    ``sums`` = (mass, S_x, S_y, S_z, P_xz, P_yz, I_zz), mpmath numbers; for
    layouts whose aggregates are known another way.
    """
    import numpy as np
    forces, moments, torques = [], [], []
    with mp.workdps(DIGITS):
        mass, sx, sy, sz, pxz, pyz, izz = (mp.mpf(v) for v in sums)
        gx, gy, gz = (mp.mpf(v) for v in gravity)
        for qk, wk, ak in zip(q, omega, alpha):
            c, s = mp.cos(mp.mpf(qk)), mp.sin(mp.mpf(qk))
            grx, gry = c * gx + s * gy, -s * gx + c * gy
            w2, a = mp.mpf(wk) ** 2, mp.mpf(ak)
            # Newton: load = m g_r - m a_c; Euler about O with the product integrals.
            fx = mass * grx + w2 * sx + a * sy
            fy = mass * gry + w2 * sy - a * sx
            mx = sy * gz - sz * gry + a * pxz - w2 * pyz
            my = sz * grx - sx * gz + a * pyz + w2 * pxz
            torque = izz * a - (sx * gry - sy * grx)
            forces.append([float(fx), float(fy), float(mass * gz)])
            moments.append([float(mx), float(my), 0.0])
            torques.append(float(torque))
    return np.array(forces), np.array(moments), np.array(torques)
