"""
Properties the physics must have, over layouts that hypothesis draws.

Turning a layout turns its rotor-frame loads; loads superpose over layouts;
a point-symmetric layout puts no dynamic force or moment on the stator;
the computed correction masses cancel the dynamic unbalance; the one-sample
(plain float) path equals the vectorised path.
"""

import math

from hypothesis import given, settings, strategies as st
import numpy as np

from cvc_balance.physics.engine import loads, RotorModel, sample_loads
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.limits import MASS
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance

SUPPORTS = [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.35, 'axial': True}]
ZERO_G = [0.0, 0.0, 0.0]
ROUNDING = 2e-15
"""Tolerance as a fraction of :func:`scale`, the size of the terms: the largest deviation
measured over the drawn examples was 1.8e-16 of it (turning, superposing); the
symmetric and corrected layouts' residuals and the two paths' differences are smaller."""

lengths = st.floats(0.01, 0.4)
shapes = st.one_of(
    st.none(),
    st.builds(lambda r, h, a: {'type': 'cylinder', 'radius': r, 'length': h, 'axis': a},
              lengths, lengths, st.sampled_from(['radial', 'tangential', 'axial'])),
    st.builds(lambda s: {'type': 'box', 'size': list(s)}, st.tuples(lengths, lengths, lengths)),
    st.builds(lambda r: {'type': 'sphere', 'radius': r}, lengths),
    st.builds(lambda r, t, h: {'type': 'tube', 'inner_radius': r, 'outer_radius': r + t,
                               'length': h}, lengths, lengths, lengths),
)
components = st.lists(
    st.tuples(st.floats(0.1, 100.0), st.floats(0.0, 1.0), st.floats(-7.0, 7.0),
              st.floats(-0.5, 0.5), shapes), min_size=1, max_size=8)
motions = st.tuples(st.floats(-7.0, 7.0), st.floats(-60.0, 60.0), st.floats(-50.0, 50.0))


def layout_of(parts, gravity=None, prefix='c', supports=SUPPORTS):
    """Make a layout mapping from (mass, radius, angle, z, shape) tuples."""
    items = []
    for i, (mass, radius, angle, z, shape) in enumerate(parts):
        item = {'name': f'{prefix}{i}', 'mass': mass, 'radius': radius, 'angle': angle, 'z': z}
        if shape is not None:
            item['shape'] = shape
        items.append(item)
    layout = {'name': 'drawn', 'components': items, 'supports': supports}
    if gravity is not None:
        layout['gravity'] = gravity
    return layout


def model_of(parts, gravity=None, **kwargs):
    return RotorModel.from_layout(parse_layout(layout_of(parts, gravity, **kwargs)))


def scale(parts, omega, alpha, gravity=9.81):
    """Return the size of the loads, N and N m: what the terms of the equations are made of."""
    reach = sum(m * (1.0 + r + abs(z))**2 for m, r, _, z, _ in parts)
    return reach * (omega**2 + abs(alpha) + gravity + 1.0)


def turn(vector, angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1], vector[2]])


@settings(max_examples=150, deadline=None)
@given(components, motions, st.floats(-7.0, 7.0))
def test_turning_the_layout_turns_its_rotor_frame_loads(parts, motion, d_theta):
    q, omega, alpha = motion
    turned = [(m, r, a + d_theta, z, shape) for m, r, a, z, shape in parts]
    tolerance = ROUNDING * scale(parts, omega, alpha)
    # Without gravity, at the same rotor angle.
    base = sample_loads(model_of(parts, ZERO_G), q, omega, alpha)
    moved = sample_loads(model_of(turned, ZERO_G), q, omega, alpha)
    assert np.allclose(moved.force_rotor, turn(base.force_rotor, d_theta),
                       rtol=0.0, atol=tolerance)
    assert np.allclose(moved.moment_rotor, turn(base.moment_rotor, d_theta),
                       rtol=0.0, atol=tolerance)
    assert math.isclose(moved.drive_torque, base.drive_torque, rel_tol=0.0, abs_tol=tolerance)
    # With gravity, the rotor turned back by d_theta sees gravity turned by d_theta too.
    base = sample_loads(model_of(parts), q, omega, alpha)
    moved = sample_loads(model_of(turned), q - d_theta, omega, alpha)
    assert np.allclose(moved.force_rotor, turn(base.force_rotor, d_theta),
                       rtol=0.0, atol=tolerance)
    assert np.allclose(moved.moment_rotor, turn(base.moment_rotor, d_theta),
                       rtol=0.0, atol=tolerance)
    assert math.isclose(moved.drive_torque, base.drive_torque, rel_tol=0.0, abs_tol=tolerance)


@settings(max_examples=150, deadline=None)
@given(components, components, motions)
def test_loads_superpose_over_layouts(first, second, motion):
    q, omega, alpha = motion
    both = sample_loads(model_of(first + second), q, omega, alpha)
    one = sample_loads(model_of(first), q, omega, alpha)
    other = sample_loads(model_of(second, prefix='d'), q, omega, alpha)
    tolerance = ROUNDING * scale(first + second, omega, alpha)
    for key in ('force_rotor', 'moment_rotor', 'force_stator', 'moment_stator'):
        assert np.allclose(getattr(both, key), np.add(getattr(one, key), getattr(other, key)),
                           rtol=0.0, atol=tolerance)
    assert math.isclose(both.drive_torque, one.drive_torque + other.drive_torque,
                        rel_tol=0.0, abs_tol=tolerance)
    for name in ('front', 'rear'):
        assert np.allclose(both.supports[name][0],
                           np.add(one.supports[name][0], other.supports[name][0]),
                           rtol=0.0, atol=tolerance)


@settings(max_examples=150, deadline=None)
@given(components, motions)
def test_point_symmetric_layout_has_no_dynamic_load(parts, motion):
    """
    Each component mirrored through the axis in its plane (R, theta + pi, z): no load.

    Mirrored through O instead, (R, theta + pi, -z), the static unbalance still
    cancels but the couple doubles: no force, yet a bearing moment.
    """
    _, omega, alpha = motion
    mirrored = parts + [(m, r, a + math.pi, z, shape) for m, r, a, z, shape in parts]
    model = model_of(mirrored, ZERO_G)
    result = loads(model, np.linspace(0.0, 6.0, 7), omega, alpha)
    tolerance = ROUNDING * scale(mirrored, omega, alpha)
    assert np.abs(result.force_stator).max() < tolerance
    assert np.abs(result.moment_stator).max() < tolerance
    assert max(map(abs, static_unbalance(model) + couple_unbalance(model))) < tolerance
    through_o = model_of(parts + [(m, r, a + math.pi, -z, shape)
                                  for m, r, a, z, shape in parts], ZERO_G)
    single = model_of(parts, ZERO_G)
    assert np.abs(loads(through_o, 0.3, omega, alpha).force_stator).max() < tolerance
    # Each part's couple about O, doubled (P_xz = int x z dm is even under r -> -r).
    assert math.isclose(through_o.p_xz, 2 * single.p_xz, rel_tol=1e-15, abs_tol=tolerance)
    assert math.isclose(through_o.p_yz, 2 * single.p_yz, rel_tol=1e-15, abs_tol=tolerance)


@settings(max_examples=150, deadline=None)
@given(components, st.floats(0.2, 1.2), motions)
def test_correction_masses_cancel_the_dynamic_unbalance(parts, correction_radius, motion):
    _, omega, alpha = motion
    model = model_of(parts, ZERO_G)
    planes = plane_unbalances(model, -0.3, 0.35, correction_radius)
    weights = []
    for p in planes:
        if p.correction_mass >= MASS.low:
            weights.append((p.correction_mass, p.correction_radius, p.correction_angle, p.z,
                            None))
        elif p.correction_mass > 0.0:   # lighter than a layout's mass: as a pair, 0.1 kg apart
            weights += [(0.1 + p.correction_mass, p.correction_radius, p.correction_angle,
                         p.z, None),
                        (0.1, p.correction_radius, p.correction_angle + math.pi, p.z, None)]
    corrected = model_of(parts + weights, ZERO_G)
    tolerance = ROUNDING * scale(parts, 1.0, 0.0) / max(correction_radius, 1.0)
    for plane in plane_unbalances(corrected, -0.3, 0.35, correction_radius):
        assert plane.amount < tolerance
    assert max(map(abs, static_unbalance(corrected) + couple_unbalance(corrected))) < tolerance
    # ... and so no dynamic load on the stator at any speed.
    result = sample_loads(corrected, 0.4, omega, alpha)
    assert np.abs(result.force_stator).max() < ROUNDING * scale(parts, omega, alpha)
    assert np.abs(result.moment_stator).max() < ROUNDING * scale(parts, omega, alpha)


@settings(max_examples=60, deadline=None)
@given(components, st.lists(motions, min_size=1, max_size=20), st.booleans())
def test_one_sample_path_equals_vectorised_path(parts, samples, one_support):
    supports = [{'name': 'front', 'z': 0.1}] if one_support else SUPPORTS
    model = model_of(parts, supports=supports)
    q, omega, alpha = (np.array(column) for column in zip(*samples))
    many = loads(model, q, omega, alpha)
    for i, (qi, wi, ai) in enumerate(samples):
        one = sample_loads(model, qi, wi, ai)
        tolerance = ROUNDING * scale(parts, wi, ai)
        assert np.allclose(many.force_stator[i], one.force_stator, rtol=0.0, atol=tolerance)
        assert np.allclose(many.moment_rotor[i], one.moment_rotor, rtol=0.0, atol=tolerance)
        assert math.isclose(many.drive_torque[i], one.drive_torque, rel_tol=0.0,
                            abs_tol=tolerance)
        for s in supports:
            assert np.allclose(many.support_force[s['name']][i], one.supports[s['name']][0],
                               rtol=0.0, atol=tolerance)
            assert np.allclose(many.support_moment[s['name']][i], one.supports[s['name']][1],
                               rtol=0.0, atol=tolerance)
