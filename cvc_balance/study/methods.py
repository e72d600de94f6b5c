"""
Ways to compute a layout's loads over motion samples, side by side, behind one interface.

Each method is ``prepare(layout) -> state`` and ``compute(state, q, omega, alpha,
gravity) -> (force_rotor (n, 3), moment_rotor (n, 3), drive_torque (n,))``: the load on
the stator in the rotor frame, moment about O (its Z part 0), as the engine defines them.

* ``aggregated``: the project's engine (layout aggregates once, O(1) per sample);
* ``aggregated_f32``: the same in float32;
* ``thesis_particles``: Eq. 4.39-4.41: point masses at the centres of mass, summed per
  sample; centripetal and gravity terms only (the thesis's alpha = 0), and its F1 = F2
  shortcut: no bearing moment. Gravity as the physics has it (see test_thesis.py);
* ``thesis_cylinders``: Eq. 5.6 (corrected, NOTES.md 2-3): forces as above, the inertia
  tensor summed per body in the plane (no products with z), so again no bearing moment,
  and drive torque I_zz alpha plus gravity;
* ``newton_euler``: Cartesian Newton-Euler over the bodies, a rotation matrix per body per
  sample, stator frame, turned back to the rotor frame;
* ``euler_zxz``: the same with each body's orientation from ZXZ Euler angles (q, 0,
  theta): three matrices per body per sample (at nutation 0, the gimbal-lock case);
* ``particles_N``: each rigid body cut into about N particles (grids in its volume;
  a body given by its inertia tensor: 6 points on its principal axes that reproduce it),
  Newton per particle, per sample.
"""

import math

import numpy as np

from cvc_balance.physics.engine import loads, own_inertia, RotorModel, rotor_frame_loads
from cvc_balance.physics.frames import turn_xy


def _zeros_moment(n):
    return np.zeros((n, 3))


# -- the aggregated engine ------------------------------------------------------------

def aggregated(layout):
    """Prepare: the engine's aggregates."""
    return RotorModel.from_layout(layout)


def aggregated_compute(model, q, omega, alpha, gravity):
    """Compute with the engine (float64)."""
    result = loads(model, q, omega, alpha, gravity)
    return result.force_rotor, result.moment_rotor, result.drive_torque


class _Float32Model:
    """The engine's aggregates as float32 numbers."""

    moments = True

    def __init__(self, model):
        for name in ('mass', 's_x', 's_y', 's_z', 'p_xz', 'p_yz', 'i_zz'):
            setattr(self, name, np.float32(getattr(model, name)))


def aggregated_f32(layout):
    """Prepare: the engine's aggregates in float32."""
    return _Float32Model(RotorModel.from_layout(layout))


def aggregated_f32_compute(model, q, omega, alpha, gravity):
    """Compute the engine's equations in float32 throughout."""
    q, omega, alpha = (np.asarray(v, np.float32) for v in (q, omega, alpha))
    g = tuple(np.float32(v) for v in gravity)
    f_x, f_y, f_z, m_x, m_y, torque = rotor_frame_loads(
        model, np.cos(q), np.sin(q), omega, alpha, g)
    n = len(q)
    force = np.stack([f_x, f_y, np.full(n, f_z, np.float32)], 1)
    moment = np.stack([m_x, m_y, np.zeros(n, np.float32)], 1)
    return force, moment, torque


# -- summing over bodies, in order ----------------------------------------------------

CHUNK = 1 << 15
"""Body-samples (particle-samples) computed at once: the work arrays stay in cache."""


def _chunks(bodies, samples):
    """Slices of ``bodies`` of at most :data:`CHUNK` body-samples each."""
    step = max(1, CHUNK // max(samples, 1))
    return [slice(start, min(start + step, bodies)) for start in range(0, bodies, step)]


def _sum_rows(total, rows, ufunc=np.add):
    """Return ``total`` op rows[0] op rows[1] ..., in that order: a loop over bodies' rounding."""
    return ufunc.reduce(np.concatenate([total[None], rows]), axis=0)


# -- the thesis's sums ----------------------------------------------------------------

def thesis_particles(layout):
    """Prepare: each component's mass and centre of mass (x, y) in the rotor frame."""
    components = layout.components
    return (np.array([c.mass for c in components], float),
            np.array([c.radius * math.cos(c.angle) for c in components], float),
            np.array([c.radius * math.sin(c.angle) for c in components], float)), None


def thesis_particles_compute(state, q, omega, alpha, gravity):
    """Eq. 4.39-4.41 summed per sample: no alpha, no bearing moment (F1 = F2)."""
    (mass, x_all, y_all), i_zz = state
    g_x, g_y, g_z = gravity
    c, s = np.cos(q), np.sin(q)
    gr_x, gr_y = turn_xy(g_x, g_y, c, -s)
    w2 = omega * omega
    n = len(q)
    f_x, f_y, f_z = np.zeros(n), np.zeros(n), np.zeros(n)
    torque = np.zeros(n) if i_zz is None else i_zz * alpha
    for part in _chunks(len(mass), n):
        m, x, y = mass[part, None], x_all[part, None], y_all[part, None]
        f_x = _sum_rows(f_x, m * (gr_x + w2 * x))
        f_y = _sum_rows(f_y, m * (gr_y + w2 * y))
        f_z = _sum_rows(f_z, np.broadcast_to(m * g_z, (len(m), n)))
        torque = _sum_rows(torque, m * (x * gr_y - y * gr_x), np.subtract)
    return np.stack([f_x, f_y, f_z], 1), _zeros_moment(n), torque


def thesis_cylinders(layout):
    """Prepare: masses and places, and I_zz summed per body (Eq. 5.6, corrected)."""
    bodies, _ = thesis_particles(layout)
    i_zz = 0.0
    for component in layout.components:
        own, m, r = own_inertia(component), component.mass, component.radius
        i_zz += own[2, 2] + m * r * r           # Eq. 5.6's I_ZZ: own + m (r + R_i)^2
    return bodies, i_zz


thesis_cylinders_compute = thesis_particles_compute


# -- Cartesian Newton-Euler with rotation matrices -------------------------------------

def newton_euler(layout):
    """Prepare: per body mass, centre of mass (rotor frame), own tensor, angle theta."""
    components = layout.components
    return (np.array([c.mass for c in components], float),
            np.array([[c.radius * math.cos(c.angle), c.radius * math.sin(c.angle), c.z]
                      for c in components], float).reshape(-1, 3),
            np.array([own_inertia(c) for c in components], float).reshape(-1, 3, 3),
            np.array([c.angle for c in components], float))


def _rotation(angle, axis):
    """Rotation matrices (..., 3, 3) by ``angle`` about coordinate axis ``axis`` (0 x, 2 z)."""
    i, j = [k for k in range(3) if k != axis]
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., i, i], out[..., i, j], out[..., j, i], out[..., j, j] = c, -s, s, c
    out[..., axis, axis] = 1.0
    return out


def _newton_euler(bodies, q, omega, alpha, gravity, orientation):
    masses, centres, owns, thetas = bodies
    n = len(q)
    w = np.zeros((n, 3))
    w[:, 2] = omega
    a = np.zeros((n, 3))
    a[:, 2] = alpha
    g = np.broadcast_to(np.asarray(gravity, float), (n, 3))
    rotor = _rotation(q, 2)
    force, moment = np.zeros((n, 3)), np.zeros((n, 3))
    for part in _chunks(len(masses), n):                     # bodies b of the part:
        m = masses[part, None, None]
        r = (rotor @ centres[part, None, :, None])[..., 0]   # stator frame, (b, n, 3)
        acc = np.cross(a, r) + np.cross(w, np.cross(w, r))
        f = m * (g - acc)                                    # load on the stator
        body = orientation(q, thetas[part, None])            # (b, n, 3, 3) body -> stator
        inertia = body @ owns[part, None] @ np.swapaxes(body, -1, -2)
        spin = np.einsum('...ij,...j->...i', inertia, a) + np.cross(
            w, np.einsum('...ij,...j->...i', inertia, w))
        force = _sum_rows(force, f)
        moment = _sum_rows(moment, np.cross(r, f) - spin)
    to_rotor = np.swapaxes(rotor, 1, 2)
    force_r = np.einsum('nij,nj->ni', to_rotor, force)
    moment_r = np.einsum('nij,nj->ni', to_rotor, moment)
    torque = -moment_r[:, 2].copy()
    moment_r[:, 2] = 0.0
    return force_r, moment_r, torque


def newton_euler_compute(bodies, q, omega, alpha, gravity):
    """Newton-Euler, each body's orientation a rotation matrix Rz(q + theta)."""
    return _newton_euler(bodies, q, omega, alpha, gravity,
                         lambda q, theta: _rotation(q + theta, 2))


def euler_zxz_compute(bodies, q, omega, alpha, gravity):
    """Newton-Euler, orientation from ZXZ Euler angles (q, 0, theta): Rz Rx Rz."""
    zero = np.zeros(len(q))
    return _newton_euler(bodies, q, omega, alpha, gravity,
                         lambda q, theta: _rotation(q, 2) @ _rotation(zero, 0)
                         @ _rotation(np.broadcast_to(theta, theta.shape[:-1] + q.shape), 2))


def zxz_angle_rates(precession, nutation, spin, omega_body):
    """
    Rates of ZXZ Euler angles (rad/s) from a body's angular velocity (body frame, rad/s).

    What a method that carries orientation as Euler angles must integrate. The
    inverse of omega = (p' sin(n) sin(s) + n' cos(s), p' sin(n) cos(s) - n' sin(s),
    p' cos(n) + s') divides by sin(nutation): at nutation 0 or pi (gimbal lock,
    thesis Sec. 6.2) precession and spin turn about one axis and the rates are
    0/0 (nan); near it, cross rates are amplified by 1 / sin(nutation).
    """
    w_x, w_y, w_z = omega_body
    sin_s, cos_s = np.sin(spin), np.cos(spin)
    with np.errstate(divide='ignore', invalid='ignore'):
        precession_rate = (w_x * sin_s + w_y * cos_s) / np.sin(nutation)
    nutation_rate = w_x * cos_s - w_y * sin_s
    spin_rate = w_z - precession_rate * np.cos(nutation)
    return np.array([precession_rate, nutation_rate, spin_rate])


# -- rigid bodies cut into particles ----------------------------------------------------

def _cloud_kind(component, n):
    """How a component is cut: 'tensor', 'point', 'box', 'sphere', ('cylinder'|'tube', axis)."""
    shape = component.shape
    if component.inertia is not None:
        return 'tensor'
    if shape is None or shape.type == 'point' or n <= 1:
        return 'point'
    if shape.type in ('box', 'sphere'):
        return shape.type
    return shape.type, shape.axis


def _tensor_points(component):
    """Six particles +-a on the principal axes: they reproduce any body's tensor exactly."""
    m = component.mass
    moments, axes = np.linalg.eigh(own_inertia(component))
    trace = moments.sum()
    second = (trace / 2.0 - moments) / m * 3.0      # int x_k^2 dm / (m/3) per axis
    local = []
    for k in range(3):
        a = math.sqrt(max(second[k], 0.0))          # 2 (m/6) a^2 = int x_k^2 dm
        local += [axes[:, k] * a, -axes[:, k] * a]
    return np.array(local)


def _local_particles(kind, components, k):
    """
    Particles of components of one kind in their own frames: (c, p, 3) places, (c, p) masses.

    Midpoint grids of k per side (boxes, spheres: the cube's points inside; cylinders and
    tubes: equal-area rings, k angles, k slices).
    """
    mass = np.array([c.mass for c in components], float)[:, None]
    u = (np.arange(k) + 0.5) / k                           # midpoints in [0, 1]
    if kind == 'tensor':
        local = np.stack([_tensor_points(c) for c in components])
    elif kind == 'point':
        local = np.zeros((len(components), 1, 3))          # one particle: at the centre
    elif kind == 'box':
        grid = np.stack(np.meshgrid(u, u, u, indexing='ij'), -1).reshape(-1, 3) - 0.5
        local = grid * np.array([c.shape.size for c in components], float)[:, None, :]
    elif kind == 'sphere':
        grid = np.stack(np.meshgrid(u, u, u, indexing='ij'), -1).reshape(-1, 3) * 2 - 1
        inside = grid[(grid ** 2).sum(1) <= 1.0]
        local = inside * np.array([c.shape.radius for c in components], float)[:, None, None]
    else:
        shape_type, axis = kind
        tube = shape_type == 'tube'
        inner = np.array([c.shape.inner_radius if tube else 0.0 for c in components])[:, None]
        outer = np.array([c.shape.outer_radius if tube else c.shape.radius
                          for c in components])[:, None]
        length = np.array([c.shape.length for c in components], float)[:, None]
        radius = np.sqrt(inner ** 2 + u * (outer ** 2 - inner ** 2))       # (c, k)
        phi = 2 * math.pi * (np.arange(k) + 0.5) / k
        along = (u - 0.5) * length
        shape = (len(components), k, k, k)
        rr = np.broadcast_to(radius[:, :, None, None], shape)
        pp = np.broadcast_to(phi[None, None, :, None], shape)
        zz = np.broadcast_to(along[:, None, None, :], shape)
        cyl = np.stack([rr * np.cos(pp), rr * np.sin(pp), zz], -1)
        cyl = cyl.reshape(len(components), -1, 3)
        order = {'axial': [0, 1, 2], 'radial': [2, 0, 1], 'tangential': [0, 2, 1]}
        local = cyl[:, :, order[axis]]
    return local, np.broadcast_to(mass / local.shape[1], local.shape[:2])


def particle_clouds(components, n):
    """(mass, x, y, z) rows, rotor frame: about ``n`` particles of each component, in order."""
    k = max(1, round(n ** (1.0 / 3.0)))
    kinds = {}
    for i, component in enumerate(components):
        kinds.setdefault(_cloud_kind(component, n), []).append(i)
    counts, parts = np.zeros(len(components), int), []
    for kind, members in kinds.items():
        local, masses = _local_particles(kind, [components[i] for i in members], k)
        counts[members] = local.shape[1]
        parts.append((members, local, masses))
    starts = np.cumsum(counts) - counts
    cloud = np.empty((int(counts.sum()), 4))
    for members, local, masses in parts:
        chosen = [components[i] for i in members]
        c = np.array([math.cos(p.angle) for p in chosen])[:, None]
        s = np.array([math.sin(p.angle) for p in chosen])[:, None]
        radius = np.array([p.radius for p in chosen], float)[:, None]
        z = np.array([p.z for p in chosen], float)[:, None]
        rows = starts[members][:, None] + np.arange(local.shape[1])
        cloud[rows] = np.stack([masses,
                                radius * c + c * local[..., 0] - s * local[..., 1],
                                radius * s + s * local[..., 0] + c * local[..., 1],
                                z + local[..., 2]], -1)
    return cloud


def particles(count):
    """Return the (prepare, compute) pair of the method with ~``count`` particles a body."""
    def prepare(layout):
        return particle_clouds(layout.components, count)

    def compute(cloud, q, omega, alpha, gravity):
        g_x, g_y, g_z = gravity
        c, s = np.cos(q), np.sin(q)
        gr_x, gr_y = turn_xy(g_x, g_y, c, -s)
        w2 = omega * omega
        n = len(q)
        sums = [np.zeros(n) for _ in range(5)]
        torque = np.zeros(n)
        for part in _chunks(len(cloud), n):
            m, x, y, z = (cloud[part, k, None] for k in range(4))
            f_x = m * (gr_x + w2 * x + alpha * y)
            f_y = m * (gr_y + w2 * y - alpha * x)
            f_z = m * g_z
            rows = (f_x, f_y, np.broadcast_to(f_z, f_x.shape), y * f_z - z * f_y,
                    z * f_x - x * f_z)
            sums = [_sum_rows(total, row) for total, row in zip(sums, rows)]
            torque = _sum_rows(torque, x * f_y - y * f_x, np.subtract)
        f_x, f_y, f_z, m_x, m_y = sums
        return np.stack([f_x, f_y, f_z], 1), np.stack([m_x, m_y, np.zeros(n)], 1), torque
    return prepare, compute


METHODS = {
    'aggregated': (aggregated, aggregated_compute),
    'aggregated_f32': (aggregated_f32, aggregated_f32_compute),
    'thesis_particles': (thesis_particles, thesis_particles_compute),
    'thesis_cylinders': (thesis_cylinders, thesis_cylinders_compute),
    'newton_euler': (newton_euler, newton_euler_compute),
    'euler_zxz': (newton_euler, euler_zxz_compute),
    **{f'particles_{n}': particles(n) for n in (1, 8, 64, 1000, 10000)},
}
