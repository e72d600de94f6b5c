"""
Design for balance (issue 16) against references the design code did not write.

* derivatives: central finite differences of the test's own 50-digit evaluation
  of the layout (mpmath: the ISO 21940-2 two-plane split, the couple about the
  centre of mass, the supports' unbalance loads from force and moment balance);
  the thesis's Eq. 4.16-4.19 (two particles) and 4.25-4.38 (three), with two
  misprints found here (Eq. 4.18: the sign of P's last term and Q's factor 2;
  Eq. 4.34: the sign of P's second term) shown against Eq. 4.13 and 4.31;
* Monte Carlo: against the linearised RSS on small tolerances (within sampling
  error); against exact distributions of one toleranced component (a closed
  form through the arcsine of a turned particle, a Rayleigh-like law of a
  box-truncated normal integrated in mpmath, a uniform law); each draw against
  the test's own float64 evaluation and against the physics (RotorModel);
* the worst case against every draw; the allocation against the test's own
  Monte Carlo (scipy's truncated normal, not the package's tables) and against
  tightening every tolerance alike;
* balance points against Eq. 4.15, 4.32 and the implicit derivatives of 4.15;
* the commands: bad tolerance files and arguments get one line and exit code 2.

Seeds are fixed, so every run draws the same numbers.
"""

import json
import math
from pathlib import Path
import subprocess
import sys

import mpmath
import numpy as np
import pytest
from scipy import stats

from cvc_balance.cli import main
from cvc_balance.design.allocation import allocate
from cvc_balance.design.balance_point import solve_balance
from cvc_balance.design.monte_carlo import simulate
from cvc_balance.design.parameters import parse_parameter, with_values
from cvc_balance.design.sensitivity import judged_vectors, norm_slopes, sensitivities
from cvc_balance.design.stack import analyse
from cvc_balance.design.sweep import sweep
from cvc_balance.design.tolerances import load_tolerances, ToleranceError, Tolerances
from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.layout_file import load_layout
from cvc_balance.physics.unbalance import plane_unbalances
from reference import random_layout

ROOT = Path(__file__).resolve().parents[1]
GANTRY = ROOT / 'config' / 'ct_gantry.yaml'
TWO = ROOT / 'config' / 'thesis_two_particles.yaml'
THREE = ROOT / 'config' / 'thesis_three_particles.yaml'
M, R1, OMEGA = 40.0, 1.0, 12.0                     # thesis Sec. 4.1.1
mpmath.mp.dps = 50


# --- the test's own evaluation, 50 digits ------------------------------------------


def mp_balance(components, planes, supports, omega):
    """
    Balance of (m, R, theta, z, p'_xz, p'_yz) components in mpmath, from first principles.

    S = sum m R e^{i theta}; P about O = sum (m R z + p') e^{i theta} (p': own products,
    own frame); planes by ISO 21940-2 (U_I + U_II = S, z_I U_I + z_II U_II = P); couple
    P - S z_com; support loads from force and moment balance of omega^2 S, omega^2 P.
    """
    mass = s = s_z = p = mpmath.mpf(0)
    for m, r, theta, z, own_x, own_y in components:
        turn = mpmath.expj(theta)
        mass += m
        s += m * r * turn
        s_z += m * z
        p += (m * r * z + mpmath.mpc(own_x, own_y)) * turn
    (z_i, z_ii), (z_a, z_b) = planes, supports
    w2 = mpmath.mpf(omega) ** 2
    return {'planes': [(z_ii * s - p) / (z_ii - z_i), (p - z_i * s) / (z_ii - z_i)],
            'static': [s], 'couple': [p - s * s_z / mass],
            'supports': [w2 * (z_b * s - p) / (z_b - z_a), w2 * (p - z_a * s) / (z_b - z_a)]}


def mp_components(layout):
    rows = []
    for c in layout.components:
        own = (0.0, 0.0) if c.inertia is None else (-c.inertia[4], -c.inertia[5])
        rows.append([mpmath.mpf(v) for v in (c.mass, c.radius, c.angle, c.z, *own)])
    return rows


@pytest.mark.parametrize('seed', range(4))
def test_derivatives_match_50_digit_central_differences(seed):
    """Every component x parameter x output, against d/dp of the test's own evaluation."""
    rng = np.random.default_rng(seed)
    mapping = random_layout(rng, n=4, supports=2, every_kind=True)
    mapping['balancing'] = {'planes': [-0.25, 0.35]}       # planes apart from the supports
    layout = parse_layout(mapping)
    omega = 9.0
    sens = sensitivities(RotorModel.from_layout(layout), omega)
    supports = tuple(mpmath.mpf(s.z) for s in layout.supports)
    planes = tuple(mpmath.mpf(z) for z in layout.correction_planes())
    base = mp_components(layout)
    worst = 0.0
    for row, parameter in enumerate(sens.parameters):
        h = mpmath.mpf('1e-20') * max(1, abs(base[parameter.index][parameter.column]))
        outputs = []
        for sign in (1, -1):
            moved = [list(c) for c in base]
            moved[parameter.index][parameter.column] += sign * h
            outputs.append(mp_balance(moved, planes, supports, omega))
        package = {'planes': sens.planes[row], 'static': sens.static[row][None],
                   'couple': sens.couple[row][None], 'supports': sens.supports[row]}
        for key, values in package.items():
            for k, value in enumerate(values):
                exact = complex((outputs[0][key][k] - outputs[1][key][k]) / (2 * h))
                scale = max(abs(complex(*v)) for v in sens.__dict__[key].reshape(-1, 2))
                error = abs(complex(*value) - exact) / max(abs(exact), 1e-9 * scale)
                worst = max(worst, error)
    # Measured: 1.5e-13 at most (an entry whose terms cancel), 1e-15 typically.
    assert worst < 1e-12


# --- the thesis, Ch. 4 -----------------------------------------------------------------


def particles(*items, name='thesis'):
    """Particles (m, R, theta) in the plane z = 0, bearings at +-0.5 m, no gravity."""
    return parse_layout({
        'name': name, 'gravity': [0.0, 0.0, 0.0],
        'components': [{'name': 'ABC'[i], 'mass': m, 'radius': r, 'angle': t}
                       for i, (m, r, t) in enumerate(items)],
        'supports': [{'name': 'front', 'z': -0.5}, {'name': 'rear', 'z': 0.5, 'axial': True}],
        'balancing': {'grade': 6.3, 'service_speed': OMEGA}})


def resultant_slopes(layout, parameter):
    """One-sided slopes of F_res = omega^2 |S| along ``parameter`` (package)."""
    sens = sensitivities(RotorModel.from_layout(layout), OMEGA)
    row = [p.label for p in sens.parameters].index(parameter)
    w2 = OMEGA ** 2
    return norm_slopes(w2 * sens.nominal.static, w2 * sens.static[row], w2 * sens.size)


@pytest.mark.parametrize('r2', [0.3, 0.7, 1.3, 1.9])
def test_eq_4_16_slope_of_the_resultant_in_r2(r2):
    w2 = OMEGA ** 2
    eq_4_16 = -w2 * M * (w2 * R1 * M - w2 * r2 * M) / abs(w2 * R1 * M - w2 * r2 * M)
    minus, plus = resultant_slopes(particles((M, R1, 0.0), (M, r2, math.pi)), 'B.radius')
    assert minus == pytest.approx(eq_4_16, rel=1e-14) and plus == minus


def test_eq_4_16_jumps_at_the_balance_point_the_vector_does_not():
    """At R2 = R1 m1 / m2 (Eq. 4.15) the norm's slopes are -omega^2 m2 and +omega^2 m2."""
    layout = particles((M, R1, 0.0), (M, R1, math.pi))
    minus, plus = resultant_slopes(layout, 'B.radius')
    assert (minus, plus) == (pytest.approx(-OMEGA ** 2 * M, rel=1e-15),
                             pytest.approx(OMEGA ** 2 * M, rel=1e-15))
    # The vector's derivative: -omega^2 m2 e_x, the same from both sides (both layouts).
    for r2 in (R1 - 1e-3, R1, R1 + 1e-3):
        sens = sensitivities(RotorModel.from_layout(particles((M, R1, 0.0), (M, r2, math.pi))),
                             OMEGA)
        row = [p.label for p in sens.parameters].index('B.radius')
        np.testing.assert_allclose(OMEGA ** 2 * sens.static[row], [-OMEGA ** 2 * M, 0.0],
                                   atol=1e-12)


def eq_4_13(r2, phi):
    w2 = OMEGA ** 2
    return mpmath.sqrt((w2 * R1 * M + w2 * r2 * M * mpmath.cos(phi)) ** 2
                       + w2 ** 2 * r2 ** 2 * M ** 2 * mpmath.sin(phi) ** 2)


@pytest.mark.parametrize('phi', [0.4, 2.0, 2.9, 3.5, 5.5])
def test_eq_4_17_to_4_19_slope_in_phi_and_the_misprint_of_4_18(phi):
    """dF_res/dphi at R2 = R1 m1 / m2: the package, Eq. 4.13 differentiated, Eq. 4.17-4.19."""
    w2, h = OMEGA ** 2, mpmath.mpf('1e-25')
    exact = float((eq_4_13(R1, phi + h) - eq_4_13(R1, phi - h)) / (2 * h))
    minus, plus = resultant_slopes(particles((M, R1, 0.0), (M, R1, phi)), 'B.angle')
    assert minus == plus == pytest.approx(exact, rel=1e-13)
    a = w2 * R1 * M
    q = math.sqrt((a + a * math.cos(phi)) ** 2 + a ** 2 * math.sin(phi) ** 2)     # Eq. 4.19
    printed = -2 * a * math.sin(phi) * (a + a * math.cos(phi)) \
        - 2 * a ** 2 * math.cos(phi) * math.sin(phi)                                # Eq. 4.18
    corrected = -2 * a * math.sin(phi) * (a + a * math.cos(phi)) \
        + 2 * a ** 2 * math.cos(phi) * math.sin(phi)
    assert corrected / (2 * q) == pytest.approx(exact, rel=1e-12)
    assert abs(printed / q - exact) > 0.1 * abs(exact)        # as printed: not the slope


def three(r3, gamma):
    return particles((M, R1, 0.0), (M, 1.0, 2 * math.pi / 3), (M, r3, gamma))


@pytest.mark.parametrize('r3, gamma', [(1.0, 4 * math.pi / 3), (0.6, 1.0), (1.4, -2.0)])
def test_eq_4_25_to_4_29_bearing_force_derivatives(r3, gamma):
    """d/dR3 and d/dgamma of F1 = F2 (Eq. 4.25-4.26) and F4 = F5 (4.28-4.29), g = 0."""
    w2 = OMEGA ** 2
    by_hand = {'C.radius': (-M / 2 * w2 * math.cos(gamma), -M / 2 * w2 * math.sin(gamma)),
               'C.angle': (M / 2 * r3 * w2 * math.sin(gamma), -M / 2 * r3 * w2 * math.cos(gamma))}
    sens = sensitivities(RotorModel.from_layout(three(r3, gamma)), OMEGA)
    labels = [p.label for p in sens.parameters]
    for parameter, (d_f1, d_f4) in by_hand.items():
        for support in range(2):
            # Loads on the stator (rotor frame at q = 0) are minus the thesis's reactions.
            np.testing.assert_allclose(-sens.supports[labels.index(parameter), support],
                                       (d_f1, d_f4), rtol=1e-13, atol=1e-10)


def eq_4_31(r3, gamma):
    w2, phi = OMEGA ** 2, 2 * mpmath.pi / 3
    return mpmath.sqrt((w2 * r3 * M * mpmath.sin(gamma) + w2 * M * mpmath.sin(phi)) ** 2
                       + (w2 * R1 * M + w2 * r3 * M * mpmath.cos(gamma)
                          + w2 * M * mpmath.cos(phi)) ** 2)


@pytest.mark.parametrize('r3', [0.6, 1.3])
def test_eq_4_33_to_4_35_slope_in_r3_and_the_misprint_of_4_34(r3):
    w2, h, gamma = OMEGA ** 2, mpmath.mpf('1e-25'), 4 * mpmath.pi / 3
    exact = float((eq_4_31(r3 + h, gamma) - eq_4_31(r3 - h, gamma)) / (2 * h))
    minus, plus = resultant_slopes(three(r3, float(gamma)), 'C.radius')
    assert minus == plus == pytest.approx(exact, rel=1e-12)
    a, b3, b2, phi = w2 * R1 * M, w2 * r3 * M, w2 * M, 2 * math.pi / 3
    root3 = math.sqrt(3.0)
    q = 2 * math.sqrt((root3 * b3 / 2 - b2 * math.sin(phi)) ** 2
                      + (a - b3 / 2 + b2 * math.cos(phi)) ** 2)                     # Eq. 4.35
    first = -w2 * M * (a - b3 / 2 + b2 * math.cos(phi))
    second = root3 * w2 * M * (root3 * b3 / 2 - b2 * math.sin(phi))
    assert (first + second) / q == pytest.approx(exact, rel=1e-12)       # sign corrected
    assert (first - second) / q == pytest.approx(-exact / 2, rel=1e-12)  # Eq. 4.34 as printed


@pytest.mark.parametrize('gamma', [2.0, 3.5, 4.5])
def test_eq_4_36_to_4_38_slope_in_gamma(gamma):
    w2, h = OMEGA ** 2, mpmath.mpf('1e-25')
    exact = float((eq_4_31(1.0, gamma + h) - eq_4_31(1.0, gamma - h)) / (2 * h))
    minus, plus = resultant_slopes(three(1.0, gamma), 'C.angle')
    assert minus == plus == pytest.approx(exact, rel=1e-12)
    a = b = w2 * M
    phi = 2 * math.pi / 3
    f_y = b * math.sin(gamma) + b * math.sin(phi)
    f_x = a + b * math.cos(gamma) + b * math.cos(phi)
    m_437 = 2 * b * math.cos(gamma) * f_y - 2 * b * math.sin(gamma) * f_x           # Eq. 4.37
    assert m_437 / (2 * math.hypot(f_x, f_y)) == pytest.approx(exact, rel=1e-12)   # / Eq. 4.38


# --- balance points --------------------------------------------------------------------


def test_balance_solves_eq_4_15_and_its_implicit_derivatives():
    layout = load_layout(TWO)
    r2, phi = parse_parameter(layout, 'B.radius'), parse_parameter(layout, 'B.angle')
    solution = solve_balance(with_values(layout, {r2: 0.6, phi: 2.0}), [r2, phi])
    assert solution.values[0] == pytest.approx(R1 * M / M, rel=1e-14)      # Eq. 4.15
    assert solution.values[1] == pytest.approx(math.pi, rel=1e-14)
    assert solution.balanced
    # d R2 / d m1 = R1 / m2, d R2 / d R1 = m1 / m2, d R2 / d m2 = -R1 m1 / m2^2 (Eq. 4.15).
    moves = dict(zip([p.label for p in solution.others], solution.moves_with[0]))
    assert moves['A.mass'] == pytest.approx(R1 / M, rel=1e-12)
    assert moves['A.radius'] == pytest.approx(M / M, rel=1e-12)
    assert moves['B.mass'] == pytest.approx(-R1 * M / M ** 2, rel=1e-12)
    assert abs(moves['A.angle']) < 1e-12                      # the radius ignores A's angle
    # ... and phi follows A's angle one for one.
    assert dict(zip([p.label for p in solution.others], solution.moves_with[1]))[
        'A.angle'] == pytest.approx(1.0, rel=1e-12)


def test_balance_solves_eq_4_32_three_particles():
    layout = load_layout(THREE)
    r3, gamma = parse_parameter(layout, 'C.radius'), parse_parameter(layout, 'C.angle')
    solution = solve_balance(with_values(layout, {r3: 0.4, gamma: 3.0}), [r3, gamma])
    assert solution.values[0] == pytest.approx(1.0, rel=1e-13)              # erratum 8
    assert solution.values[1] == pytest.approx(4 * math.pi / 3, rel=1e-13)
    assert solution.balanced


def test_balance_of_the_gantry_by_its_counterweights():
    layout = load_layout(GANTRY)
    free = [parse_parameter(layout, f'counterweight_{side}.{name}')
            for side in ('front', 'rear') for name in ('mass', 'angle')]
    solution = solve_balance(layout, free)
    assert solution.balanced and solution.within_grade
    # The physics, on the solved layout: no unbalance left in either plane.
    model = RotorModel.from_layout(solution.layout)
    size = solution.size
    for plane in plane_unbalances(model, -0.12, 0.12, 0.68):
        assert plane.amount < 1e-13 * size          # measured 1.4e-16 of sum m R
    # Two angles alone cannot zero four components: least squares, not balanced.
    angles = [p for p in free if p.name == 'angle']
    least = solve_balance(layout, angles)
    assert not least.balanced
    residual = float(np.sum(least.planes ** 2))
    for delta in ([1e-4, 0.0], [0.0, 1e-4], [-1e-4, 1e-4]):
        nudged = RotorModel.from_layout(with_values(
            layout, {p: v + d for p, v, d in zip(angles, least.values, delta)}))
        planes = plane_unbalances(nudged, -0.12, 0.12, 0.68)
        assert sum(p.amount ** 2 for p in planes) > residual    # a minimum


# --- Monte Carlo -----------------------------------------------------------------------


def gantry_tolerances(layout, scale=1.0, normal=True):
    """Typical workshop tolerances on every component, times ``scale``."""
    mass = layout.placement[0]
    values = np.column_stack([0.002 * mass, np.full(len(mass), 5e-4),
                              np.full(len(mass), math.radians(0.1)), np.full(len(mass), 5e-4)])
    return Tolerances(values * scale, np.full(len(mass), normal))


@pytest.mark.parametrize('normal', [True, False])
def test_monte_carlo_agrees_with_the_linearised_rss_on_small_tolerances(normal):
    layout = load_layout(GANTRY)
    model = RotorModel.from_layout(layout)
    tolerances = gantry_tolerances(layout, scale=0.01, normal=normal)
    samples = 100_000
    result = analyse(model, tolerances, samples, seed=3)
    draws = simulate(model, tolerances, samples, seed=3)
    sens = sensitivities(model)
    nominal = np.array([p.vector for p in plane_unbalances(model, -0.12, 0.12, 0.68)])
    change = judged_vectors(layout, draws.first_moment, draws.products) - nominal
    sigma = tolerances.sigma().reshape(-1)
    for k, plane in enumerate(result.planes):
        squared = np.sum(change[:, k] ** 2, axis=-1)
        stderr = squared.std() / math.sqrt(samples) / (2 * plane.rms_change)
        assert abs(plane.rms_change - plane.rss_sigma) < 4 * stderr
        # The covariance too, entry by entry, against sum sigma^2 J J^T.
        jacobian = sens.planes[:, k]
        expected = (jacobian * sigma[:, None] ** 2).T @ jacobian
        measured = np.cov(change[:, k].T)
        scale = np.trace(expected)
        assert np.max(np.abs(measured - expected)) < 4 * math.sqrt(2.0 / samples) * scale
        # No bias at first order: the mean change is within its standard error.
        mean = change[:, k].mean(axis=0)
        assert np.all(np.abs(mean) < 4 * np.sqrt(np.diag(expected) / samples))


def balanced_two(tolerance_b):
    layout = load_layout(TWO)
    values = np.zeros((2, 4))
    values[1] = tolerance_b[:4]
    return layout, RotorModel.from_layout(layout), Tolerances(values,
                                                              np.array([True, tolerance_b[4]]))


def test_exact_distribution_of_a_particle_turned_within_its_tolerance():
    """|U_plane| = m R |sin(d/2)| (planes halve S), d uniform: CDF 2 asin(u / m R) / t."""
    t = math.radians(60.0)
    layout, model, tolerances = balanced_two([0.0, 0.0, t, 0.0, False])
    draws = simulate(model, tolerances, 100_000, seed=11)
    amounts = np.hypot(*(draws.first_moment / 2).T)
    exact = stats.kstest(amounts, lambda u: np.clip(2 * np.arcsin(u / (M * R1)) / t, 0, 1))
    linear = stats.kstest(amounts, lambda u: np.clip(u / (M * R1 * t / 2), 0, 1))
    assert exact.pvalue > 1e-3            # measured: KS distance 2.8e-3, p = 0.42
    assert linear.pvalue < 1e-12          # the linearised law is not it (distance 0.045)
    worst = analyse(model, tolerances, 1000, seed=1).planes[0].worst_case
    assert worst == pytest.approx(M * R1 * math.sin(t / 2), rel=1e-14)


def box_truncated_rayleigh_cdf(u, sigma):
    """P(sqrt(X^2 + Y^2) <= u), X, Y iid normal(0, sigma) truncated at 3 sigma (mpmath)."""
    def density(x):
        return mpmath.npdf(x, 0, sigma)
    inside = mpmath.ncdf(3 * sigma, 0, sigma) - mpmath.ncdf(-3 * sigma, 0, sigma)

    def strip(x):
        half = mpmath.sqrt(max(u * u - x * x, 0))
        half = min(half, 3 * sigma)
        return density(x) * (mpmath.ncdf(half, 0, sigma) - mpmath.ncdf(-half, 0, sigma))
    edge = min(u, 3 * sigma)
    with mpmath.workdps(20):                    # 20 digits: far below the test's 6e-3
        return float(mpmath.quad(strip, [-edge, 0, edge]) / inside ** 2)


def test_rayleigh_law_of_a_particle_off_by_radius_and_angle():
    """sigma_R = R sigma_theta: U - U0 is a 2-D truncated normal, |U| Rayleigh-like."""
    t_radius = 3e-5                                         # m, 3 sigma: linear to 1e-5
    layout, model, tolerances = balanced_two([0.0, t_radius, t_radius / R1, 0.0, True])
    samples = 200_000
    draws = simulate(model, tolerances, samples, seed=5)
    amounts = np.sort(np.hypot(*(draws.first_moment / 2).T))
    sigma = M * t_radius / 3 / 2                            # per axis, in the plane
    grid = np.linspace(0.25, 4.0, 16) * sigma
    distance = max(abs(np.searchsorted(amounts, u) / samples
                       - box_truncated_rayleigh_cdf(mpmath.mpf(u), mpmath.mpf(sigma)))
                   for u in grid)
    # DKW: P(sup |F_n - F| > e) <= 2 exp(-2 n e^2) = 1e-6 at e = 0.0060. Measured 1.2e-3
    # (the untruncated Rayleigh law is 5.9e-3 away: the draws are truncated at 3 sigma).
    assert distance < 0.006


def test_probability_within_grade_of_a_uniform_radius():
    """|U_plane| = m |dR| / 2, dR uniform +-t: P(|U| <= A) = 2 A / (m t) exactly."""
    allowed = 0.021                     # kg m: G 6.3, 80 kg, 12 rad/s, half per plane
    t = 4 * allowed / M                 # P = 0.5
    layout, model, tolerances = balanced_two([0.0, t, 0.0, 0.0, False])
    result = analyse(model, tolerances, 200_000, seed=2)
    assert result.planes[0].permissible == pytest.approx(allowed, rel=1e-14)
    assert abs(result.probability_within_grade - 0.5) < 4 * result.probability_stderr
    # The worst case is reached: the radius at its tolerance (16-bit draws: 1 - 2^-16).
    assert result.planes[0].worst_case == pytest.approx(M * t / 2, rel=1e-14)
    assert result.planes[0].max_drawn == pytest.approx(M * t / 2, rel=2e-5)


@pytest.mark.parametrize('seed', range(3))
def test_each_draw_is_the_layout_it_says(seed):
    """Draws against the test's own float64 sums and against the physics' RotorModel."""
    rng = np.random.default_rng(seed)
    layout = parse_layout(random_layout(rng, n=6, supports=2, every_kind=True))
    model = RotorModel.from_layout(layout)
    n = len(layout.components)
    values = np.column_stack([rng.uniform(0, 0.05, n) * layout.placement[0],
                              rng.uniform(0, 5e-3, n), rng.uniform(0, 0.2, n),
                              rng.uniform(0, 5e-3, n)])
    tolerances = Tolerances(values, rng.random(n) < 0.5)
    draws = simulate(model, tolerances, 3000, seed, keep_deviations=True)
    dev = draws.deviations
    assert np.all(np.abs(dev) <= values)                     # within the tolerances
    mass, radius, angle, z = (p + dev[..., i] for i, p in enumerate(layout.placement))
    own = np.array([(0.0, 0.0) if c.inertia is None else (-c.inertia[4], -c.inertia[5])
                    for c in layout.components])
    turn = np.exp(1j * angle)
    s = np.sum(mass * radius * turn, axis=1)
    p = np.sum((mass * radius * z + own[:, 0] + 1j * own[:, 1]) * turn, axis=1)
    change_s = np.abs(s - complex(model.s_x, model.s_y)).max()
    change_p = np.abs(p - complex(model.p_xz, model.p_yz)).max()
    # float32 deviations: measured 1.4e-7 to 2.1e-7 of the largest change.
    assert np.abs(s - (draws.first_moment @ [1, 1j])).max() < 2e-6 * change_s
    assert np.abs(p - (draws.products @ [1, 1j])).max() < 2e-6 * change_p
    for k in range(0, 3000, 600):
        values = {q: getattr(layout.components[q.index], q.name) + dev[k, q.index, q.column]
                  for q in sensitivities(model).parameters}
        for q in list(values):
            if q.name == 'radius' and values[q] < 0.0:     # a signed radius: half a turn on
                values[q] = -values[q]
                angle = parse_parameter(layout, f'{q.component}.angle')
                values[angle] += math.pi
        drawn = RotorModel.from_layout(with_values(layout, values))
        assert abs(complex(drawn.s_x, drawn.s_y) - draws.first_moment[k] @ [1, 1j]) \
            < 2e-6 * change_s


@pytest.mark.parametrize('seed', range(3))
def test_worst_case_is_never_below_a_draw(seed):
    rng = np.random.default_rng(seed + 20)
    layout = parse_layout(random_layout(rng, n=int(rng.integers(1, 5)), supports=2,
                                        every_kind=seed == 0))
    model = RotorModel.from_layout(layout)
    n = len(layout.components)
    # Large tolerances, where the linear worst case is not a bound: angles up to 40 deg.
    values = np.column_stack([rng.uniform(0, 0.3, n) * layout.placement[0],
                              rng.uniform(0, 0.05, n), rng.uniform(0, 0.7, n),
                              rng.uniform(0, 0.05, n)])
    for normal in (True, False):
        result = analyse(model, Tolerances(values, np.full(n, normal)), 50_000, seed)
        for plane in result.planes:
            assert plane.max_drawn <= plane.worst_case


def test_seed_fixes_the_draws_on_any_number_of_threads():
    layout = load_layout(GANTRY)
    model = RotorModel.from_layout(layout)
    tolerances = gantry_tolerances(layout)
    one = simulate(model, tolerances, 50_000, seed=9)
    again = simulate(model, tolerances, 50_000, seed=9)
    other = simulate(model, tolerances, 50_000, seed=10)
    np.testing.assert_array_equal(one.first_moment, again.first_moment)
    assert not np.array_equal(one.first_moment, other.first_moment)


# --- allocation ------------------------------------------------------------------------


def own_monte_carlo(layout, values, normal, samples, seed):
    """Return the probability within grade by the test's own draws (scipy), float64 sums."""
    rng = np.random.default_rng(seed)
    n = len(layout.components)
    draws = np.empty((samples, n, 4))
    for i in range(n):
        for j in range(4):
            if normal[i]:
                draws[:, i, j] = stats.truncnorm.rvs(-3, 3, scale=values[i, j] / 3,
                                                     size=samples, random_state=rng)
            else:
                draws[:, i, j] = rng.uniform(-values[i, j], values[i, j], samples)
    mass, radius, angle, z = (p + draws[..., j] for j, p in enumerate(layout.placement))
    u = mass * radius * np.exp(1j * angle)
    z_i, z_ii = layout.correction_planes()
    plane_i = np.abs(np.sum(u * (z_ii - z), axis=1) / (z_ii - z_i))
    plane_ii = np.abs(np.sum(u * (z - z_i), axis=1) / (z_ii - z_i))
    assessment = assess_balance(RotorModel.from_layout(layout))
    allowed_i, allowed_ii = assessment.plane_permissible
    return float(np.mean((plane_i <= allowed_i) & (plane_ii <= allowed_ii)))


def test_allocation_meets_its_target_in_an_independent_monte_carlo():
    layout = load_layout(GANTRY)
    model = RotorModel.from_layout(layout)
    tolerances = gantry_tolerances(layout, scale=2.0)
    target = 0.9
    allocation = allocate(model, tolerances, target, 40_000, seed=4)
    assert allocation.probability_given < 0.7                  # it had work to do
    values = allocation.tolerances.values
    assert np.all(values <= tolerances.values)                 # only tightened
    samples = 40_000
    achieved = own_monte_carlo(layout, values, tolerances.normal, samples, seed=99)
    assert achieved > target - 4 * math.sqrt(target * (1 - target) / samples)
    # Cheaper than tightening every tolerance alike to the same probability.
    low, high = 0.0, 1.0
    for _ in range(14):
        middle = (low + high) / 2
        if analyse(model, tolerances.scaled(middle), 20_000, 5).probability_within_grade \
                >= target:
            low = middle
        else:
            high = middle
    uniform_cost = float(np.sum(tolerances.values > 0)) / low
    assert allocation.cost_proposed < 0.9 * uniform_cost


# --- sweeps ----------------------------------------------------------------------------


def test_sweep_reproduces_eq_4_13_and_its_balance_point():
    layout = load_layout(TWO)
    r2, phi = parse_parameter(layout, 'B.radius'), parse_parameter(layout, 'B.angle')
    result = sweep(layout, [r2, phi], [(0.0, 2.0), (0.0, 2 * math.pi)], 41)
    grid_r, grid_phi = np.meshgrid(*result.axes, indexing='ij')
    expected = np.vectorize(lambda r, p: float(eq_4_13(r, p)))(grid_r, grid_phi)
    np.testing.assert_allclose(result.resultant, expected, rtol=1e-12, atol=1e-9)
    (point,) = result.balance_points
    assert point.balanced
    assert point.values == pytest.approx((1.0, math.pi), rel=1e-12)
    along = sweep(layout, [r2], [(0.0, 2.0)], 201)
    minus, plus = along.resultant_slopes
    below, above = along.axes[0] < 1.0, along.axes[0] > 1.0
    assert np.all(plus[below] == pytest.approx(-OMEGA ** 2 * M, rel=1e-13))
    assert np.all(plus[above] == pytest.approx(OMEGA ** 2 * M, rel=1e-13))
    at = int(np.argmin(np.abs(along.axes[0] - 1.0)))
    assert (minus[at], plus[at]) == (pytest.approx(-OMEGA ** 2 * M), pytest.approx(
        OMEGA ** 2 * M))


def test_sweep_of_three_particles_finds_eq_4_32():
    layout = load_layout(THREE)
    r3, gamma = parse_parameter(layout, 'C.radius'), parse_parameter(layout, 'C.angle')
    result = sweep(layout, [r3, gamma], [(0.0, 2.0), (0.0, 2 * math.pi)], 31)
    grid_r, grid_g = np.meshgrid(*result.axes, indexing='ij')
    expected = np.vectorize(lambda r, g: float(eq_4_31(r, g)))(grid_r, grid_g)
    np.testing.assert_allclose(result.resultant, expected, rtol=1e-12, atol=1e-9)
    (point,) = result.balance_points
    assert point.values == pytest.approx((1.0, 4 * math.pi / 3), rel=1e-12)


def test_sweep_values_are_the_physics_at_every_point():
    layout = load_layout(GANTRY)
    p = parse_parameter(layout, 'counterweight_rear.z')
    q = parse_parameter(layout, 'xray_tube.mass')
    result = sweep(layout, [p, q], [(-0.2, 0.2), (55.0, 65.0)], 5)
    for i, z in enumerate(result.axes[0]):
        for j, mass in enumerate(result.axes[1]):
            model = RotorModel.from_layout(with_values(layout, {p: z, q: mass}))
            planes = plane_unbalances(model, -0.12, 0.12, 0.68)
            np.testing.assert_allclose(result.planes[i, j], [pl.vector for pl in planes],
                                       rtol=1e-12, atol=1e-14)


# --- the commands ----------------------------------------------------------------------


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


TOLERANCES = 'default: {mass: 0.05, radius: 0.0005, angle_deg: 0.1, z: 0.0005}\n' \
    'xray_tube: {mass: 0.3, distribution: uniform}\n'

BAD_TOLERANCES = {
    'unknown component': ('tube: {mass: 0.1}\n', ("'tube'", 'unknown component')),
    'unknown field': ('default: {mass: 0.1, speed: 3}\n', ("'speed'", 'unknown field')),
    'negative': ('default: {radius: -0.001}\n', ('radius', '>= 0')),
    'nan': ('default: {z: .nan}\n', ('z', 'finite')),
    'text': ('default: {mass: heavy}\n', ('mass', 'number')),
    'distribution': ('default: {distribution: gaussian}\n', ('distribution', 'gaussian')),
    'mass too large': ('collimator: {mass: 15}\n', ("'collimator'", 'mass tolerance')),
    'angle too large': ('default: {angle_deg: 200}\n', ('angle', '180')),
    'both angles': ('default: {angle_deg: 1, angle: 0.01}\n', ('angle_deg', 'not both')),
    'not a mapping': ('- 1\n- 2\n', ('tolerances', 'mapping')),
    'entry not a mapping': ('detector: 0.1\n', ("'detector'", 'mapping')),
    'broken yaml': ('default: {mass: [\n', ('YAML',)),
    'empty': ('', ('mapping',)),
}


@pytest.mark.parametrize('case', sorted(BAD_TOLERANCES))
def test_bad_tolerance_file_gets_one_line_and_exit_code_2(case, tmp_path, capsys):
    text, needles = BAD_TOLERANCES[case]
    path = tmp_path / 'tol.yaml'
    path.write_text(text)
    code, out, err = run_cli(capsys, 'tolerance', GANTRY, '--tolerances', path)
    assert code == 2 and out == '' and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, (needle, err)
    with pytest.raises(ToleranceError):
        load_tolerances(path, load_layout(GANTRY))


BAD_ARGUMENTS = {
    'no file': (['tolerance', GANTRY, '--tolerances', 'absent.yaml'], 'cannot read'),
    'samples': (['tolerance', GANTRY, '--tolerances', '{tol}', '--samples', '0'], 'samples'),
    'seed': (['tolerance', GANTRY, '--tolerances', '{tol}', '--seed', '-1'], 'seed'),
    'target': (['tolerance', GANTRY, '--tolerances', '{tol}', '--target-probability', '1.5'],
               'target'),
    'omega': (['sensitivity', GANTRY, '--omega', '0'], 'omega'),
    'free component': (['balance', GANTRY, '--free', 'tube.angle'], "'tube'"),
    'free parameter': (['balance', GANTRY, '--free', 'detector.speed'], "'speed'"),
    'free form': (['balance', GANTRY, '--free', 'detector'], 'COMPONENT.PARAMETER'),
    'sweep component': (['sweep', GANTRY, '--component', 'tube', '--parameter', 'z',
                         '--range', '0', '1'], "'tube'"),
    'sweep range': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                     '--range', '1', '0'], 'low to high'),
    'sweep radius': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'radius',
                      '--range', '-1', '1'], '>= 0'),
    'sweep ranges': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                      '--parameter', 'mass', '--range', '0', '1'], '--range'),
    'sweep three': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                     '--parameter', 'mass', '--parameter', 'angle', '--range', '0', '1',
                     '--range', '1', '2', '--range', '0', '1'], 'one or two'),
    'sweep derivative': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                          '--parameter', 'mass', '--range', '0', '1', '--range', '1', '2',
                          '--derivative'], 'derivative'),
    'sweep points': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                      '--range', '0', '1', '--points', '1'], 'points'),
    'out of grade': (['tolerance', TWO, '--tolerances', '{two_tol}', '--target-probability',
                      '0.9'], 'out of G'),
    'samples not a number': (['tolerance', GANTRY, '--tolerances', '{tol}', '--samples',
                              'many'], '--samples'),
    'no tolerance file': (['tolerance', GANTRY], '--tolerances'),
    'range not a number': (['sweep', GANTRY, '--component', 'detector', '--parameter', 'z',
                            '--range', '0', 'far'], '--range'),
    'unknown parameter choice': (['sweep', GANTRY, '--component', 'detector', '--parameter',
                                  'speed', '--range', '0', '1'], '--parameter'),
}


@pytest.mark.parametrize('case', sorted(BAD_ARGUMENTS))
def test_bad_arguments_get_one_line_and_exit_code_2(case, tmp_path, capsys):
    tol = tmp_path / 'tol.yaml'
    tol.write_text(TOLERANCES)
    two_tol = tmp_path / 'two.yaml'
    two_tol.write_text('B: {radius: 0.001}\n')
    unbalanced = tmp_path / 'two_unbalanced.yaml'
    unbalanced.write_text(TWO.read_text().replace('{name: B, mass: 40.0, radius: 1.0',
                                                  '{name: B, mass: 40.0, radius: 1.1'))
    argv, needle = BAD_ARGUMENTS[case]
    argv = [str(a).format(tol=tol, two_tol=two_tol) for a in argv]
    if case == 'out of grade':
        argv[1] = str(unbalanced)
    try:
        code, out, err = run_cli(capsys, *argv, '-o' if argv[0] == 'sweep' else '--json',
                                 *([tmp_path / 'x.png'] if argv[0] == 'sweep' else []))
    except SystemExit as stop:             # argparse's own errors (types, choices, missing)
        out, err = capsys.readouterr()
        code = stop.code
    assert code == 2 and out == '' and len(err.strip().splitlines()) == 1, err
    assert needle in err, err


def test_commands_json_carry_the_issue_schemas(tmp_path, capsys):
    tol = tmp_path / 'tol.yaml'
    tol.write_text(TOLERANCES)
    code, out, _ = run_cli(capsys, 'sensitivity', GANTRY, '--json', '--norms')
    rows = json.loads(out)['parameters']
    assert code == 0 and len(rows) == 40
    assert set(rows[0]) >= {'component', 'parameter', 'd_planes_g_mm', 'd_static_kg_m',
                            'd_couple_kg_m2', 'd_supports_N', 'norm_slopes'}
    moves = [r['moves_worse_plane_g_mm'] for r in rows]
    assert moves == sorted(moves, reverse=True)
    code, out, _ = run_cli(capsys, 'tolerance', GANTRY, '--tolerances', tol, '--samples',
                           '20000', '--json', '--target-probability', '0.8')
    summary = json.loads(out)
    assert code == 0
    for plane in summary['planes']:
        assert set(plane) >= {'z', 'nominal_g_mm', 'mean_g_mm', 'p50_g_mm', 'p95_g_mm',
                              'p99_g_mm', 'rss_sigma_g_mm', 'worst_case_g_mm',
                              'permissible_g_mm'}
    assert 0.0 <= summary['probability_within_grade'] <= 1.0
    assert sum(c['share'] for c in summary['contributions']) == pytest.approx(1.0)
    assert summary['allocation']['probability_proposed'] >= 0.8
    code, out, _ = run_cli(capsys, 'balance', TWO, '--free', 'B.radius', 'B.angle', '--json')
    assert code == 0 and json.loads(out)['balanced']
    png = tmp_path / 'map.png'
    code, out, _ = run_cli(capsys, 'sweep', THREE, '--component', 'C', '--parameter', 'radius',
                           '--range', '0', '2', '--parameter', 'angle', '--range', '0', '360',
                           '--points', '31', '-o', png, '--json')
    summary = json.loads(out)
    assert code == 0 and png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    (point,) = summary['balance_points']
    assert point['values']['C.angle_deg'] == pytest.approx(240.0, rel=1e-12)


def test_the_installed_command_runs_without_a_traceback(tmp_path):
    """One real process: the entry point, a table for people, and a bad file."""
    tol = tmp_path / 'tol.yaml'
    tol.write_text(TOLERANCES)
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'tolerance', str(GANTRY),
                          '--tolerances', str(tol), '--samples', '5000'],
                         capture_output=True, text=True)
    assert run.returncode == 0 and 'probability of meeting G 6.3' in run.stdout, run.stderr
    tol.write_text('default: {mass: -1}\n')
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'tolerance', str(GANTRY),
                          '--tolerances', str(tol)], capture_output=True, text=True)
    assert run.returncode == 2 and 'Traceback' not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1


def test_matplotlib_only_in_the_chart_module():
    """The design package's pictures are drawn in one module (test_architecture: its layer)."""
    import ast
    for path in sorted((ROOT / 'cvc_balance' / 'design').glob('*.py')):
        tree = ast.parse(path.read_text())
        names = {alias.name.split('.')[0] for node in ast.walk(tree)
                 if isinstance(node, ast.Import) for alias in node.names}
        names |= {node.module.split('.')[0] for node in ast.walk(tree)
                  if isinstance(node, ast.ImportFrom) and node.module}
        assert ('matplotlib' in names) == (path.name == 'charts.py'), path.name
