"""
Unbalance, correction masses and ISO 21940-11 grades against independent references.

References: the two-plane formulas of ISO 21940-2 evaluated per component in
50-digit arithmetic (mpmath), and the worked example of shared/domain/FACTS.md.
"""

import math
from pathlib import Path

import mpmath
import numpy as np
import pytest

from cvc_balance.physics import iso21940
from cvc_balance.physics.assessment import assess_balance, judge_balance, judging_speed
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.layout_file import load_layout
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance

mpmath.mp.dps = 50
GANTRY = Path(__file__).resolve().parents[1] / 'config' / 'ct_gantry.yaml'


def points(masses):
    """Make a layout of point masses (m, R, theta, z)."""
    return RotorModel.from_layout(parse_layout({
        'name': 'points', 'supports': [{'name': 'a', 'z': -0.4},
                                       {'name': 'b', 'z': 0.4, 'axial': True}],
        'components': [{'name': f'p{i}', 'mass': m, 'radius': r, 'angle': t, 'z': z}
                       for i, (m, r, t, z) in enumerate(masses)]}))


def two_plane_reference(masses, z_i, z_ii):
    """ISO 21940-2: U_I = sum U_i (z_II - z_i) / b, U_II = sum U_i (z_i - z_I) / b (mpmath)."""
    b = mpmath.mpf(z_ii) - mpmath.mpf(z_i)
    u_i = u_ii = mpmath.mpc(0)
    for m, r, t, z in masses:
        u = mpmath.mpf(m) * mpmath.mpf(r) * mpmath.expj(mpmath.mpf(t))
        u_i += u * (mpmath.mpf(z_ii) - mpmath.mpf(z)) / b
        u_ii += u * (mpmath.mpf(z) - mpmath.mpf(z_i)) / b
    return u_i, u_ii


@pytest.mark.parametrize('seed', range(10))
def test_plane_unbalances_match_the_two_plane_formula(seed):
    rng = np.random.default_rng(seed)
    masses = [(rng.uniform(0.1, 50), rng.uniform(0, 0.8), rng.uniform(-4, 4),
               rng.uniform(-0.5, 0.5)) for _ in range(int(rng.integers(1, 30)))]
    z_i, z_ii = -0.3, 0.25
    plane_1, plane_2 = plane_unbalances(points(masses), z_i, z_ii, 0.7)
    ref_1, ref_2 = two_plane_reference(masses, z_i, z_ii)
    size = float(sum(m * r for m, r, _, _ in masses))
    # Measured over the 10 draws: 1.2e-16, 1.0e-16 and 1.6e-16 of sum m R.
    for plane, ref in ((plane_1, ref_1), (plane_2, ref_2)):
        assert abs(complex(*plane.vector) - complex(ref)) < 1e-15 * size
        assert plane.correction_mass * plane.correction_radius == pytest.approx(
            float(abs(ref)), abs=1e-15 * size)
        correction = plane.correction_mass * plane.correction_radius * complex(
            math.cos(plane.correction_angle), math.sin(plane.correction_angle))
        assert abs(correction + complex(ref)) < 1e-15 * size     # U_corr = -U_plane


def test_no_correction_mass_without_a_correction_radius():
    """
    Point masses all on the axis: no radius to put a correction at, so no correction mass.

    The layout's default correction radius is then 0 (no component off the axis, no shape):
    each plane still has its unbalance (here 0) and angle, its correction mass is None, not
    a division by zero; a radius given by hand gives the mass U / r.
    """
    model = points([(5.0, 0.0, 0.0, -0.1), (7.0, 0.0, 1.0, 0.2)])
    assert model.layout.correction_radius() == 0.0
    for plane in plane_unbalances(model, -0.3, 0.3, model.layout.correction_radius()):
        assert plane.amount == 0.0 and plane.correction_mass is None
    off_axis = points([(5.0, 0.0, 0.0, -0.1), (0.02, 0.5, 1.0, 0.3)])
    plane_1, plane_2 = plane_unbalances(off_axis, -0.3, 0.3, 0.25)
    assert plane_2.correction_mass == pytest.approx(0.02 * 0.5 * 0.6 / 0.6 / 0.25, rel=1e-15)
    assert plane_1.correction_mass == 0.0


def test_static_and_couple_unbalance_of_a_pure_couple():
    """Equal and opposite m r at z = -d and +d: no static; couple 2 m r d at the +z angle."""
    m, r, d, angle = 2.0, 0.5, 0.15, 0.7
    model = points([(m, r, angle + math.pi, -d), (m, r, angle, d)])
    assert math.hypot(*static_unbalance(model)) < 1e-15           # measured 1.0e-16 kg m
    amount = math.hypot(*couple_unbalance(model))
    assert amount == pytest.approx(2 * m * r * d, rel=1e-15)      # measured: equal
    assert math.atan2(*couple_unbalance(model)[::-1]) == pytest.approx(angle, rel=1e-15)


def test_couple_unbalance_is_taken_about_the_centre_of_mass():
    """A static unbalance alone, off the z = 0 plane, has no couple about the centre of mass."""
    model = points([(3.0, 0.4, 1.0, 0.3), (50.0, 0.0, 0.0, 0.3)])
    assert math.hypot(*couple_unbalance(model)) < 1e-16           # measured 2.8e-17 kg m^2
    assert math.hypot(*static_unbalance(model)) == pytest.approx(1.2, rel=1e-15)


@pytest.mark.parametrize('grade, kg_mm, force', [(6.3, 250.7, 158.0), (2.5, 99.5, 63.0),
                                                 (1.0, 39.8, 25.0), (0.4, 15.9, 10.0)])
def test_iso_21940_worked_example_1000_kg_at_240_rpm(grade, kg_mm, force):
    omega = 240 * 2 * math.pi / 60
    u_per = iso21940.permissible_unbalance(grade, 1000.0, omega)
    assert u_per * 1e3 == pytest.approx(kg_mm, abs=0.05)          # kg mm, 4 figures
    assert u_per * omega**2 == pytest.approx(force, abs=0.5)       # N = m G Omega
    assert u_per * 1e6 == pytest.approx(9549 * grade * 1000.0 / 240, rel=1e-4)  # g mm


def test_plane_allocation_for_a_rotor_between_bearings():
    # Measured: equal to the last bit.
    assert iso21940.plane_shares(0.0, -0.5, 0.5) == pytest.approx((0.5, 0.5), rel=1e-15)
    assert iso21940.plane_shares(-0.1, -0.5, 0.5) == pytest.approx((0.6, 0.4), rel=1e-15)
    clamped = iso21940.plane_shares(-0.45, -0.5, 0.5)
    assert clamped == pytest.approx((0.7, 0.3), rel=1e-15)


def test_equivalent_and_finest_grade():
    mass, omega = 1000.0, 25.0
    u_per = iso21940.permissible_unbalance(2.5, mass, omega)
    shares = (0.5, 0.5)
    exact = iso21940.equivalent_grade([0.5 * u_per, 0.25 * u_per], shares, mass, omega)
    assert exact == pytest.approx(2.5, rel=1e-14)
    assert iso21940.finest_grade_met(exact) == 2.5
    assert iso21940.finest_grade_met(2.6) == 6.3
    assert iso21940.finest_grade_met(5000.0) is None


def test_gantry_assessment_against_a_per_component_reference():
    layout = load_layout(GANTRY)
    assessment = assess_balance(RotorModel.from_layout(layout))
    masses = []
    for c in layout.components:
        masses.append((c.mass, c.radius, c.angle, c.z))
    z_i, z_ii = layout.balancing.planes
    refs = two_plane_reference(masses, z_i, z_ii)   # shapes here have no own products
    for plane, ref in zip(assessment.planes, refs):         # measured 8.9e-16 apart
        assert plane.amount == pytest.approx(float(abs(ref)), rel=1e-14)
    mass = sum(m for m, *_ in masses)
    z_com = sum(m * z for m, _, _, z in masses) / mass
    b = z_ii - z_i
    shares = [min(max(s, 0.3), 0.7) for s in ((z_ii - z_com) / b, (z_com - z_i) / b)]
    u_per = layout.balancing.grade * mass / layout.balancing.service_speed * 1e-3
    expected = max(float(abs(r)) / (u_per * s) for r, s in zip(refs, shares)) \
        * layout.balancing.grade
    assert assessment.equivalent_grade == pytest.approx(expected, rel=1e-14)
    assert assessment.within_grade == (expected <= layout.balancing.grade)


def rotor_with_a_bolt(**balancing):
    """Make a 100 kg drum on the axis with a 10 g bolt at 0.5 m, z = 0, planes at -/+0.4 m."""
    return RotorModel.from_layout(parse_layout({
        'name': 'drum_and_bolt', 'supports': [{'name': 'a', 'z': -0.4},
                                              {'name': 'b', 'z': 0.4, 'axial': True}],
        'components': [{'name': 'drum', 'mass': 100.0, 'radius': 0.0, 'angle': 0.0},
                       {'name': 'bolt', 'mass': 0.01, 'radius': 0.5, 'angle': 0.0}],
        'balancing': {'planes': [-0.4, 0.4], **balancing}}))


def bolt_grade(omega):
    """
    Return the drum and bolt's achieved grade at ``omega`` by hand (ISO 21940-11), mm/s.

    U = 0.005 kg m, half in each plane; the centre of mass midway, so each plane's share of
    U_per = G m / omega is 0.5: G = (0.0025 / 0.5) omega / m, in mm/s.
    """
    return 0.0025 / 0.5 * omega / 100.01 * 1e3


def test_the_verdict_is_judged_at_the_service_speed_whatever_the_rotor_does():
    """
    The service speed judges; the speed seen never does then (ISO 21940-11).

    G 1.163 at 23.27 rad/s: within G 6.3 (OK), within G 1.3 but beyond 0.8 of it (WARN),
    out of G 1.0 (ERROR); the text as people read it.
    """
    model = rotor_with_a_bolt(service_speed=23.27, grade=6.3)
    for top_speed in (0.0, 5.0, -50.0, 1e3):
        assert judging_speed(model.layout, top_speed) == (23.27, 'service speed')
        verdict = judge_balance(model, top_speed)
        assert (verdict.level, verdict.grade, verdict.speed_source, verdict.warn_fraction) == \
            ('OK', 6.3, 'service speed', 0.8)
        assert verdict.assessment.omega == 23.27
        assert verdict.assessment.equivalent_grade == pytest.approx(bolt_grade(23.27),
                                                                    rel=1e-14)
    assert judge_balance(model, grade=1.3).level == 'WARN'
    error = judge_balance(model, grade=1.0)
    assert (error.level, error.grade) == ('ERROR', 1.0)
    assert error.text == f'G {bolt_grade(23.27):.3g} at the service speed 23.27 rad/s: ' \
        'OUT OF G 1'
    near = judge_balance(model, warn_fraction=0.1)
    assert (near.level, near.warn_fraction) == ('WARN', 0.1)          # 1.16 > 0.63
    assert error.assessment.grade == 1.0                  # judged against the grade asked
    assert error.assessment.permissible == pytest.approx(1e-3 * 100.01 / 23.27,
                                                         rel=1e-15)
    slow = rotor_with_a_bolt(service_speed=0.5)
    assert judging_speed(slow.layout, 30.0) == (0.5, 'service speed')


def test_without_a_service_speed_the_top_speed_seen_judges():
    """|top speed| judges when the layout names no service speed; nothing seen: not judged."""
    model = rotor_with_a_bolt(grade=1.0)
    assert judging_speed(model.layout, -40.0) == (40.0, 'top speed seen')
    assert judging_speed(model.layout, 0.5) == (0.5, 'top speed seen')
    assert judging_speed(model.layout, 0.0) == judging_speed(model.layout) == (None, None)
    assert judge_balance(model).level == 'NOT JUDGED'      # no speed seen by default
    verdict = judge_balance(model, -40.0)
    assert (verdict.level, verdict.speed_source) == ('ERROR', 'top speed seen')
    assert verdict.assessment.omega == 40.0
    assert verdict.assessment.equivalent_grade == pytest.approx(bolt_grade(40.0), rel=1e-14)
    assert judge_balance(model, 4.0).level == 'OK'          # G 0.2 at 4 rad/s
    unjudged = judge_balance(model, 0.0, warn_fraction=0.7)
    assert (unjudged.level, unjudged.grade, unjudged.assessment, unjudged.speed_source,
            unjudged.warn_fraction) == ('NOT JUDGED', 1.0, None, None, 0.7)
    assert unjudged.words == 'NOT JUDGED'
    assert unjudged.text == ('balance grade not judged: the layout names no service speed '
                             '(balancing.service_speed) and the rotor has not turned')


def test_a_grade_met_exactly_is_within_it():
    """
    Achieved == grade is within (ERROR only beyond); achieved == warn_fraction x grade is OK.

    The grade is the rotor's own achieved grade, so the comparison is exact; 0.5 x 2 G is
    exact in binary.
    """
    model = rotor_with_a_bolt(service_speed=23.27)
    achieved = judge_balance(model).assessment.equivalent_grade
    exactly = judge_balance(model, grade=achieved)
    assert exactly.level == 'WARN' and exactly.words == f'WITHIN G {achieved:g}, NEAR ITS LIMIT'
    assert judge_balance(model, grade=2 * achieved, warn_fraction=0.5).level == 'OK'
    assert judge_balance(model, grade=achieved * (1 - 1e-15)).level == 'ERROR'
