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


# -- the thesis's sums ----------------------------------------------------------------

def thesis_particles(layout):
    """Prepare: each component's mass and centre of mass (R, theta, z)."""
    return np.array([[c.mass, c.radius, c.angle, c.z] for c in layout.components]), None


def thesis_particles_compute(state, q, omega, alpha, gravity):
    """Eq. 4.39-4.41 summed per sample: no alpha, no bearing moment (F1 = F2)."""
    bodies, i_zz = state
    g_x, g_y, g_z = gravity
    c, s = np.cos(q), np.sin(q)
    gr_x, gr_y = turn_xy(g_x, g_y, c, -s)
    w2 = omega * omega
    n = len(q)
    force = np.zeros((n, 3))
    torque = np.zeros(n) if i_zz is None else i_zz * alpha
    for m, r, theta, _ in bodies:
        x, y = r * math.cos(theta), r * math.sin(theta)
        force[:, 0] += m * (gr_x + w2 * x)
        force[:, 1] += m * (gr_y + w2 * y)
        force[:, 2] += m * g_z
        torque -= m * (x * gr_y - y * gr_x)
    return force, _zeros_moment(n), torque


def thesis_cylinders(layout):
    """Prepare: masses and places, and I_zz summed per body (Eq. 5.6, corrected)."""
    bodies, _ = thesis_particles(layout)
    i_zz = 0.0
    for component, (m, r, _, _) in zip(layout.components, bodies):
        own = own_inertia(component)
        i_zz += own[2, 2] + m * r * r           # Eq. 5.6's I_ZZ: own + m (r + R_i)^2
    return bodies, i_zz


thesis_cylinders_compute = thesis_particles_compute


# -- Cartesian Newton-Euler with rotation matrices -------------------------------------

def newton_euler(layout):
    """Prepare: per body mass, centre of mass (rotor frame), own tensor, angle theta."""
    return [(c.mass, np.array([c.radius * math.cos(c.angle), c.radius * math.sin(c.angle),
                               c.z]), own_inertia(c), c.angle) for c in layout.components]


def _rotation(angle, axis):
    """Rotation matrices (..., 3, 3) by ``angle`` about coordinate axis ``axis`` (0 x, 2 z)."""
    i, j = [k for k in range(3) if k != axis]
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., i, i], out[..., i, j], out[..., j, i], out[..., j, j] = c, -s, s, c
    out[..., axis, axis] = 1.0
    return out


def _newton_euler(bodies, q, omega, alpha, gravity, orientation):
    n = len(q)
    w = np.zeros((n, 3))
    w[:, 2] = omega
    a = np.zeros((n, 3))
    a[:, 2] = alpha
    g = np.broadcast_to(np.asarray(gravity, float), (n, 3))
    rotor = _rotation(q, 2)
    force, moment = np.zeros((n, 3)), np.zeros((n, 3))
    for m, centre, own, theta in bodies:
        r = rotor @ centre                                   # stator frame, (n, 3)
        acc = np.cross(a, r) + np.cross(w, np.cross(w, r))
        f = m * (g - acc)                                    # load on the stator
        body = orientation(q, theta)                         # (n, 3, 3) body -> stator
        inertia = body @ own @ np.swapaxes(body, 1, 2)
        spin = np.einsum('nij,nj->ni', inertia, a) + np.cross(
            w, np.einsum('nij,nj->ni', inertia, w))
        force += f
        moment += np.cross(r, f) - spin
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
                         @ _rotation(np.full(len(q), theta), 2))


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

def particle_cloud(component, n):
    """About ``n`` (mass, x, y, z) particles of a component, rotor frame."""
    shape, m = component.shape, component.mass
    if component.inertia is not None:
        # Six particles +-a on the principal axes reproduce any body's tensor exactly.
        tensor = own_inertia(component)
        moments, axes = np.linalg.eigh(tensor)
        trace = moments.sum()
        second = (trace / 2.0 - moments) / m * 3.0      # int x_k^2 dm / (m/3) per axis
        local = []
        for k in range(3):
            a = math.sqrt(max(second[k], 0.0))          # 2 (m/6) a^2 = int x_k^2 dm
            local += [axes[:, k] * a, -axes[:, k] * a]
        local = np.array(local)
        masses = np.full(6, m / 6.0)
    elif shape is None or shape.type == 'point' or n <= 1:
        local, masses = np.zeros((1, 3)), np.array([m])   # one particle: at the centre
    else:
        k = max(1, round(n ** (1.0 / 3.0)))
        u = (np.arange(k) + 0.5) / k                       # midpoints in [0, 1]
        if shape.type == 'box':
            a, b, c = shape.size
            grid = np.stack(np.meshgrid(u, u, u, indexing='ij'), -1).reshape(-1, 3) - 0.5
            local = grid * [a, b, c]
            masses = np.full(len(local), m / len(local))
        elif shape.type == 'sphere':
            grid = np.stack(np.meshgrid(u, u, u, indexing='ij'), -1).reshape(-1, 3) * 2 - 1
            inside = grid[(grid ** 2).sum(1) <= 1.0] * shape.radius
            local = inside
            masses = np.full(len(local), m / len(local))
        else:   # cylinder or tube: equal-area rings, k angles, k slices
            inner = shape.inner_radius if shape.type == 'tube' else 0.0
            outer = shape.outer_radius if shape.type == 'tube' else shape.radius
            radius = np.sqrt(inner ** 2 + u * (outer ** 2 - inner ** 2))
            phi = 2 * math.pi * (np.arange(k) + 0.5) / k
            along = (u - 0.5) * shape.length
            rr, pp, zz = np.meshgrid(radius, phi, along, indexing='ij')
            cyl = np.stack([rr * np.cos(pp), rr * np.sin(pp), zz], -1).reshape(-1, 3)
            order = {'axial': [0, 1, 2], 'radial': [2, 0, 1], 'tangential': [0, 2, 1]}
            local = cyl[:, order[shape.axis]]
            masses = np.full(len(local), m / len(local))
    c, s = math.cos(component.angle), math.sin(component.angle)
    x = component.radius * c + c * local[:, 0] - s * local[:, 1]
    y = component.radius * s + s * local[:, 0] + c * local[:, 1]
    z = component.z + local[:, 2]
    return np.stack([masses, x, y, z], 1)


def particles(count):
    """Return the (prepare, compute) pair of the method with ~``count`` particles a body."""
    def prepare(layout):
        return np.concatenate([particle_cloud(c, count) for c in layout.components])

    def compute(cloud, q, omega, alpha, gravity):
        g_x, g_y, g_z = gravity
        c, s = np.cos(q), np.sin(q)
        gr_x, gr_y = turn_xy(g_x, g_y, c, -s)
        w2 = omega * omega
        n = len(q)
        force, moment, torque = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        for m, x, y, z in cloud:
            f_x = m * (gr_x + w2 * x + alpha * y)
            f_y = m * (gr_y + w2 * y - alpha * x)
            f_z = m * g_z
            force[:, 0] += f_x
            force[:, 1] += f_y
            force[:, 2] += f_z
            moment[:, 0] += y * f_z - z * f_y
            moment[:, 1] += z * f_x - x * f_z
            torque -= x * f_y - y * f_x
        return force, moment, torque
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
