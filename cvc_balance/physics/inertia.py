"""
Mass properties as composable values, and the inertia of the layout's shapes.

A :class:`MassProperties` is mass, first mass moment and inertia tensor about
the origin of the frame it is expressed in, like Pinocchio's ``Inertia``:
values add (``a + b`` is the two bodies bolted together). :func:`place` puts
a body given about its own centre of mass, in its own (radial, tangential,
axial) frame, at the cylindrical vector components (R, theta, z) of the rotor
frame, by the thesis's CVC parallel-axis theorem
(Eq. 3.7, with its last line corrected: NOTES.md erratum 5).

Units: kg, m, kg m, kg m^2. Tensors hold tensor elements (see
:mod:`cvc_balance.physics.frames`). numpy only.
"""

from dataclasses import dataclass

import numpy as np

from cvc_balance.physics import compensated as dd
from cvc_balance.physics.frames import tensor_from_elements

SHAPE_AXES = ('radial', 'tangential', 'axial')
"""Directions a shape's symmetry axis can take, own-frame x, y, z."""


@dataclass(frozen=True)
class MassProperties:
    """
    Mass, first moment and inertia tensor about the frame origin O.

    ``first_moment`` is int r dm (kg m, shape (3,)); ``inertia`` the 3x3
    tensor about O (kg m^2, tensor elements).
    """

    mass: float
    first_moment: np.ndarray
    inertia: np.ndarray

    def __add__(self, other):
        """Two bodies rigidly joined, both expressed in the same frame."""
        return MassProperties(self.mass + other.mass,
                              self.first_moment + other.first_moment,
                              self.inertia + other.inertia)

    @property
    def com(self):
        """Centre of mass, m (undefined for zero mass)."""
        return self.first_moment / self.mass

    def inertia_about_com(self):
        """Inertia tensor about the centre of mass, same axes (kg m^2)."""
        c = self.com
        return self.inertia - self.mass * (c @ c * np.eye(3) - np.outer(c, c))


def parallel_axis_cvc(inertia_com, mass, r_o, phi_o, z_o):
    """
    Inertia about a point B from the inertia about the centre of mass G.

    The thesis's Eq. 3.7 in cylindrical vector components: the centre of mass
    lies at (r_o cos phi_o, r_o sin phi_o, z_o) from B, axes parallel. Works
    on one tensor (3, 3) or a stack (n, 3, 3) with (n,) parameters. Returns
    tensor elements; the products of inertia shift by
    P_xy += m r_o^2 cos sin, P_xz += m r_o z_o cos, P_yz += m r_o z_o sin.
    """
    mass = np.asarray(mass, dtype=float)
    c, s = np.cos(phi_o), np.sin(phi_o)
    shifted = np.array(inertia_com, dtype=float, copy=True)
    shifted[..., 0, 0] += mass * (r_o**2 * s**2 + z_o**2)
    shifted[..., 1, 1] += mass * (r_o**2 * c**2 + z_o**2)
    shifted[..., 2, 2] += mass * r_o**2
    p_xy = mass * r_o**2 * c * s
    p_xz = mass * r_o * z_o * c
    p_yz = mass * r_o * z_o * s
    for (i, j), p in (((0, 1), p_xy), ((0, 2), p_xz), ((1, 2), p_yz)):
        shifted[..., i, j] -= p
        shifted[..., j, i] -= p
    return shifted


def place(mass, inertia_own, radius, angle, z):
    """
    Bodies placed on the rotor at (R, theta, z), summed into one value.

    ``inertia_own`` is each body's tensor about its centre of mass in its own
    (radial, tangential, axial) frame, shape (n, 3, 3) (or (3, 3) for one),
    or None for point masses;
    ``mass``, ``radius`` (m), ``angle`` (rad) and ``z`` (m) are (n,) or
    scalars. Vectorised: the cost is a few numpy calls whatever n is.

    The terms are those of :func:`parallel_axis_cvc` (the own tensor turned by
    theta, plus the shift), evaluated and summed in double-double
    (:mod:`cvc_balance.physics.compensated`): each aggregate is within an ulp or so of
    the exact sum for the given numbers, so a layout balanced to 1e-9 of its mass
    moment keeps its residual unbalance to ~1e-16, not ~1e-7.
    """
    mass = np.atleast_1d(np.asarray(mass, dtype=float))
    radius = np.broadcast_to(np.asarray(radius, dtype=float), mass.shape)
    angle = np.broadcast_to(np.asarray(angle, dtype=float), mass.shape)
    z = np.broadcast_to(np.asarray(z, dtype=float), mass.shape)
    c, s = dd.cos_sin(angle)
    x, y = dd.scale(c, radius), dd.scale(s, radius)          # centre of mass, rotor frame
    first = [dd.scale(x, mass), dd.scale(y, mass), dd.two_prod(mass, z)]
    # The shift to O (tensor elements: products enter with a minus sign).
    m_x2, m_y2 = dd.mul(first[0], x), dd.mul(first[1], y)
    m_z2 = dd.scale(first[2], z)
    elements = {
        (0, 0): dd.add(m_y2, m_z2),
        (1, 1): dd.add(m_x2, m_z2),
        (2, 2): dd.scale(dd.two_prod(radius, radius), mass),
        (0, 1): dd.negate(dd.mul(first[0], y)),
        (0, 2): dd.negate(dd.scale(first[0], z)),
        (1, 2): dd.negate(dd.scale(first[1], z)),
    }
    if inertia_own is not None:
        own = np.broadcast_to(np.asarray(inertia_own, dtype=float), mass.shape + (3, 3))
        for key, turned in _turned_elements(own, c, s).items():
            elements[key] = dd.add(elements[key], turned)
    inertia = np.zeros((3, 3))
    for (i, j), value in elements.items():
        inertia[i, j] = inertia[j, i] = dd.total(value)
    total_mass = dd.total((mass, np.zeros_like(mass)))
    return MassProperties(total_mass, np.array([dd.total(v) for v in first]), inertia)


def _turned_elements(own, c, s):
    """Own tensors turned by theta about Z (R I R^T), element by element, double-double."""
    cc, ss, cs = dd.mul(c, c), dd.mul(s, s), dd.mul(c, s)
    o_xx, o_yy, o_zz = own[:, 0, 0], own[:, 1, 1], own[:, 2, 2]
    o_xy, o_xz, o_yz = own[:, 0, 1], own[:, 0, 2], own[:, 1, 2]
    two_cs_xy = dd.scale(cs, 2.0 * o_xy)
    turned_xx = dd.add(dd.add(dd.scale(cc, o_xx), dd.scale(ss, o_yy)), dd.negate(two_cs_xy))
    turned_yy = dd.add(dd.add(dd.scale(ss, o_xx), dd.scale(cc, o_yy)), two_cs_xy)
    turned_xy = dd.add(dd.scale(cs, o_xx - o_yy), dd.scale(dd.add(cc, dd.negate(ss)), o_xy))
    turned_xz = dd.add(dd.scale(c, o_xz), dd.negate(dd.scale(s, o_yz)))
    turned_yz = dd.add(dd.scale(s, o_xz), dd.scale(c, o_yz))
    zeros = np.zeros_like(o_zz)
    return {(0, 0): turned_xx, (1, 1): turned_yy, (2, 2): (o_zz, zeros), (0, 1): turned_xy,
            (0, 2): turned_xz, (1, 2): turned_yz}


def solid_cylinder(mass, radius, length, axis='axial'):
    """Solid cylinder about its centre of mass, own frame (kg m^2)."""
    return tensor_from_elements(*solid_cylinder_elements(mass, radius, length, axis))


def solid_cylinder_elements(mass, radius, length, axis='axial'):
    """Solid cylinder's tensor elements (ixx, iyy, izz, ixy, ixz, iyz), own frame."""
    along = 0.5 * mass * radius**2
    across = mass * (3.0 * radius**2 + length**2) / 12.0
    return _axisymmetric(along, across, axis)


def tube(mass, inner_radius, outer_radius, length, axis='axial'):
    """Inertia of a thick-walled hollow cylinder about its centre of mass, own frame."""
    return tensor_from_elements(*tube_elements(mass, inner_radius, outer_radius, length, axis))


def tube_elements(mass, inner_radius, outer_radius, length, axis='axial'):
    """Thick-walled tube's tensor elements (ixx, iyy, izz, ixy, ixz, iyz), own frame."""
    r2 = inner_radius**2 + outer_radius**2
    along = 0.5 * mass * r2
    across = mass * (3.0 * r2 + length**2) / 12.0
    return _axisymmetric(along, across, axis)


def box_elements(mass, size):
    """Solid box's tensor elements (ixx, iyy, izz, ixy, ixz, iyz), own frame; ``size`` m."""
    a, b, c = size
    return (mass * (b**2 + c**2) / 12.0, mass * (a**2 + c**2) / 12.0,
            mass * (a**2 + b**2) / 12.0, 0.0, 0.0, 0.0)


def sphere_elements(mass, radius):
    """Solid sphere's tensor elements (ixx, iyy, izz, ixy, ixz, iyz)."""
    i = 0.4 * mass * radius**2
    return (i, i, i, 0.0, 0.0, 0.0)


def _axisymmetric(along, across, axis):
    diagonal = [across, across, across]
    diagonal[SHAPE_AXES.index(axis)] = along
    return (*diagonal, 0.0, 0.0, 0.0)
