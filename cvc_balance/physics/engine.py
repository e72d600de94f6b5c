"""
Loads a spinning rotor puts on its stator: the CVC engine.

The layout is reduced once to its aggregates about O (mass, first moments,
products of inertia P_xz, P_yz, moment of inertia I_zz, in the rotor frame);
the loads for a motion sample (rotor angle q, speed omega, acceleration
alpha, gravity) then cost O(1) whatever the number of components. The
equations are Newton's for the force and Euler's with products of inertia
for the moment (thesis Eq. 2.20 for omega = omega_Z), not the thesis's
F1 = F2 shortcut (NOTES.md erratum 1).

With S = int r dm (rotor frame), g_r gravity in the rotor frame, the load on
the stator (minus the support reaction on the rotor), about O, rotor frame:

    F   = m g_r + omega^2 (S_x, S_y, 0) + alpha (S_y, -S_x, 0)
    M_x = (S x g_r)_x + alpha P_xz - omega^2 P_yz
    M_y = (S x g_r)_y + alpha P_yz + omega^2 P_xz,   M_z = 0
    drive torque = I_zz alpha - (S x g_r)_z

Frames, signs and units are those of :mod:`cvc_balance.physics.frames`. numpy only.
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.physics import inertia as shapes
from cvc_balance.physics.frames import (products_of_inertia, tensor_from_elements,
                                        tensors_from_elements, turn_xy)
from cvc_balance.physics.inertia import place
from cvc_balance.physics.workers import pool

CHUNK = 1 << 16
"""Samples per block in the vectorised path: the temporaries stay in cache."""


@dataclass(frozen=True)
class RotorModel:
    """
    A layout's aggregates about O in the rotor frame, computed once.

    ``body`` holds the full mass properties; the scalars below are what the
    per-sample equations read (kg, kg m, kg m^2, m/s^2). A reduced model
    (:mod:`cvc_balance.physics.model_choice`) has ``own_inertia`` False (components
    taken as point masses) or ``moments`` False (the bearing-moment terms not
    evaluated: M_x = M_y = 0 about O).
    """

    layout: object
    body: shapes.MassProperties
    mass: float
    s_x: float
    s_y: float
    s_z: float
    p_xz: float
    p_yz: float
    i_zz: float
    gravity: tuple
    own_inertia: bool = True
    moments: bool = True

    @classmethod
    def from_layout(cls, layout, own_inertia=True, moments=True, own_tensors=None):
        """
        Aggregate a validated :class:`cvc_balance.physics.layout.Layout`.

        ``own_tensors``: the components' own tensors, (n, 3, 3), when already
        computed (:func:`own_tensors_of`).
        """
        if own_inertia and own_tensors is None:
            own_tensors = layout_own_tensors(layout)
        mass, radius, angle, z = layout.placement
        body = place(mass, own_tensors if own_inertia else None, radius, angle, z)
        s_x, s_y, s_z = (float(v) for v in body.first_moment)
        _, p_xz, p_yz = (float(v) for v in products_of_inertia(body.inertia))
        return cls(layout, body, body.mass, s_x, s_y, s_z, p_xz, p_yz,
                   float(body.inertia[2, 2]), tuple(float(g) for g in layout.gravity),
                   own_inertia, moments)

    @property
    def supports(self):
        """Return the layout's supports."""
        return self.layout.supports


def own_tensors_of(components):
    """Return the components' own inertia tensors, (n, 3, 3) (kg m^2)."""
    return tensors_from_elements([own_elements(c) for c in components])


def layout_own_tensors(layout):
    """
    Return a layout's own inertia tensors, (n, 3, 3) (kg m^2), or None: all point masses.

    Made from its bodies only (:attr:`Layout.bodies`): 10^6 point masses need none.
    """
    if not layout.bodies:
        return None
    tensors = np.zeros((len(layout.components), 3, 3))
    indices, bodies = zip(*layout.bodies)
    tensors[list(indices)] = own_tensors_of(bodies)
    return tensors


def own_inertia(component):
    """Return a component's inertia tensor about its centre of mass, own frame (kg m^2)."""
    return tensor_from_elements(*own_elements(component))


def own_elements(component):
    """
    Return a component's own tensor elements (ixx, iyy, izz, ixy, ixz, iyz), kg m^2.

    About its centre of mass, own (radial, tangential, axial) frame; plain floats.
    """
    if component.inertia is not None:
        return tuple(component.inertia)
    shape = component.shape
    if shape is None or shape.type == 'point':
        return (0.0,) * 6
    m = component.mass
    if shape.type == 'cylinder':
        return shapes.solid_cylinder_elements(m, shape.radius, shape.length, shape.axis)
    if shape.type == 'tube':
        return shapes.tube_elements(m, shape.inner_radius, shape.outer_radius, shape.length,
                                    shape.axis)
    if shape.type == 'box':
        return shapes.box_elements(m, shape.size)
    return shapes.sphere_elements(m, shape.radius)


def rotor_frame_loads(model, cos_q, sin_q, omega, alpha, gravity):
    """
    Load on the stator about O, rotor frame, and the drive torque.

    Plain arithmetic: works on floats (the per-message path) and on numpy
    arrays (the vectorised path). ``gravity`` = (g_x, g_y, g_z), stator frame.
    Returns (F_x, F_y, F_z, M_x, M_y, drive_torque): N, N m.
    """
    g_x, g_y, g_z = gravity
    gr_x, gr_y = turn_xy(g_x, g_y, cos_q, -sin_q)
    w2 = omega * omega
    m, s_x, s_y, s_z = model.mass, model.s_x, model.s_y, model.s_z
    f_x = m * gr_x + w2 * s_x + alpha * s_y
    f_y = m * gr_y + w2 * s_y - alpha * s_x
    f_z = m * g_z
    if model.moments:
        m_x = s_y * g_z - s_z * gr_y + alpha * model.p_xz - w2 * model.p_yz
        m_y = s_z * gr_x - s_x * g_z + alpha * model.p_yz + w2 * model.p_xz
    else:
        m_x = m_y = 0.0
    torque = model.i_zz * alpha - (s_x * gr_y - s_y * gr_x)
    return f_x, f_y, f_z, m_x, m_y, torque


def support_loads(supports, f_x, f_y, f_z, m_x, m_y):
    """
    Split a load (force, moment about O) over the supports on the axis.

    Any frame turning about Z (the supports are on the axis). Two supports:
    the force at each, the axial force on the one marked axial, no moments.
    One support: its force and tilting moment about the support point.
    Returns one (force, moment) pair of 3-tuples per support.
    """
    if len(supports) == 1:
        z = supports[0].z
        return [((f_x, f_y, f_z), (m_x + z * f_y, m_y - z * f_x, 0.0))]
    a, b = supports
    span = b.z - a.z
    force_a = ((b.z * f_x - m_y) / span, (b.z * f_y + m_x) / span, f_z if a.axial else 0.0)
    force_b = ((m_y - a.z * f_x) / span, (-m_x - a.z * f_y) / span, f_z if b.axial else 0.0)
    moment = (0.0, 0.0, 0.0)
    return [(force_a, moment), (force_b, moment)]


@dataclass(frozen=True)
class SampleLoads:
    """
    Loads for one motion sample (floats; N, N m).

    ``*_stator`` in the stator frame, ``*_rotor`` in the rotor frame, moments
    about O; ``supports`` maps each support's name to (force, moment), stator
    frame, moment about the support point.
    """

    force_rotor: tuple
    moment_rotor: tuple
    force_stator: tuple
    moment_stator: tuple
    drive_torque: float
    supports: dict


def sample_loads(model, q, omega, alpha=0.0, gravity=None):
    """Compute the loads for one sample in plain Python floats (no numpy: the live path)."""
    cos_q, sin_q = math.cos(q), math.sin(q)
    g = model.gravity if gravity is None else gravity
    f_x, f_y, f_z, m_x, m_y, torque = rotor_frame_loads(model, cos_q, sin_q, omega, alpha, g)
    fs_x, fs_y = turn_xy(f_x, f_y, cos_q, sin_q)
    ms_x, ms_y = turn_xy(m_x, m_y, cos_q, sin_q)
    per_support = support_loads(model.supports, fs_x, fs_y, f_z, ms_x, ms_y)
    return SampleLoads((f_x, f_y, f_z), (m_x, m_y, 0.0), (fs_x, fs_y, f_z), (ms_x, ms_y, 0.0),
                       torque, {s.name: load for s, load in zip(model.supports, per_support)})


@dataclass(frozen=True)
class Loads:
    """
    Loads over n motion samples; each field an (n, 3) or (n,) array view.

    Same meanings as :class:`SampleLoads`; ``support_force`` and
    ``support_moment`` map support names to (n, 3) arrays, stator frame.
    """

    force_rotor: np.ndarray
    moment_rotor: np.ndarray
    force_stator: np.ndarray
    moment_stator: np.ndarray
    drive_torque: np.ndarray
    support_force: dict
    support_moment: dict

    def __len__(self):
        """Return the number of samples."""
        return len(self.drive_torque)


def loads(model, q, omega, alpha=0.0, gravity=None):
    """
    Compute the loads for arrays of motion samples, vectorised.

    ``q`` (rad), ``omega`` (rad/s), ``alpha`` (rad/s^2) broadcast to n
    samples; ``gravity`` is a stator-frame 3-vector or an (n, 3) array (tilt
    that changes over the run), default the layout's.
    """
    q, omega, alpha = np.broadcast_arrays(np.asarray(q, float), np.asarray(omega, float),
                                          np.asarray(alpha, float))
    q, omega, alpha = q.ravel(), omega.ravel(), alpha.ravel()
    n = q.size
    g = np.asarray(model.gravity if gravity is None else gravity, dtype=float)
    per_sample_gravity = g.ndim == 2
    n_support = len(model.supports)
    # Rows: F_rotor(3) M_rotor(3) F_stator(3) M_stator(3) torque(1) supports(6 each).
    out = np.zeros((13 + 6 * n_support, n))

    def fill(start):
        part = slice(start, min(start + CHUNK, n))
        q_part = q[part]
        cos_q, sin_q = np.cos(q_part), np.sin(q_part)
        g_part = tuple(g[part, i] for i in range(3)) if per_sample_gravity else tuple(g)
        f_x, f_y, f_z, m_x, m_y, torque = rotor_frame_loads(
            model, cos_q, sin_q, omega[part], alpha[part], g_part)
        fs_x, fs_y = turn_xy(f_x, f_y, cos_q, sin_q)
        ms_x, ms_y = turn_xy(m_x, m_y, cos_q, sin_q) if model.moments else (0.0, 0.0)
        rows = [f_x, f_y, f_z, m_x, m_y, 0.0, fs_x, fs_y, f_z, ms_x, ms_y, 0.0, torque]
        for force, moment in support_loads(model.supports, fs_x, fs_y, f_z, ms_x, ms_y):
            rows.extend(force)
            rows.extend(moment)
        for row, value in enumerate(rows):
            if not (isinstance(value, float) and value == 0.0):  # out starts at zero
                out[row, part] = value

    starts = range(0, n, CHUNK)
    if len(starts) > 1:
        # numpy releases the GIL inside each call: blocks run on all cores.
        list(pool().map(fill, starts))
    else:
        for start in starts:
            fill(start)
    names = [s.name for s in model.supports]
    return Loads(out[0:3].T, out[3:6].T, out[6:9].T, out[9:12].T, out[12],
                 {name: out[13 + 6 * i:16 + 6 * i].T for i, name in enumerate(names)},
                 {name: out[16 + 6 * i:19 + 6 * i].T for i, name in enumerate(names)})
