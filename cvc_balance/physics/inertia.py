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
import math
import os

import numpy as np

from cvc_balance.physics import compensated as dd
from cvc_balance.physics.frames import tensor_from_elements
from cvc_balance.physics.workers import pool

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
    scalars. Vectorised in blocks of :data:`compensated.BLOCK` components spread
    over the worker threads (numpy releases the GIL).

    The terms are those of :func:`parallel_axis_cvc` (the own tensor turned by
    theta, plus the shift), each evaluated to ~2^-100 of itself in double-double
    and summed exactly (:mod:`cvc_balance.physics.compensated`): each aggregate is
    within an ulp or so of the exact sum for the given numbers, so a layout balanced
    to 1e-9 of its mass moment keeps its residual unbalance to ~1e-16, not ~1e-7.
    """
    mass = np.atleast_1d(np.asarray(mass, dtype=float))
    arrays = [np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), mass.shape))
              for v in (mass, radius, angle, z)]
    own = None
    if inertia_own is not None:
        own = np.broadcast_to(np.asarray(inertia_own, dtype=float), mass.shape + (3, 3))
    n = mass.size
    top = [float(np.max(np.abs(v))) if n else 0.0 for v in arrays]
    fast = top[2] <= dd.cos_sin_fast_limit()
    bounds = _bounds(top[0], top[1], top[3])
    blocks = [(start, min(start + dd.BLOCK, n)) for start in range(0, n, dd.BLOCK)]
    # A few blocks are done sooner here than handed over (and waited for) on a busy machine.
    workers = (os.cpu_count() or 1) if len(blocks) >= _THREADED_BLOCKS else 1
    share = max(-(-len(blocks) // workers), 1)
    shares = [blocks[k:k + share] for k in range(0, len(blocks), share)]
    if len(shares) <= 1:
        partials = [_place_blocks(blocks, arrays, own, bounds, fast)]
    else:
        jobs = [pool().submit(_place_blocks, part, arrays, own, bounds, fast)
                for part in shares]
        partials = [job.result() for job in jobs]
    return _assemble(partials)


_THREADED_BLOCKS = 4

# The sums, in the rows of the kernel's stacked arrays: terms of either sign (summed to
# ~2^-100 of sum |terms|) and terms of one sign (no cancellation: one level suffices).
_SIGNED = ('mx', 'my', 'mz', 'mxz', 'myz', 'mxy')
_POSITIVE = ('m', 'mxx', 'myy', 'mzz')
_OWN_POSITIVE = ('oxx', 'oyy', 'ozz')
_OWN_SIGNED = ('c2d', 'csd', 'c2b', 'csb', 'b', 'cxz', 'syz', 'sxz', 'cyz')


def _bounds(m, r, h):
    """Powers of two above the largest |term| of each sum, from max |m|, |R|, |z|."""
    slack = 1.0 + 2.0 ** -40            # products of rounded factors, |cos| ~ 1 + 2^-52
    values = {'m': m, 'mx': m * r, 'my': m * r, 'mz': m * h, 'mxz': m * r * h,
              'myz': m * r * h, 'mxy': m * r * r, 'mxx': m * r * r, 'myy': m * r * r,
              'mzz': m * h * h}
    return {name: dd.power_of_two_above(value * slack) for name, value in values.items()}


def _place_blocks(blocks, arrays, own, bounds, fast):
    """Partial sums of the aggregates' terms over some blocks (one worker's share)."""
    sums = {name: [] for name in _SIGNED + _POSITIVE + _OWN_POSITIVE + _OWN_SIGNED}
    s = dd.scratch()
    for start, stop in blocks:
        views = [a[start:stop] for a in arrays]
        _place_block(*views, None if own is None else own[start:stop], bounds, fast, sums, s)
    return sums


def _place_block(mass, radius, angle, z, own, bounds, fast, sums, s):
    """
    Add one block's partial sums (floats whose exact sum is the block's sum) to sums.

    Every product is exact (Dekker's two-product on split factors) up to its
    low-order parts; rows of stacked arrays share each numpy call. s: the scratch.
    """
    n = mass.size

    def rows(name, k):
        return s(name, n, rows=k)

    def parts(value, name):
        k = None if value.ndim == 1 else value.shape[0]
        hi, lo = s(name + '_1', n, rows=k), s(name + '_2', n, rows=k)
        dd.split_into(value, hi, lo)
        return hi, lo

    cs, cs_lo = dd.cos_sin_into(angle, s, fast)         # rows cos, sin
    w = rows('work', 6)
    m_p, r_p, z_p, cs_p = parts(mass, 'm'), parts(radius, 'R'), parts(z, 'z'), parts(cs, 'cs')
    # Centre of mass in the rotor frame, rows x = R cos, y = R sin.
    xy, xy_lo = rows('xy', 2), rows('xy_lo', 2)
    dd.two_prod_into(cs, cs_p, radius, r_p, xy, xy_lo, w[:2])
    dd.add_product(xy_lo, cs_lo, radius, w[:2])
    xy_p = parts(xy, 'xy')
    # First moments, rows m x, m y, m z; the second moments from them.
    first, first_lo = rows('first', 3), rows('first_lo', 3)
    dd.two_prod_into(xy, xy_p, mass, m_p, first[:2], first_lo[:2], w[:2])
    dd.add_product(first_lo[:2], xy_lo, mass, w[:2])
    dd.two_prod_into(z, z_p, mass, m_p, first[2], first_lo[2], w[0])
    first_p = parts(first, 'first')
    # Rows m x z, m y z, m x y (either sign), m x x, m y y, m z z (positive).
    second, second_lo = rows('second', 6), rows('second_lo', 6)
    dd.two_prod_into(first[:2], (first_p[0][:2], first_p[1][:2]), z, z_p,
                     second[:2], second_lo[:2], w[:2])
    dd.add_product(second_lo[:2], first_lo[:2], z, w[:2])
    dd.two_prod_into(first[0], (first_p[0][0], first_p[1][0]), xy[1], (xy_p[0][1], xy_p[1][1]),
                     second[2], second_lo[2], w[0])
    dd.add_product(second_lo[2], first_lo[0], xy[1], w[0])
    dd.add_product(second_lo[2], first[0], xy_lo[1], w[0])
    dd.two_prod_into(first[:2], (first_p[0][:2], first_p[1][:2]), xy, xy_p,
                     second[3:5], second_lo[3:5], w[:2])
    dd.add_product(second_lo[3:5], first_lo[:2], xy, w[:2])
    dd.add_product(second_lo[3:5], first[:2], xy_lo, w[:2])
    dd.two_prod_into(first[2], (first_p[0][2], first_p[1][2]), z, z_p,
                     second[5], second_lo[5], w[0])
    dd.add_product(second_lo[5], first_lo[2], z, w[0])
    rest = rows('rest', 6)
    _add_sums(sums, ('mx', 'my', 'mz'), first, first_lo, bounds, 2, w[:3], rest[:3])
    _add_sums(sums, ('mxz', 'myz', 'mxy'), second[:3], second_lo[:3], bounds, 2, w[:3],
              rest[:3])
    _add_sums(sums, ('mxx', 'myy', 'mzz'), second[3:], second_lo[3:], bounds, 1, w[:3],
              rest[:3])
    _add_sums(sums, ('m',), mass[None], None, bounds, 1, w[:1], rest[:1])
    if own is not None:
        _own_block(own, cs, cs_lo, cs_p, s, sums)


def _add_sums(sums, names, hi, lo, bounds, levels, work, rest):
    """Append the rows' partial sums to sums[name] (bounds: a dict or one bound)."""
    row_bounds = [bounds[name] if isinstance(bounds, dict) else bounds for name in names]
    for name, values in zip(names, dd.partial_sums_into(hi, lo, row_bounds, levels, work,
                                                        rest)):
        sums[name].extend(values.tolist())


def _own_block(own, cs, cs_lo, cs_p, s, sums):
    """
    The own tensors turned by theta (R I R^T), element sums added to sums.

    With d = I_xx - I_yy and b = I_xy (own frame): turned xx = I_yy + c^2 d - 2 c s b,
    yy = I_xx - c^2 d + 2 c s b, xy = c s d + (2 c^2 - 1) b, xz = c I_xz - s I_yz,
    yz = s I_xz + c I_yz, zz = I_zz. Terms that are zero in the whole block are skipped.
    """
    n = own.shape[0]

    def rows(name, k):
        return s(name, n, rows=k)

    block = rows('own', 6)              # rows I_xx, I_yy, I_zz, I_xy, I_xz, I_yz
    for row, (i, j) in zip(block, ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        np.copyto(row, own[:, i, j])
    w, rest = rows('work', 8), rows('rest', 8)
    # Every term is at most |I_xx - I_yy| <= 2 max |element|.
    top = max(float(np.max(block)), -float(np.min(block)))
    bound = dd.power_of_two_above(2.0 * top * (1.0 + 2.0 ** -40))
    _add_sums(sums, _OWN_POSITIVE, block[:3], None, bound, 1, w[:3], rest[:3])
    c, c_lo, c_p = cs[0], cs_lo[0], (cs_p[0][0], cs_p[1][0])
    terms, terms_lo = rows('own_terms', 8), rows('own_terms_lo', 8)
    names = []
    d, d_lo = rows('d', 2)
    dd.two_sum_into(block[0], block[1], d, d_lo, w[0], subtract=True)
    b = block[3]
    has_d, has_b = bool(np.any(d)), bool(np.any(b))
    if has_d or has_b:
        # c^2 and c s, double-double.
        c2cs, c2cs_lo = rows('c2cs', 2), rows('c2cs_lo', 2)
        dd.two_prod_into(c, c_p, cs, cs_p, c2cs, c2cs_lo, w[:2])
        dd.add_product(c2cs_lo, c, cs_lo, w[:2])
        dd.add_product(c2cs_lo, c_lo, cs, w[:2])
        c2cs_p = (rows('c2cs_1', 2), rows('c2cs_2', 2))
        dd.split_into(c2cs, *c2cs_p)
        k = 0
        for value, value_lo, value_names in ((d, d_lo, ('c2d', 'csd')), (b, None, ('c2b', 'csb'))):
            if not np.any(value):
                continue
            value_p = (rows('own_1', 1)[0], rows('own_2', 1)[0])
            dd.split_into(value, *value_p)
            dd.two_prod_into(c2cs, c2cs_p, value, value_p, terms[k:k + 2], terms_lo[k:k + 2],
                             w[:2])
            dd.add_product(terms_lo[k:k + 2], c2cs_lo, value, w[:2])
            if value_lo is not None:
                dd.add_product(terms_lo[k:k + 2], c2cs, value_lo, w[:2])
            names += value_names
            k += 2
        if has_b:
            _add_sums(sums, ('b',), b[None], None, bound, 2, w[:1], rest[:1])
    oxz, oyz = block[4], block[5]
    if np.any(oxz) or np.any(oyz):
        for value, value_names in ((oxz, ('cxz', 'sxz')), (oyz, ('cyz', 'syz'))):
            k = len(names)
            value_p = (rows('own_1', 1)[0], rows('own_2', 1)[0])
            dd.split_into(value, *value_p)
            dd.two_prod_into(cs, cs_p, value, value_p, terms[k:k + 2], terms_lo[k:k + 2],
                             w[:2])
            dd.add_product(terms_lo[k:k + 2], cs_lo, value, w[:2])
            names += value_names
    if names:
        k = len(names)
        _add_sums(sums, names, terms[:k], terms_lo[:k], bound, 2, w[:k], rest[:k])


def _assemble(partials):
    """MassProperties from the workers' partial sums: each aggregate one math.fsum."""
    sums = {name: [v for part in partials for v in part[name]] for name in partials[0]}

    def total(*terms):
        return math.fsum(sign * v for sign, name in terms for v in sums[name])

    inertia = np.zeros((3, 3))
    inertia[0, 0] = total((1, 'myy'), (1, 'mzz'), (1, 'oyy'), (1, 'c2d'), (-2, 'csb'))
    inertia[1, 1] = total((1, 'mxx'), (1, 'mzz'), (1, 'oxx'), (-1, 'c2d'), (2, 'csb'))
    inertia[2, 2] = total((1, 'mxx'), (1, 'myy'), (1, 'ozz'))
    inertia[0, 1] = inertia[1, 0] = total((-1, 'mxy'), (1, 'csd'), (2, 'c2b'), (-1, 'b'))
    inertia[0, 2] = inertia[2, 0] = total((-1, 'mxz'), (1, 'cxz'), (-1, 'syz'))
    inertia[1, 2] = inertia[2, 1] = total((-1, 'myz'), (1, 'sxz'), (1, 'cyz'))
    first = np.array([total((1, 'mx')), total((1, 'my')), total((1, 'mz'))])
    return MassProperties(total((1, 'm')), first, inertia)


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
