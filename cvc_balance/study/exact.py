"""
The loads in extended precision (mpmath, 40 digits): the reference the methods are judged by.

Written apart from the engine, from Newton-Euler per component in vector form: each
component's inertia tensor (from its shape, in mpmath), turned to the rotor frame as
R I R^T and carried to O by the vector parallel-axis theorem m (|c|^2 1 - c c^T); then
Euler's equation about the fixed point O for each body, with cross products and
matrix-vector products on full 3x3 tensors (no element of the engine's aggregated
equations: no S, no P_xz, no formula for a bearing moment)::

    load force  = m g_r - m a_c,     a_c = alpha x c + omega x (omega x c)
    h           = I_O alpha + omega x (I_O omega) - (m c) x g_r
    load moment = -(h_x, h_y, 0),    drive torque = h_z

(g_r gravity in the rotor frame; omega and alpha along Z). These are linear in
(g_r, omega^2, alpha), exactly, so each component's wrench is evaluated once at the
five unit motions (g_r = e_x, e_y, e_z; omega^2 = 1; alpha = 1) and summed over the
components; a sample's loads are then the same linear combination of those five sums:
a cost of one Newton-Euler evaluation per component and motion, not per sample
(:func:`direct_loads` evaluates per component and per sample, for the tests). The
layout's numbers are taken as exact binary fractions. Slow (tens of us per component):
for references, not for use.
"""

import mpmath as mp

DIGITS = 40
BASIS = ('g_x', 'g_y', 'g_z', 'omega2', 'alpha')
"""The unit motions, in the order of :func:`basis_wrenches`."""


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _times(matrix, vector):
    return [sum(row[j] * vector[j] for j in range(3)) for row in matrix]


def _product(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def _diagonal(values):
    zero = mp.mpf(0)
    return [[values[i] if i == j else zero for j in range(3)] for i in range(3)]


def own_tensor(component):
    """Return the own inertia tensor about the centre of mass, own frame (3x3 rows, mpmath)."""
    m, shape = mp.mpf(component.mass), component.shape
    if component.inertia is not None:
        ixx, iyy, izz, ixy, ixz, iyz = (mp.mpf(v) for v in component.inertia)
        return [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]
    if shape is None or shape.type == 'point':
        return _diagonal([mp.mpf(0)] * 3)
    if shape.type == 'box':
        a, b, c = (mp.mpf(v) for v in shape.size)
        return _diagonal([m * (b * b + c * c) / 12, m * (a * a + c * c) / 12,
                          m * (a * a + b * b) / 12])
    if shape.type == 'sphere':
        i = 2 * m * mp.mpf(shape.radius) ** 2 / 5
        return _diagonal([i, i, i])
    if shape.type == 'tube':
        r2 = mp.mpf(shape.inner_radius) ** 2 + mp.mpf(shape.outer_radius) ** 2
    else:
        r2 = mp.mpf(shape.radius) ** 2
    along, across = m * r2 / 2, m * (3 * r2 + mp.mpf(shape.length) ** 2) / 12
    diagonal = [across, across, across]
    diagonal[('radial', 'tangential', 'axial').index(shape.axis)] = along
    return _diagonal(diagonal)


def about_o(component):
    """Return (mass, first moment m c, inertia tensor about O), rotor frame, mpmath."""
    m, theta = mp.mpf(component.mass), mp.mpf(component.angle)
    c, s = mp.cos(theta), mp.sin(theta)
    r = mp.mpf(component.radius)
    centre = [r * c, r * s, mp.mpf(component.z)]
    turn = [[c, -s, 0], [s, c, 0], [0, 0, 1]]                # own frame -> rotor frame
    turned = _product(_product(turn, own_tensor(component)), [list(row) for row in zip(*turn)])
    square = sum(x * x for x in centre)
    inertia = [[turned[i][j] + m * ((square if i == j else 0) - centre[i] * centre[j])
                for j in range(3)] for i in range(3)]
    return m, [m * x for x in centre], inertia


def body_load(mass, first_moment, inertia_about_o, gravity_rotor, omega, alpha):
    """
    Newton-Euler of a rigid body turning about the Z axis through the fixed point O.

    ``first_moment`` m c and ``inertia_about_o`` in the rotor frame; returns the load on
    the stator (force, moment about O with its Z part 0) and the drive torque, mpmath.
    """
    zero = mp.mpf(0)
    spin, rate, g = [zero, zero, omega], [zero, zero, alpha], list(gravity_rotor)
    acceleration = [a + b for a, b in zip(_cross(rate, first_moment),
                                          _cross(spin, _cross(spin, first_moment)))]
    force = [mass * gi - ai for gi, ai in zip(g, acceleration)]
    h = [a + b - c for a, b, c in zip(_times(inertia_about_o, rate),
                                      _cross(spin, _times(inertia_about_o, spin)),
                                      _cross(first_moment, g))]
    return force, [-h[0], -h[1], zero], h[2]


def _unit_motions():
    one, zero = mp.mpf(1), mp.mpf(0)
    return (((one, zero, zero), zero, zero), ((zero, one, zero), zero, zero),
            ((zero, zero, one), zero, zero), ((zero, zero, zero), one, zero),
            ((zero, zero, zero), zero, one))


def basis_wrenches(layout):
    """
    Return the layout's loads at the five unit motions of :data:`BASIS`, summed.

    Returns five (force, moment, torque) triples of mpmath numbers.
    """
    with mp.workdps(DIGITS):
        sums = [([mp.mpf(0)] * 3, [mp.mpf(0)] * 3, mp.mpf(0)) for _ in BASIS]
        for component in layout.components:
            mass, first, inertia = about_o(component)
            for k, (g, omega, alpha) in enumerate(_unit_motions()):
                force, moment, torque = body_load(mass, first, inertia, g, omega, alpha)
                f, m, t = sums[k]
                sums[k] = ([a + b for a, b in zip(f, force)],
                           [a + b for a, b in zip(m, moment)], t + torque)
        return sums


def unbalance_about_o(layout):
    """
    Return static unbalance (S_x, S_y) and couple about O (P_xz, P_yz), mpmath.

    At omega = 1 rad/s with no gravity, the load on the stator is the centrifugal
    force (S_x, S_y, 0) and the moment (-P_yz, P_xz, 0).
    """
    force, moment, _ = basis_wrenches(layout)[BASIS.index('omega2')]
    return (force[0], force[1]), (moment[1], -moment[0])


def gravity_in_rotor(q, gravity):
    """Stator-frame gravity turned into the rotor frame at rotor angle ``q``, mpmath."""
    c, s = mp.cos(mp.mpf(q)), mp.sin(mp.mpf(q))
    g_x, g_y, g_z = (mp.mpf(v) for v in gravity)
    return c * g_x + s * g_y, -s * g_x + c * g_y, g_z


def exact_loads(layout, q, omega, alpha, gravity):
    """
    Return (force_rotor (n, 3), moment_rotor (n, 3), drive_torque (n,)) as float arrays.

    Rounded from 40-digit values: correct to the last bit of a float64.
    """
    return loads_from_basis(basis_wrenches(layout), q, omega, alpha, gravity)


def loads_from_basis(basis, q, omega, alpha, gravity):
    """Return the loads as :func:`exact_loads` does, from :func:`basis_wrenches`."""
    import numpy as np
    forces, moments, torques = [], [], []
    with mp.workdps(DIGITS):
        for qk, wk, ak in zip(q, omega, alpha):
            weights = (*gravity_in_rotor(qk, gravity), mp.mpf(wk) ** 2, mp.mpf(ak))
            force = [sum(w * b[0][i] for w, b in zip(weights, basis)) for i in range(3)]
            moment = [sum(w * b[1][i] for w, b in zip(weights, basis)) for i in range(3)]
            forces.append([float(v) for v in force])
            moments.append([float(v) for v in moment])
            torques.append(float(sum(w * b[2] for w, b in zip(weights, basis))))
    return np.array(forces, float).reshape(-1, 3), np.array(moments, float).reshape(-1, 3), \
        np.array(torques, float)


def direct_loads(layout, q, omega, alpha, gravity):
    """
    Return the loads as :func:`exact_loads` does, summed per component and per sample.

    No superposition: for the tests (it costs components x samples evaluations).
    """
    import numpy as np
    forces, moments, torques = [], [], []
    with mp.workdps(DIGITS):
        bodies = [about_o(c) for c in layout.components]
        for qk, wk, ak in zip(q, omega, alpha):
            g = gravity_in_rotor(qk, gravity)
            force, moment, torque = [mp.mpf(0)] * 3, [mp.mpf(0)] * 3, mp.mpf(0)
            for mass, first, inertia in bodies:
                f, m, t = body_load(mass, first, inertia, g, mp.mpf(wk), mp.mpf(ak))
                force = [a + b for a, b in zip(force, f)]
                moment = [a + b for a, b in zip(moment, m)]
                torque += t
            forces.append([float(v) for v in force])
            moments.append([float(v) for v in moment])
            torques.append(float(torque))
    return np.array(forces, float).reshape(-1, 3), np.array(moments, float).reshape(-1, 3), \
        np.array(torques, float)
