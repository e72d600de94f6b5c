"""
Independent references for the tests: random layouts and Pinocchio's RNEA.

Nothing here uses cvc_balance's physics: layouts are plain mappings (the file
format), and Pinocchio builds each component from its own shape primitives
and placements (SE3), then runs the recursive Newton-Euler algorithm on one
revolute joint about Z.
"""

import cmath
import math

import numpy as np
import pinocchio as pin

SHAPE_KINDS = ('point', 'cylinder', 'tube', 'box', 'sphere', 'inertia', 'none')
AXIS_ROTATION = {
    # Pinocchio's cylinders have their axis along z; turn it onto the own-frame axis.
    'axial': np.eye(3),
    'radial': pin.utils.rotate('y', math.pi / 2),
    'tangential': pin.utils.rotate('x', -math.pi / 2),
}


def random_component(rng, index, kind=None):
    """One component mapping with a random place and a random shape kind."""
    kind = kind or SHAPE_KINDS[rng.integers(len(SHAPE_KINDS))]
    item = {'name': f'c{index}', 'mass': float(rng.uniform(0.5, 80.0)),
            'radius': float(rng.uniform(0.0, 0.8)), 'z': float(rng.uniform(-0.3, 0.3))}
    if rng.random() < 0.5:
        item['angle_deg'] = float(rng.uniform(-360.0, 360.0))
    else:
        item['angle'] = float(rng.uniform(-math.pi, 2 * math.pi))
    axis = ('radial', 'tangential', 'axial')[rng.integers(3)]
    if kind == 'point':
        item['shape'] = {'type': 'point'}
    elif kind == 'cylinder':
        item['shape'] = {'type': 'cylinder', 'radius': float(rng.uniform(0.01, 0.2)),
                         'length': float(rng.uniform(0.01, 0.5)), 'axis': axis}
    elif kind == 'tube':
        inner = float(rng.uniform(0.01, 0.2))
        item['shape'] = {'type': 'tube', 'inner_radius': inner,
                         'outer_radius': inner + float(rng.uniform(0.005, 0.1)),
                         'length': float(rng.uniform(0.01, 0.5)), 'axis': axis}
    elif kind == 'box':
        item['shape'] = {'type': 'box', 'size': [float(v) for v in rng.uniform(0.01, 0.5, 3)]}
    elif kind == 'sphere':
        item['shape'] = {'type': 'sphere', 'radius': float(rng.uniform(0.01, 0.2))}
    elif kind == 'inertia':
        item['inertia'] = random_inertia(rng, item['mass'])
    return item


def random_inertia(rng, mass):
    """URDF elements of a physical tensor: a random box turned by a random rotation."""
    size = rng.uniform(0.02, 0.4, 3)
    a, b, c = size
    principal = mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    rotation = pin.utils.rpyToMatrix(*rng.uniform(-math.pi, math.pi, 3))
    tensor = rotation @ np.diag(principal) @ rotation.T
    return {key: float(tensor[i, j]) for key, (i, j) in (
        ('ixx', (0, 0)), ('iyy', (1, 1)), ('izz', (2, 2)), ('ixy', (0, 1)), ('ixz', (0, 2)),
        ('iyz', (1, 2)))}


def random_layout(rng, n=8, supports=2, tilt=True, every_kind=False):
    """
    Draw a layout mapping: n random components, 1 or 2 supports, optionally tilted gravity.

    ``every_kind`` puts one component of each shape kind before the n random ones.
    """
    tilt_angle = rng.uniform(-math.radians(30), math.radians(30)) if tilt else 0.0
    layout = {
        'name': f'random_{int(rng.integers(1 << 30))}',
        'components': ([random_component(rng, i, kind) for i, kind in enumerate(SHAPE_KINDS)]
                       if every_kind else [])
        + [random_component(rng, len(SHAPE_KINDS) + i) for i in range(n)],
        'gravity': [0.0, -9.80665 * math.cos(tilt_angle), 9.80665 * math.sin(tilt_angle)],
    }
    if supports == 2:
        z_front = float(rng.uniform(-0.6, -0.05))
        layout['supports'] = [{'name': 'front', 'z': z_front},
                              {'name': 'rear', 'z': float(rng.uniform(0.05, 0.6)), 'axial': True}]
    else:
        layout['supports'] = [{'name': 'bearing', 'z': float(rng.uniform(-0.3, 0.3))}]
    return layout


def component_angle(item):
    """Return the component's angle in radians, read from the mapping."""
    return item['angle'] if 'angle' in item else math.radians(item['angle_deg'])


def pinocchio_inertia(item):
    """Build the component's spatial inertia in its own frame from Pinocchio's primitives."""
    m = item['mass']
    if 'inertia' in item:
        e = item['inertia']
        tensor = np.array([[e['ixx'], e['ixy'], e['ixz']], [e['ixy'], e['iyy'], e['iyz']],
                           [e['ixz'], e['iyz'], e['izz']]])
        return pin.Inertia(m, np.zeros(3), tensor)
    shape = item.get('shape', {'type': 'point'})
    kind = shape['type']
    if kind == 'point':
        return pin.Inertia(m, np.zeros(3), np.zeros((3, 3)))
    if kind == 'sphere':
        return pin.Inertia.FromSphere(m, shape['radius'])
    if kind == 'box':
        return pin.Inertia.FromBox(m, *shape['size'])
    if kind == 'cylinder':
        body = pin.Inertia.FromCylinder(m, shape['radius'], shape['length'])
    else:  # tube: a full cylinder minus its bore, same density
        ri, ro, length = shape['inner_radius'], shape['outer_radius'], shape['length']
        density_mass = m / (ro**2 - ri**2)
        body = (pin.Inertia.FromCylinder(density_mass * ro**2, ro, length)
                - pin.Inertia.FromCylinder(density_mass * ri**2, ri, length))
    axis = shape.get('axis', 'axial')
    return pin.SE3(AXIS_ROTATION[axis], np.zeros(3)).act(body)


def pinocchio_model(layout):
    """Build a Pinocchio model: the universe (stator), one revolute joint about Z, the rotor."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), 'spin')
    for item in layout['components']:
        theta = component_angle(item)
        place = pin.SE3(pin.utils.rotate('z', theta),
                        np.array([item['radius'] * math.cos(theta),
                                  item['radius'] * math.sin(theta), item.get('z', 0.0)]))
        model.appendBodyToJoint(joint, pinocchio_inertia(item), place)
    return model


def pinocchio_loads(layout, q, omega, alpha, gravity):
    """
    Load on the stator (rotor frame, about O) and drive torque, by RNEA.

    ``data.f[1]`` is the spatial force the stator transmits to the rotor
    through the joint, in the joint (rotor) frame at O; the load on the stator
    is its opposite, and the joint torque is the drive torque.
    """
    model = pinocchio_model(layout)
    model.gravity.linear = np.asarray(gravity, dtype=float)
    data = model.createData()
    tau = pin.rnea(model, data, np.array([q]), np.array([omega]), np.array([alpha]))
    wrench = data.f[1]
    rotation = pin.utils.rotate('z', q)
    force_rotor = -wrench.linear
    moment_rotor = -wrench.angular
    moment_rotor[2] = 0.0  # the Z part goes through the drive (tau), not the bearings
    rotor = model.inertias[1]  # all bodies of the joint, summed by Pinocchio
    return {
        'force_rotor': force_rotor, 'moment_rotor': moment_rotor,
        'force_stator': rotation @ force_rotor, 'moment_stator': rotation @ moment_rotor,
        'drive_torque': float(tau[0]), 'mass': rotor.mass, 'com': np.array(rotor.lever),
        'inertia_about_com': np.array(rotor.inertia),
    }


def relative_error(value, reference):
    """|value - reference| / |reference| over whole vectors (scale-aware, not per element)."""
    value, reference = np.asarray(value, float), np.asarray(reference, float)
    return float(np.linalg.norm(value - reference) / max(np.linalg.norm(reference), 1e-300))


def method_error(name, layout, q, omega, alpha, gravity=None):
    """
    Largest relative error of a method (cvc_balance.study.methods) against the 40-digit reference.

    The bench's measure: each output's deviation over the samples, scaled by the
    reference's largest value of that output.
    """
    from cvc_balance.study.bench import _relative
    from cvc_balance.study.exact import exact_loads
    from cvc_balance.study.methods import METHODS
    gravity = layout.gravity if gravity is None else gravity
    reference = exact_loads(layout, q, omega, alpha, gravity)
    prepare, compute = METHODS[name]
    result = compute(prepare(layout), q, omega, alpha, gravity)
    return max(_relative(got, ref) for got, ref in zip(result, reference))


def planes_by_hand(layout):
    """
    Return plane I and II unbalance (kg m, complex) of a layout's components as points.

    ISO 21940-2's lever rule over a layout mapping with ``balancing.planes`` and each
    component's ``angle_deg``.
    """
    return component_planes_by_hand(layout['components'], layout['balancing']['planes'])


def component_planes_by_hand(components, planes):
    """
    Return plane I and II unbalance (kg m, complex) of point components (mappings).

    ISO 21940-2's lever rule: planes at z = ``planes`` (m); each component's ``mass``,
    ``radius``, ``angle_deg`` and ``z`` (0 if not given).
    """
    z_i, z_ii = planes
    out = [0j, 0j]
    for c in components:
        u = c['mass'] * c['radius'] * cmath.exp(1j * math.radians(c['angle_deg']))
        out[0] += u * (z_ii - c.get('z', 0.0)) / (z_ii - z_i)
        out[1] += u * (c.get('z', 0.0) - z_i) / (z_ii - z_i)
    return out


def shares_by_hand(layout):
    """Return each plane's permissible share (kg m) at the service speed (ISO 21940-11)."""
    z_i, z_ii = layout['balancing']['planes']
    mass = sum(c['mass'] for c in layout['components'])
    z_com = sum(c['mass'] * c.get('z', 0.0) for c in layout['components']) / mass
    u_per = layout['balancing']['grade'] * 1e-3 * mass / layout['balancing']['service_speed']
    return [u_per * min(max(lever, 0.3), 0.7)
            for lever in ((z_ii - z_com) / (z_ii - z_i), (z_com - z_i) / (z_ii - z_i))]
