"""
The thesis's worked results as tests, and its errata (NOTES.md) shown by the physics.

Equation numbers are those of Jennings (2014), shared/thesis/. The thesis's
bearing forces F1..F5 are support reactions on the rotor in the rotor frame
(F1, F2 along X at the two bearings, F4, F5 along Y, F3 axial); cvc_balance
reports loads on the stator, their opposite, in the stator frame, so the
tests turn them back. The thesis's gravity acts along -X of the stator with
rotor angle theta = q (its Eq. 4.1-4.2).

One more erratum than NOTES.md lists: Eq. 4.1-4.2, 4.6-4.10, 4.20-4.29 and
4.39-4.41 project each particle's weight on its own radial line
(g cos(theta + Theta_i)) while summing along body A's axes; the tests compare
with the physical form (g cos(theta) for every particle) and show the printed
one losing the rotor's weight.
"""

import math

import numpy as np
import pytest

from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.frames import products_of_inertia
from cvc_balance.physics.inertia import parallel_axis_cvc, solid_cylinder, tube
from cvc_balance.physics.layout import parse_layout

M, R1, OMEGA, G = 40.0, 1.0, 12.0, 9.81   # Sec. 4.1.1: "based upon ... a CT scanner"
HALF_SPAN = 0.5                             # bearings at z = -L/2, +L/2


def particles_model(particles, gravity=G, shapes=None, axial_gravity=0.0):
    """Rotor of point masses (m, R, angle) in the plane z = 0, bearings at +-L/2 (rear axial)."""
    components = []
    for i, (m, r, angle) in enumerate(particles):
        item = {'name': f'p{i}', 'mass': m, 'radius': r, 'angle': angle}
        if shapes:
            item['shape'] = shapes[i]
        components.append(item)
    return RotorModel.from_layout(parse_layout({
        'name': 'thesis', 'components': components,
        'supports': [{'name': 'front', 'z': -HALF_SPAN},
                     {'name': 'rear', 'z': HALF_SPAN, 'axial': True}],
        'gravity': [-gravity, 0.0, axial_gravity]}))


def bearing_reactions(model, theta, omega, alpha=0.0):
    """
    Thesis-style reactions on the rotor, rotor frame: [(F1, F4, .), (F2, F5, .)].

    The third of each is that bearing's axial reaction: the thesis's F3 is the rear's
    (the axial one), the front's is always 0.
    """
    result = sample_loads(model, theta, omega, alpha)
    c, s = math.cos(theta), math.sin(theta)
    to_rotor = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return [-(to_rotor @ np.asarray(result.supports[name][0])) for name in ('front', 'rear')]


def resultant(model, omega):
    """Thesis Eq. 4.12: F_res = sqrt(F_R^2 + F_theta^2), g = 0."""
    force = sample_loads(model, 0.0, omega, 0.0, (0.0, 0.0, 0.0)).force_rotor
    return math.hypot(force[0], force[1])


# --- Ch. 3: CVC parallel-axis theorem ------------------------------------------------

def test_eq_3_11_shift_along_two_axes():
    m, r, length = 3.0, 0.2, 0.7
    shifted = parallel_axis_cvc(solid_cylinder(m, r, length), m, r, -math.pi / 2, 0.0)
    # Measured: equal to the last bit (1e-15 relative asserted, a few roundings).
    assert shifted[0, 0] == pytest.approx(m * (15 * r**2 + length**2) / 12, rel=1e-15)
    assert shifted[1, 1] == pytest.approx(m * (3 * r**2 + length**2) / 12, rel=1e-15)
    assert shifted[2, 2] == pytest.approx(1.5 * m * r**2, rel=1e-15)


def test_eq_3_15_to_3_17_shift_along_three_axes():
    m, r, length = 3.0, 0.2, 0.7
    shifted = parallel_axis_cvc(solid_cylinder(m, r, length), m, r, -math.pi / 6, length / 2)
    # Measured: at most 2.8e-17 apart (1.1e-16 relative).
    assert shifted[0, 0] == pytest.approx(m * r**2 / 2 + m * length**2 / 3, rel=1e-15)
    assert shifted[1, 1] == pytest.approx(m * r**2 + m * length**2 / 3, rel=1e-15)
    assert shifted[2, 2] == pytest.approx(1.5 * m * r**2, rel=1e-15)
    p_xy, p_xz, p_yz = products_of_inertia(shifted)
    assert p_xy == pytest.approx(-math.sqrt(3) / 4 * m * r**2, rel=1e-15)
    assert p_xz == pytest.approx(math.sqrt(3) / 4 * m * r * length, rel=1e-15)
    assert p_yz == pytest.approx(-m * r * length / 4, rel=1e-15)


def test_erratum_4_eq_3_13_means_l_over_2_squared():
    """3.13 prints l^2/2; only (l/2)^2 = l^2/4 reproduces the thesis's own 3.15."""
    m, r, length = 3.0, 0.2, 0.7
    i_xx_g = m * (3 * r**2 + length**2) / 12
    printed = i_xx_g + m * (r**2 * math.sin(-math.pi / 6)**2 + length**2 / 2)
    meant = i_xx_g + m * (r**2 * math.sin(-math.pi / 6)**2 + length**2 / 4)
    eq_3_15 = m * r**2 / 2 + m * length**2 / 3
    assert meant == pytest.approx(eq_3_15, rel=1e-15)         # measured: equal
    assert abs(printed - eq_3_15) > 0.1 * eq_3_15


def test_erratum_5_eq_3_7_last_line_shifts_i_yz():
    """I_YZ_B = I_YZ_G + m r_o z_o sin(phi_o); the text's I_XY_G there is a typo."""
    m, r_o, phi_o, z_o = 2.0, 0.4, 0.7, -0.3
    # A body whose own products are all different, so a mix-up cannot hide.
    inertia_g = np.array([[0.5, -0.11, -0.07], [-0.11, 0.6, -0.02], [-0.07, -0.02, 0.4]])
    d = -np.array([r_o * math.cos(phi_o), r_o * math.sin(phi_o), z_o])  # B from G
    steiner = inertia_g + m * (d @ d * np.eye(3) - np.outer(d, d))   # Cartesian reference
    # Measured: 1.1e-16 apart at most (2e-16 relative).
    np.testing.assert_allclose(parallel_axis_cvc(inertia_g, m, r_o, phi_o, z_o), steiner,
                               rtol=2e-15)
    _, _, p_yz = products_of_inertia(parallel_axis_cvc(inertia_g, m, r_o, phi_o, z_o))
    p_xy_g, _, p_yz_g = products_of_inertia(inertia_g)
    assert p_yz == pytest.approx(p_yz_g + m * r_o * z_o * math.sin(phi_o), rel=1e-15)
    assert abs(p_yz - (p_xy_g + m * r_o * z_o * math.sin(phi_o))) > 0.05


# --- App. A: the CVC inertia integrals, numerically ------------------------------------

def cvc_inertia_integrals(density, r_in, r_out, length, centre=(0.0, 0.0, 0.0), nodes=24):
    """
    Eq. 2.8-2.13 over a (hollow) cylinder, dm = rho R dR dphi dZ, by quadrature.

    Gauss-Legendre in R and Z (exact for these polynomials), the rectangle rule
    in phi (exact for trigonometric polynomials of low degree). ``centre`` moves
    the body: each mass element sits at centre + (R cos phi, R sin phi, Z).
    Returns (I_XX, I_YY, I_ZZ, P_XY, P_XZ, P_YZ), the thesis's positive integrals.
    """
    x_r, w_r = np.polynomial.legendre.leggauss(nodes)
    radius = 0.5 * (r_out - r_in) * x_r + 0.5 * (r_out + r_in)
    w_r = w_r * 0.5 * (r_out - r_in)
    x_z, w_z = np.polynomial.legendre.leggauss(nodes)
    height, w_z = 0.5 * length * x_z, w_z * 0.5 * length
    phi = np.arange(4 * nodes) * 2 * math.pi / (4 * nodes)
    w_phi = np.full(phi.size, 2 * math.pi / phi.size)
    rr, pp, zz = np.meshgrid(radius, phi, height, indexing='ij')
    weight = np.einsum('i,j,k->ijk', w_r, w_phi, w_z) * density * rr
    x = centre[0] + rr * np.cos(pp)
    y = centre[1] + rr * np.sin(pp)
    z = centre[2] + zz
    # In the body's own CVC coordinates about the axis (R, phi, Z) when centre = 0.
    return tuple(float(np.sum(weight * f)) for f in (
        y**2 + z**2, x**2 + z**2, x**2 + y**2, x * y, x * z, y * z))


def test_app_a_cylinder_inertia_by_integrating_eq_2_8_to_2_13():
    m, r, length = 5.0, 0.15, 0.4
    density = m / (math.pi * r**2 * length)                                 # Eq. A.1
    i_xx, i_yy, i_zz, p_xy, p_xz, p_yz = cvc_inertia_integrals(density, 0.0, r, length)
    # Gauss-Legendre is exact here: measured 1.0e-15 relative at most (the sums' rounding).
    assert i_xx == pytest.approx(m * (3 * r**2 + length**2) / 12, rel=1e-14)  # Eq. A.3
    assert i_yy == pytest.approx(m * (3 * r**2 + length**2) / 12, rel=1e-14)  # Eq. A.6
    assert i_zz == pytest.approx(m * r**2 / 2, rel=1e-14)                     # Eq. A.11
    assert max(abs(p_xy), abs(p_xz), abs(p_yz)) < 1e-16 * m * r * length    # Eq. 3.3
    tensor = solid_cylinder(m, r, length)
    np.testing.assert_allclose(np.diag(tensor), [i_xx, i_yy, i_zz], rtol=1e-14)


def test_tube_inertia_by_integrating_the_cvc_integrals():
    m, r_in, r_out, length = 5.0, 0.1, 0.16, 0.3
    density = m / (math.pi * (r_out**2 - r_in**2) * length)
    i_xx, i_yy, i_zz, *_ = cvc_inertia_integrals(density, r_in, r_out, length)
    np.testing.assert_allclose(np.diag(tube(m, r_in, r_out, length)), [i_xx, i_yy, i_zz],
                               rtol=1e-14)                   # measured 6.8e-16 relative


def test_shifted_cylinder_by_integration_matches_cvc_parallel_axis():
    """The CVC parallel-axis theorem against integrating the displaced body directly."""
    m, r, length = 5.0, 0.15, 0.4
    r_o, phi_o, z_o = 0.55, 2.2, -0.12
    density = m / (math.pi * r**2 * length)
    centre = (r_o * math.cos(phi_o), r_o * math.sin(phi_o), z_o)
    i_xx, i_yy, i_zz, p_xy, p_xz, p_yz = cvc_inertia_integrals(density, 0.0, r, length, centre)
    shifted = parallel_axis_cvc(solid_cylinder(m, r, length), m, r_o, phi_o, z_o)
    # Measured: 3.3e-16 apart at most (5e-16 relative).
    np.testing.assert_allclose(np.diag(shifted), [i_xx, i_yy, i_zz], rtol=1e-14)
    np.testing.assert_allclose(products_of_inertia(shifted), [p_xy, p_xz, p_yz], rtol=1e-14)


def test_erratum_9_eq_a_7_integrand_is_r_squared():
    """With dm = rho R dR dphi dZ the I_ZZ integrand is R^2; A.7's R^3 is not I_ZZ."""
    m, r, length = 5.0, 0.15, 0.4
    rho = m / (math.pi * r**2 * length)
    x, w = np.polynomial.legendre.leggauss(12)
    radius, w = 0.5 * r * (x + 1), 0.5 * r * w
    meant = rho * 2 * math.pi * length * np.sum(w * radius**2 * radius)
    printed = rho * 2 * math.pi * length * np.sum(w * radius**3 * radius)
    assert meant == pytest.approx(m * r**2 / 2, rel=1e-15)       # measured 1e-16
    assert printed == pytest.approx(0.4 * m * r**3, rel=1e-15)   # not even an inertia


# --- Ch. 2: Euler's equations with products of inertia (Eq. 2.20) -----------------

def euler_2_20(i_xx, i_yy, i_zz, p_xy, p_xz, p_yz, w, a):
    """Thesis Eq. 2.20 as printed, with erratum 10 (I_RX -> I_XX) applied."""
    wx, wy, wz = w
    ax, ay, az = a
    return np.array([
        i_xx * ax + (i_zz - i_yy) * wz * wy - p_xy * (ay - wx * wz) - p_xz * (az + wx * wy)
        + p_yz * (wz**2 - wy**2),
        i_yy * ay + (i_xx - i_zz) * wx * wz - p_yz * (az - wy * wx) - p_xy * (ax + wy * wz)
        + p_xz * (wx**2 - wz**2),
        i_zz * az + (i_yy - i_xx) * wx * wy - p_xz * (ax - wy * wz) - p_yz * (ay + wx * wz)
        + p_xy * (wy**2 - wx**2)])


def test_eq_2_20_is_the_rate_of_angular_momentum():
    rng = np.random.default_rng(3)
    for _ in range(20):
        i_xx, i_yy, i_zz = rng.uniform(1, 3, 3)
        p_xy, p_xz, p_yz = rng.uniform(-0.5, 0.5, 3)
        tensor = np.array([[i_xx, -p_xy, -p_xz], [-p_xy, i_yy, -p_yz], [-p_xz, -p_yz, i_zz]])
        w, a = rng.normal(size=3), rng.normal(size=3)
        expected = tensor @ a + np.cross(w, tensor @ w)
        # Measured: 6.7e-16 apart at most (terms of size 1 to 10).
        np.testing.assert_allclose(euler_2_20(i_xx, i_yy, i_zz, p_xy, p_xz, p_yz, w, a),
                                   expected, rtol=1e-14, atol=1e-14)


def test_engine_moments_are_eq_2_20_for_single_axis_spin():
    """With g = 0 the bearing moment is minus Eq. 2.20's X, Y rows; the drive, its Z row."""
    model = RotorModel.from_layout(parse_layout({
        'name': 'offset', 'supports': [{'name': 'only', 'z': 0.0}],
        'components': [{'name': 'a', 'mass': 7.0, 'radius': 0.4, 'angle': 0.3, 'z': 0.2,
                        'shape': {'type': 'box', 'size': [0.1, 0.3, 0.2]}},
                       {'name': 'b', 'mass': 3.0, 'radius': 0.6, 'angle': 2.5, 'z': -0.1}]}))
    i_xx, i_yy, i_zz = np.diag(model.body.inertia)
    p_xy, p_xz, p_yz = products_of_inertia(model.body.inertia)
    omega, alpha = 11.0, -4.0
    rate = euler_2_20(i_xx, i_yy, i_zz, p_xy, p_xz, p_yz, (0, 0, omega), (0, 0, alpha))
    result = sample_loads(model, 0.0, omega, alpha, (0.0, 0.0, 0.0))
    # Measured: equal to the last bit.
    np.testing.assert_allclose(result.moment_rotor[:2], -rate[:2], rtol=1e-14)
    assert result.drive_torque == pytest.approx(rate[2], rel=1e-14)
    assert rate[0] == pytest.approx(-p_xz * alpha + p_yz * omega**2, rel=1e-14)
    assert rate[1] == pytest.approx(-p_yz * alpha - p_xz * omega**2, rel=1e-14)


# --- Ch. 4: particles ----------------------------------------------------------------

def eq_4_39_4_41(particles, theta, omega, g, printed_gravity=False):
    """
    Thesis Eq. 4.39 / 4.41 (the n-particle form of 4.6-4.10, 4.25-4.29): F1 and F4.

    As printed, particle i's weight enters as g cos(theta + Theta_i), projected on
    its own radial line though the sum runs along body A's axes. Gravity is one
    uniform field: on A's axes it is (-g cos theta, g sin theta) for every particle
    (an erratum NOTES.md does not list). ``printed_gravity`` picks the printed form.
    """
    f1 = f4 = 0.0
    for m, r, angle in particles:
        along = theta + angle if printed_gravity else theta
        f1 += m / 2 * (g * math.cos(along) - r * omega**2 * math.cos(angle))
        f4 += -m / 2 * (g * math.sin(along) + r * omega**2 * math.sin(angle))
    return f1, f4


@pytest.mark.parametrize('gravity', [0.0, G])
@pytest.mark.parametrize('theta', [0.0, 0.8, 2.9, -1.7])
@pytest.mark.parametrize('r2, phi', [(1.0, math.pi), (0.6, 2.0), (1.4, -0.9)])
def test_eq_4_6_to_4_10_two_particles(gravity, theta, r2, phi):
    particles = [(M, R1, 0.0), (M, r2, phi)]
    (f1, f4, _), (f2, f5, _) = bearing_reactions(particles_model(particles, gravity),
                                                 theta, OMEGA)
    eq_4_6, eq_4_9 = eq_4_39_4_41(particles, theta, OMEGA, gravity)
    scale = M * R1 * OMEGA**2     # 5760 N; measured: 1.6e-16 of it at most
    assert f1 == pytest.approx(eq_4_6, abs=1e-15 * scale)      # Eq. 4.6
    assert f2 == pytest.approx(eq_4_6, abs=1e-15 * scale)      # Eq. 4.7
    # Eq. 4.8, F3 = 0: gravity in the plane; test_eq_4_3_... takes it out of the plane.
    assert f4 == pytest.approx(eq_4_9, abs=1e-15 * scale)      # Eq. 4.9
    assert f5 == pytest.approx(eq_4_9, abs=1e-15 * scale)      # Eq. 4.10
    if gravity == 0.0:   # without gravity the printed and the physical forms agree
        assert (f1, f4) == pytest.approx(
            eq_4_39_4_41(particles, theta, OMEGA, 0.0, printed_gravity=True),
            abs=1e-15 * scale)


@pytest.mark.parametrize('g_z', [1.7, -3.4])
@pytest.mark.parametrize('theta', [0.0, 0.8, -1.7])
def test_eq_4_3_axial_reaction_is_the_axial_weight_on_the_axial_bearing(g_z, theta):
    """
    Eq. 4.3, sum F_Z = F3, with gravity out of the plane (the thesis's is in it: Eq. 4.8).

    A gantry tilted so that gravity has an axial part g_z: F3 = -sum m g_z, all of it
    on the axial (rear) bearing, none on the front. The sums of Eq. 4.1-4.2 stay as in
    the plane (F1 + F2 and F4 + F5 twice Eq. 4.6 and 4.9): the axial weight acting off
    the axis only shifts load between the bearings.
    """
    particles = [(M, R1, 0.0), (M, 0.6, 2.0), (25.0, 1.3, -0.9)]
    model = particles_model(particles, G, axial_gravity=g_z)
    (f1, f4, front_axial), (f2, f5, f3) = bearing_reactions(model, theta, OMEGA)
    total_mass = sum(m for m, _, _ in particles)
    assert f3 == pytest.approx(-total_mass * g_z, rel=1e-15)      # measured: exact
    assert front_axial == 0.0
    eq_4_6, eq_4_9 = eq_4_39_4_41(particles, theta, OMEGA, G)
    scale = M * R1 * OMEGA**2
    # Measured: 3.2e-16 of the scale at most.
    assert f1 + f2 == pytest.approx(2 * eq_4_6, abs=2e-15 * scale)
    assert f4 + f5 == pytest.approx(2 * eq_4_9, abs=2e-15 * scale)
    assert abs(f1 - f2) > 1.0        # the axial weight at the particles' radii: a moment


def test_printed_gravity_terms_of_eq_4_6_lose_the_weight():
    """
    At rest, phi = pi: the bearings must carry the rotor's full weight 2 m g.

    Eq. 4.6 as printed gives F1 + F2 = m g cos(theta) + m g cos(theta + pi) = 0.
    """
    particles = [(M, R1, 0.0), (M, R1, math.pi)]
    reactions = bearing_reactions(particles_model(particles, G), 0.0, 0.0)
    total = reactions[0] + reactions[1]
    np.testing.assert_allclose(total, [2 * M * G, 0.0, 0.0], atol=1e-12)   # measured: 0
    printed_f1, _ = eq_4_39_4_41(particles, 0.0, 0.0, G, printed_gravity=True)
    assert 2 * printed_f1 == pytest.approx(0.0, abs=1e-12)   # 4.8e-14 = 1e-16 of m g


@pytest.mark.parametrize('r2, phi', [(0.5, math.pi / 2), (1.0, 2.0), (0.2, -2.5), (1.7, 0.0)])
def test_eq_4_13_resultant_balance_force(r2, phi):
    model = particles_model([(M, R1, 0.0), (M, r2, phi)], gravity=0.0)
    w2 = OMEGA**2
    eq_4_13 = math.sqrt((w2 * R1 * M + w2 * r2 * M * math.cos(phi))**2
                        + w2**2 * r2**2 * M**2 * math.sin(phi)**2)
    assert resultant(model, OMEGA) == pytest.approx(eq_4_13, rel=1e-15)    # measured: equal


def test_eq_4_13_value_at_the_thesis_parameters():
    # R2 = 0.5 m, phi = 90 deg: sqrt(5760^2 + 2880^2) N.
    model = particles_model([(M, R1, 0.0), (M, 0.5, math.pi / 2)], gravity=0.0)
    assert resultant(model, OMEGA) == pytest.approx(math.hypot(5760.0, 2880.0), rel=1e-15)


@pytest.mark.parametrize('m2', [40.0, 25.0, 64.0])
def test_eq_4_15_balance_point(m2):
    r2 = R1 * M / m2                                               # Eq. 4.15
    model = particles_model([(M, R1, 0.0), (m2, r2, math.pi)], gravity=0.0)
    assert resultant(model, OMEGA) < 1e-12 * M * R1 * OMEGA**2


def test_eq_4_16_the_resultant_has_a_kink_at_balance():
    """dF_res/dR2 at phi = pi is -omega^2 m2 just below balance and +omega^2 m2 above."""
    step = 1e-4
    below = [resultant(particles_model([(M, R1, 0.0), (M, r, math.pi)], 0.0), OMEGA)
             for r in (R1 - 2 * step, R1 - step)]
    above = [resultant(particles_model([(M, R1, 0.0), (M, r, math.pi)], 0.0), OMEGA)
             for r in (R1 + step, R1 + 2 * step)]
    # F_res is linear on each side: the differences are exact but for rounding, 2 eps
    # F_res / step = 2.6e-8 N at most (4.4e-12 relative); measured 6.4e-10 N.
    assert (below[1] - below[0]) / step == pytest.approx(-OMEGA**2 * M, rel=5e-12)
    assert (above[1] - above[0]) / step == pytest.approx(OMEGA**2 * M, rel=5e-12)


@pytest.mark.parametrize('gravity', [0.0, G])
@pytest.mark.parametrize('r3, gamma', [(1.0, 4 * math.pi / 3), (0.7, 1.0), (1.3, -2.0)])
def test_eq_4_25_to_4_29_three_particles(gravity, r3, gamma):
    phi, theta, r2 = 2 * math.pi / 3, 0.6, 1.0
    particles = [(M, R1, 0.0), (M, r2, phi), (M, r3, gamma)]
    model = particles_model(particles, gravity)
    (f1, f4, _), (f2, f5, _) = bearing_reactions(model, theta, OMEGA)
    eq_4_25, eq_4_28 = eq_4_39_4_41(particles, theta, OMEGA, gravity)
    scale = M * R1 * OMEGA**2     # measured: 6.3e-16 of it at most
    for value, expected in ((f1, eq_4_25), (f2, eq_4_25), (f4, eq_4_28), (f5, eq_4_28)):
        assert value == pytest.approx(expected, abs=4e-15 * scale)
    if gravity == 0.0:
        w2 = OMEGA**2
        eq_4_31 = math.sqrt((w2 * r3 * M * math.sin(gamma) + w2 * r2 * M * math.sin(phi))**2
                            + (w2 * R1 * M + w2 * r3 * M * math.cos(gamma)
                               + w2 * r2 * M * math.cos(phi))**2)
        assert resultant(model, OMEGA) == pytest.approx(eq_4_31, abs=4e-15 * scale)


def test_eq_4_32_and_erratum_8_three_particle_balance_at_one_metre():
    """Balance at R3 = R2 = 1 m (not "40 kg"), gamma = 4 pi / 3, for phi = 2 pi / 3."""
    model = particles_model([(M, R1, 0.0), (M, 1.0, 2 * math.pi / 3),
                             (M, 1.0, 4 * math.pi / 3)], gravity=0.0)
    assert resultant(model, OMEGA) < 1e-12 * M * R1 * OMEGA**2


def test_erratum_7_gravity_torque_has_sin_theta_plus_gamma():
    """Eq. 4.23's Z moment: the third particle's term is m3 g sin(theta + gamma)."""
    phi, gamma, theta = 2 * math.pi / 3, 1.1, 0.4
    model = particles_model([(M, 1.0, 0.0), (M, 1.0, phi), (M, 1.0, gamma)], G)
    torque = sample_loads(model, theta, OMEGA, 0.0).drive_torque
    # Drive torque holding the rotor against gravity (R = 1 m, so the printed form's
    # missing R_i does not show): minus the gravity moment about Z.
    meant = -M * G * (math.sin(theta) + math.sin(theta + phi) + math.sin(theta + gamma))
    printed = -M * G * (math.sin(theta) + math.sin(theta + phi) + math.sin(gamma + phi))
    assert torque == pytest.approx(meant, rel=1e-15)          # measured: equal
    assert abs(torque - printed) > 1.0


def test_erratum_6_gravity_sign_of_sum_fy_is_that_of_eq_4_2():
    """At rest, F4 + F5 = -sum m_i g sin(theta): Eq. 4.2's sign; Ch. 5 flips it."""
    theta, phi = 0.9, 2.0
    model = particles_model([(M, R1, 0.0), (M, 0.8, phi)], G)
    (_, f4, _), (_, f5, _) = bearing_reactions(model, theta, 0.0)
    physics = -2 * M * G * math.sin(theta)
    assert f4 + f5 == pytest.approx(physics, rel=1e-15)       # measured: equal
    # Body A's own term, where Eq. 4.2 and the physics agree: -m g sin(theta) per body.
    chapter_5 = +2 * M * G * math.sin(theta)
    assert abs((f4 + f5) - chapter_5) > 100.0


def test_erratum_1_axial_offsets_load_the_bearings_unequally():
    """A couple unbalance: no net force, yet +-2 m R d omega^2 / L at the bearings."""
    m, r, d = 5.0, 0.5, 0.2
    model = RotorModel.from_layout(parse_layout({
        'name': 'couple', 'gravity': [0.0, 0.0, 0.0],
        'components': [{'name': 'front', 'mass': m, 'radius': r, 'angle': math.pi, 'z': -d},
                       {'name': 'rear', 'mass': m, 'radius': r, 'angle': 0.0, 'z': d}],
        'supports': [{'name': 'front', 'z': -HALF_SPAN},
                     {'name': 'rear', 'z': HALF_SPAN, 'axial': True}]}))
    result = sample_loads(model, 0.0, OMEGA, 0.0)
    couple_force = 2 * m * r * d * OMEGA**2 / (2 * HALF_SPAN)   # 144 N; measured 3.1e-14 off
    assert np.abs(result.force_stator).max() < 1e-15 * couple_force
    np.testing.assert_allclose(result.supports['rear'][0], [couple_force, 0, 0],
                               atol=1e-15 * couple_force)
    np.testing.assert_allclose(result.supports['front'][0], [-couple_force, 0, 0],
                               atol=1e-15 * couple_force)


# --- Ch. 5: cylinders ----------------------------------------------------------------

CYLINDER = {'type': 'cylinder', 'radius': 0.1, 'length': 0.3}


@pytest.mark.parametrize('r2_edge, phi', [(0.9, math.pi), (0.5, 1.2), (0.3, -2.4)])
def test_eq_5_4_two_cylinders_act_like_point_masses(r2_edge, phi):
    r = CYLINDER['radius']
    r1_edge = 1.0 - r                          # (R1 + r) = 1 m, Sec. 5.2
    cylinders = particles_model([(M, r1_edge + r, 0.0), (M, r2_edge + r, phi)], 0.0,
                                shapes=[CYLINDER, CYLINDER])
    points = particles_model([(M, r1_edge + r, 0.0), (M, r2_edge + r, phi)], 0.0)
    w2 = OMEGA**2
    eq_5_4 = math.sqrt((M * w2 * (r1_edge + r) + M * w2 * math.cos(phi) * (r2_edge + r))**2
                       + M**2 * w2**2 * math.sin(phi)**2 * (r2_edge + r)**2)
    # Measured: 2.1e-16 relative at most; F1 and F2 equal to 1e-16 of the scale.
    assert resultant(cylinders, OMEGA) == pytest.approx(eq_5_4, rel=1e-15)
    assert resultant(points, OMEGA) == pytest.approx(eq_5_4, rel=1e-15)
    f_cyl = bearing_reactions(cylinders, 0.3, OMEGA)
    np.testing.assert_allclose(f_cyl[0], f_cyl[1], atol=1e-15 * M * OMEGA**2)   # F1 = F2


def test_eq_5_6_n_cylinders_inertia_and_erratum_2():
    """Eq. 5.6 sums; I_YY must include body A's m (r + R1)^2 (Eq. 5.2 leaves it out)."""
    r, length = CYLINDER['radius'], CYLINDER['length']
    edges, angles = [0.8, 0.5, 0.6, 0.7], [0.0, 2.0, -2.2, 3.0]
    model = particles_model([(M, e + r, a) for e, a in zip(edges, angles)], 0.0,
                            shapes=[CYLINDER] * len(edges))
    n, inertia = len(edges), model.body.inertia
    own = n / 12 * M * (3 * r**2 + length**2)
    i_xx = own + sum(M * (r + e)**2 * math.sin(a)**2 for e, a in zip(edges[1:], angles[1:]))
    i_zz = n / 2 * M * r**2 + sum(M * (r + e)**2 for e in edges)
    i_yy_printed = own + sum(M * (r + e)**2 * math.cos(a)**2
                             for e, a in zip(edges[1:], angles[1:]))
    i_yy_physics = i_yy_printed + M * (r + edges[0])**2
    tensor_xy = sum(-0.5 * M * (r + e)**2 * math.sin(2 * a) for e, a in zip(edges, angles))
    # Measured: 3.3e-16 apart at most.
    assert inertia[0, 0] == pytest.approx(i_xx, rel=1e-15)
    assert inertia[2, 2] == pytest.approx(i_zz, rel=1e-15)
    assert inertia[1, 1] == pytest.approx(i_yy_physics, rel=1e-15)
    assert abs(inertia[1, 1] - i_yy_printed) == pytest.approx(M * (r + edges[0])**2, rel=1e-14)
    # Erratum 3: -1/2 m (r+R)^2 sin(2 phi) is the tensor entry; the product integral of
    # Eq. 2.11 is its opposite.
    assert inertia[0, 1] == pytest.approx(tensor_xy, rel=1e-14)
    assert products_of_inertia(inertia)[0] == pytest.approx(-tensor_xy, rel=1e-14)
