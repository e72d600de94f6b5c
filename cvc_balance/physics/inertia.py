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
import threading

import numpy as np

from cvc_balance.physics import compensated as dd
from cvc_balance.physics.frames import tensor_from_elements
from cvc_balance.physics.workers import in_pool, pool

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
    scalars. Vectorised in blocks of :data:`compensated.BLOCK` components, shared
    between this thread and :func:`workers.pool`'s (numpy releases the GIL); all in
    this thread when it is itself one of the pool's. ~0.1 s for 10^6 components on
    one core (``benchmarks/aggregation.py``).

    The terms are those of :func:`parallel_axis_cvc` (the own tensor turned by
    theta, plus the shift), each evaluated to ~2^-100 of itself in double-double
    and summed exactly (:mod:`cvc_balance.physics.compensated`): each aggregate is
    its exact value for the given numbers, rounded (unless it cancels below ~1e-17
    of its terms: then within ~1e-32 of them), so a layout balanced to 1e-9 of its
    mass moment keeps its residual unbalance to ~1e-16, not ~1e-7.
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
    # A few blocks are done sooner here than handed over (and waited for) on a busy machine;
    # in a worker thread (a layout aggregated off the input path) too: waiting there for
    # other workers could wait for ever.
    in_worker = in_pool()
    workers = (os.cpu_count() or 1) if len(blocks) >= _THREADED_BLOCKS and not in_worker else 1
    share = max(-(-len(blocks) // workers), 1)
    shares = [blocks[k:k + share] for k in range(0, len(blocks), share)] or [[]]
    jobs = [pool().submit(_place_blocks, part, arrays, own, bounds, fast)
            for part in shares[1:]]
    partials = [_place_blocks(shares[0], arrays, own, bounds, fast)]   # this thread's share
    return _assemble(partials + [job.result() for job in jobs])


_THREADED_BLOCKS = 4

# The sums, by the rows of the kernel's arrays they come from; levels of extraction:
# two for terms of either sign (summed to ~2^-100 of sum |terms|), one for terms of one
# sign (no cancellation: exact enough with one).
_SUMS = (('first', ('mx', 'my', 'mz'), 2), ('products', ('mxz', 'myz', 'mxy'), 2),
         ('squares', ('mxx', 'myy', 'mzz'), 1), ('mass', ('m',), 1))
_OWN_SUMS = {'own': (('own_diagonal', ('oxx', 'oyy', 'ozz'), 1),),
             'd': (('own_d', ('c2d', 'csd'), 2),),
             'b': (('own_b', ('c2b', 'csb'), 2), ('own_xy', ('b',), 2)),
             'xz': (('own_xz', ('cxz', 'sxz', 'cyz', 'syz'), 2),)}
_NAMES = [name for _, names, _ in _SUMS for name in names] + \
    [name for sums in _OWN_SUMS.values() for _, names, _ in sums for name in names]
_PROGRAMS = {}
_LOCAL = threading.local()


def _bounds(m, r, h):
    """Powers of two above the largest |term| of each sum, from max |m|, |R|, |z|."""
    slack = 1.0 + 2.0 ** -40            # products of rounded factors, |cos| ~ 1 + 2^-52
    return {name: dd.power_of_two_above(value * slack) for name, value in (
        ('m', m), ('mx', m * r), ('my', m * r), ('mz', m * h), ('mxz', m * r * h),
        ('myz', m * r * h), ('mxy', m * r * r), ('mxx', m * r * r), ('myy', m * r * r),
        ('mzz', m * h * h))}


def _program(fast, own):
    """Return the kernel of one block: angles reduced in it or not; own-tensor terms."""
    key = (fast, own)
    if key not in _PROGRAMS:
        t = dd.Tracer()
        _trace_place(t, fast, own)
        _PROGRAMS[key] = t.compile()
    return _PROGRAMS[key]


def _trace_place(t, fast, own):
    """
    Trace one block's terms and their partial sums.

    Every product is exact (Dekker's on split factors) up to its low-order parts.

    ``own``: which own-tensor terms the block has, a tuple of 'own', 'd' (I_xx !=
    I_yy), 'b' (I_xy), 'xz' (I_xz, I_yz); () for point masses.
    """
    mass, radius, z = (t.external(name) for name in ('mass', 'radius', 'z'))
    if fast:
        index, a, b = dd.trace_reduction(t, t.external('angle'))
    else:
        index, a, b = (t.external(name) for name in ('index', 'r_hi', 'r_lo'))
    cs, cs_lo = dd.trace_cos_sin(t, index, a, b)             # rows cos, sin
    m_p, r_p, z_p, cs_p = (dd.trace_split(t, v) for v in (mass, radius, z, cs))
    # Centre of mass in the rotor frame, rows x = R cos, y = R sin.
    xy, xy_lo = dd.trace_two_prod(t, cs, cs_p, radius, r_p)
    xy_lo += cs_lo * radius
    xy_p = dd.trace_split(t, xy)
    # First moments, rows m x, m y, m z.
    first, first_lo = t.new(3), t.new(3)
    dd.trace_two_prod(t, xy, xy_p, mass, m_p, out=(first[:2], first_lo[:2]))
    first_lo[:2] += xy_lo * mass
    dd.trace_two_prod(t, z, z_p, mass, m_p, out=(first[2], first_lo[2]))
    first_p = dd.trace_split(t, first)

    def row(parts, k):
        return parts[0][k], parts[1][k]

    # Second moments, rows m x z, m y z, m x y (either sign); m x x, m y y, m z z (positive).
    products, products_lo = t.new(3), t.new(3)
    dd.trace_two_prod(t, first[:2], (first_p[0][:2], first_p[1][:2]), z, z_p,
                      out=(products[:2], products_lo[:2]))
    products_lo[:2] += first_lo[:2] * z
    dd.trace_two_prod(t, first[0], row(first_p, 0), xy[1], row(xy_p, 1),
                      out=(products[2], products_lo[2]))
    products_lo[2] += first_lo[0] * xy[1]
    products_lo[2] += first[0] * xy_lo[1]
    squares, squares_lo = t.new(3), t.new(3)
    dd.trace_two_prod(t, first[:2], (first_p[0][:2], first_p[1][:2]), xy, xy_p,
                      out=(squares[:2], squares_lo[:2]))
    squares_lo[:2] += first_lo[:2] * xy
    squares_lo[:2] += first[:2] * xy_lo
    dd.trace_two_prod(t, first[2], row(first_p, 2), z, z_p, out=(squares[2], squares_lo[2]))
    squares_lo[2] += first_lo[2] * z
    terms = {'first': (first, first_lo), 'products': (products, products_lo),
             'squares': (squares, squares_lo), 'mass': (mass[None], None)}
    if own:
        terms.update(_trace_own(t, own, cs, cs_lo, cs_p))
    for group, names, levels in _SUMS + tuple(s for k in own for s in _OWN_SUMS[k]):
        hi, lo = terms[group]
        rows = len(names)
        dd.trace_partial_sums(t, hi, lo, t.external('sigma_' + group, rows, (rows, levels)),
                              levels, t.external('sums_' + group, rows, (rows, levels + 1)))


def _trace_own(t, own, cs, cs_lo, cs_p):
    """
    Trace the own tensors turned by theta (R I R^T): their terms, by sum group.

    With d = I_xx - I_yy and b = I_xy (own frame): turned xx = I_yy + c^2 d - 2 c s b,
    yy = I_xx - c^2 d + 2 c s b, xy = c s d + (2 c^2 - 1) b, xz = c I_xz - s I_yz,
    yz = s I_xz + c I_yz, zz = I_zz.
    """
    block = t.external('own', 6)                # rows I_xx, I_yy, I_zz, I_xy, I_xz, I_yz
    terms = {'own_diagonal': (block[:3], None)}
    c, c_lo, c_p = cs[0], cs_lo[0], (cs_p[0][0], cs_p[1][0])
    if 'd' in own or 'b' in own:
        # c^2 and c s, double-double.
        c2cs, c2cs_lo = dd.trace_two_prod(t, c, c_p, cs, cs_p)
        c2cs_lo += c * cs_lo
        c2cs_lo += c_lo * cs
        c2cs_p = dd.trace_split(t, c2cs)
    if 'd' in own:
        d, d_lo = dd.trace_two_sum(t, block[0], -block[1])
        product, product_lo = dd.trace_two_prod(t, c2cs, c2cs_p, d, dd.trace_split(t, d))
        product_lo += c2cs_lo * d
        product_lo += c2cs * d_lo
        terms['own_d'] = (product, product_lo)
    if 'b' in own:
        b = block[3]
        product, product_lo = dd.trace_two_prod(t, c2cs, c2cs_p, b, dd.trace_split(t, b))
        product_lo += c2cs_lo * b
        terms['own_b'] = (product, product_lo)
        terms['own_xy'] = (block[3:4], None)
    if 'xz' in own:
        product, product_lo = t.new(4), t.new(4)          # rows c I_xz, s I_xz, c I_yz, s I_yz
        for k, value in ((0, block[4]), (2, block[5])):
            dd.trace_two_prod(t, cs, cs_p, value, dd.trace_split(t, value),
                              out=(product[k:k + 2], product_lo[k:k + 2]))
            product_lo[k:k + 2] += cs_lo * value
        terms['own_xz'] = (product, product_lo)
    return terms


def _place_blocks(blocks, arrays, own, bounds, fast):
    """Partial sums of the aggregates' terms over some blocks (one worker's share)."""
    sums = {name: [] for name in _NAMES}
    mass, radius, angle, z = arrays
    sigmas = {}                          # block length -> group -> sigma (these bounds)
    for start, stop in blocks:
        n = stop - start
        inputs, programs = _inputs(n)
        for name, values in (('mass', mass), ('radius', radius), ('z', z)):
            np.copyto(inputs[name], values[start:stop])
        if fast:
            np.copyto(inputs['angle'], angle[start:stop])
        else:
            index, inputs['r_hi'][:], inputs['r_lo'][:] = dd.reduce_angles(angle[start:stop])
            inputs['index'].view(np.int64)[:] = index
        kinds = ()
        if own is not None:
            block = inputs['own']
            for row, (i, j) in zip(block, ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
                np.copyto(row, own[start:stop, i, j])
            kinds = ('own',) + tuple(kind for kind, present in (
                ('d', (block[0] != block[1]).any()), ('b', block[3].any()),
                ('xz', block[4].any() or block[5].any())) if present)
            # Every own term is at most |I_xx - I_yy| <= 2 max |element|.
            top = 2.0 * max(float(block.max()), -float(block.min())) * (1.0 + 2.0 ** -40)
            own_bound = dd.power_of_two_above(top)
        arrays_bound, run = dd.bound(programs, (fast, kinds, n), lambda: _program(fast, kinds),
                                     inputs)
        groups = _SUMS + tuple(s for k in kinds for s in _OWN_SUMS[k])
        if n not in sigmas:
            sigmas[n] = {group: dd.sigma_for(n, [bounds[name] for name in names], levels)
                         for group, names, levels in _SUMS}
        for group, names, levels in groups:
            arrays_bound['sigma_' + group][:] = (
                sigmas[n][group] if group in sigmas[n]
                else dd.sigma_for(n, [own_bound] * len(names), levels))
        run()
        for group, names, levels in groups:
            for name, row in zip(names, arrays_bound['sums_' + group].tolist()):
                sums[name] += row
    return sums


def _inputs(n):
    """
    Return this thread's input arrays for blocks of n, and the programs bound to them.

    Shared by the kernel's variants; the few most recent n are kept.
    """
    cache = getattr(_LOCAL, 'inputs', None)
    if cache is None:
        cache = _LOCAL.inputs = {}
    if n in cache:
        cache[n] = cache.pop(n)                     # most recent last
    else:
        while len(cache) >= 4:
            cache.pop(next(iter(cache)))            # with the programs bound to them
        cache[n] = ({name: np.empty((rows, n)) if rows else np.empty(n) for name, rows in (
            ('mass', None), ('radius', None), ('z', None), ('angle', None), ('index', None),
            ('r_hi', None), ('r_lo', None), ('own', 6))}, {})
    return cache[n]


def _assemble(partials):
    """Add up the workers' partial sums: each aggregate one math.fsum."""
    sums = {name: [v for part in partials for v in part[name]] for name in _NAMES}

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
