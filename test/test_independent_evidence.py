"""
The verdict of record by hand, from plane estimates given directly (no bag, no fit).

The gantry of config/ct_gantry.yaml, declared within G 6.3; the measurement a
:class:`~cvc_balance.identify.evidence.PlaneEstimate` (what vibration readings through
coefficients give): the declared planes by hand (ISO 21940-2's lever rule of point masses,
test/reference.py) plus 0.9 kg at 0.6 m, 300 deg in plane II (z 0.12 m), its errors'
covariance chosen here. Every figure people read is worked out here: the shares
(ISO 21940-11), the grades, the 95 % radii sqrt(chi2_2(0.95) a^H C a), the residual, the
words of each reason.
"""

import cmath
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from cvc_balance.identify import evidence
from cvc_balance.identify.evidence import (Disagreement, PlaneEstimate, verdict_of_record,
                                           worst)
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from reference import planes_by_hand, shares_by_hand

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
MODEL = RotorModel.from_layout(parse_layout(GANTRY))
DECLARED, SHARES = planes_by_hand(GANTRY), shares_by_hand(GANTRY)
EXTRA = 0.9 * 0.6 * cmath.exp(1j * math.radians(300.0))       # kg m, all in plane II
CHI2 = 5.991464547107979
SENSORS = 'the vibration sensors through coefficients c.yaml'


def grade_by_hand(planes):
    return 6.3 * max(abs(u) / s for u, s in zip(planes, SHARES))


def estimate(values, variance=1e-8, by=SENSORS, **options):
    return PlaneEstimate((-0.12, 0.12), tuple(values), ((variance, 0.0), (0.0, variance)), by,
                         **options)


def test_a_plane_estimate_reads_as_a_fit_does_by_hand():
    """S = u_I + u_II, P = z_I u_I + z_II u_II; the 95 % radius of w_S S + w_P P."""
    u = (0.3 - 0.1j, -0.2 + 0.5j)
    covariance = ((4e-6, 1e-6 + 2e-6j), (1e-6 - 2e-6j, 9e-6))
    e = PlaneEstimate((-0.2, 0.3), u, covariance, 'x')
    assert e.static == u[0] + u[1]
    assert abs(e.products - (-0.2 * u[0] + 0.3 * u[1])) < 1e-16
    for weights in ((1.0, 0.0), (0.0, 1.0), (0.6, -2.0), (0.3 + 0.4j, 1j)):
        a = np.array([weights[0] + z * weights[1] for z in (-0.2, 0.3)])
        variance = (a @ np.array(covariance) @ a.conj()).real
        assert e.ci95(weights) == pytest.approx(math.sqrt(CHI2 * variance), rel=1e-14)
    assert PlaneEstimate((0, 1), u, ((-1.0, 0), (0, -1.0)), 'x').ci95((1.0, 0.0)) == 0.0
    assert (e.coefficients, e.readings, e.identifiable) == (None, 0, True)


def test_a_rotor_not_what_its_layout_says_measured_by_the_sensors():
    """
    Say that the rotor is not what its layout says, measured by the sensors.

    The measured rotor's grade, the plane II residual beyond its radius and half its share,
    level ERROR (out of grade), the unlisted mass found where it is: every word by hand.
    """
    measured = [DECLARED[0], DECLARED[1] + EXTRA]
    verdict = verdict_of_record(MODEL, estimate(measured, coefficients={'file': 'c.yaml'},
                                                readings=400))
    grade, declared_grade = grade_by_hand(measured), grade_by_hand(DECLARED)
    assert (verdict.level, verdict.source, verdict.reason) == ('ERROR', 'measured', None)
    assert verdict.equivalent_grade == pytest.approx(grade, rel=1e-12)
    assert verdict.words == 'OUT OF G 6.3' and verdict.verdict is verdict.measured
    ci95 = math.sqrt(CHI2 * 1e-8)
    (plane,) = verdict.disagreements
    assert (plane.plane, plane.z) == ('II', 0.12)
    assert plane.permissible == pytest.approx(SHARES[1], rel=1e-12)
    assert abs(plane.residual - EXTRA) < 1e-13 and plane.ci95 == pytest.approx(ci95, rel=1e-12)
    assert plane.fraction == pytest.approx(0.54 / SHARES[1], rel=1e-12)
    share = f'{SHARES[1] * 1e6:.0f}'
    explanation = ('as if an unlisted 794 g at the correction radius 0.68 m were at 300 deg, '
                   'z 0.120 m (or a part there heavier than the layout says)')
    assert f'{0.54 / 0.68 * 1e3:.0f}' == '794' and share == '151657'
    assert verdict.explanation == explanation
    statement = f'{verdict.measured.text} (measured by {SENSORS})'
    assert verdict.measured.text.startswith(f'G {grade:.1f} at the service speed 23.27 rad/s')
    assert verdict.statement == statement and verdict.headline == f'ERROR: {statement}'
    assert verdict.text == (f'{statement}; the rotor is not what its layout says: plane II '
                            '+540000 g mm at 300.0 deg')
    said = (f'the rotor is not what its layout says: plane II +540000 g mm at 300.0 deg (95 % '
            f'radius 245 g mm; {0.54 / SHARES[1]:.2f} of its permissible {share} g mm); '
            f'{explanation}')
    assert verdict.disagreement_text == said
    assert verdict.layout_text == f'the layout expects OK: {verdict.layout.text}'
    assert verdict.layout.text.startswith(f'G {declared_grade:.1f} at the service speed')
    record = verdict.record()
    assert record.pop('equivalent_grade') == pytest.approx(grade, rel=1e-12)
    assert record.pop('measured_equivalent_grade') == pytest.approx(grade, rel=1e-12)
    assert record.pop('layout_equivalent_grade') == pytest.approx(declared_grade, rel=1e-12)
    (row,) = record.pop('disagreements')
    assert row == {'plane': 'II', 'z': 0.12, 'g_mm': pytest.approx(540000.0, rel=1e-12),
                   'angle_deg': pytest.approx(300.0, rel=1e-12),
                   'ci95_g_mm': pytest.approx(ci95 * 1e6, rel=1e-12),
                   'permissible_g_mm': pytest.approx(SHARES[1] * 1e6, rel=1e-12),
                   'fraction': pytest.approx(0.54 / SHARES[1], rel=1e-12)}
    assert record == {
        'level': 'ERROR', 'verdict': 'OUT OF G 6.3', 'finest_grade_met': 40.0,
        'within_grade': False, 'source': 'measured', 'source_text': f'measured by {SENSORS}',
        'headline': f'ERROR: {statement}', 'layout_expects': verdict.layout_text,
        'disagreement': said, 'layout_level': 'OK', 'layout_verdict': 'WITHIN G 6.3',
        'measured_level': 'ERROR', 'reason': None, 'explanation': explanation,
        'measured_by': SENSORS, 'coefficients': {'file': 'c.yaml'}}


def test_a_rotor_as_declared_agrees_and_is_measured():
    """The declared planes measured: OK, no disagreement, nothing to explain."""
    verdict = verdict_of_record(MODEL, estimate(DECLARED, by=evidence.LOAD_CELLS))
    assert (verdict.level, verdict.source, verdict.disagreements) == ('OK', 'measured', ())
    assert verdict.explanation is None and verdict.disagreement_text == ''
    assert verdict.text == verdict.statement == \
        f'{verdict.measured.text} (measured by the load cells)'
    assert verdict.record()['disagreement'] is None
    assert verdict.equivalent_grade == pytest.approx(grade_by_hand(DECLARED), rel=1e-12)


def test_when_the_layouts_verdict_stands_each_reason_in_its_words():
    """No measurement, no readings, readings that cannot tell, no speed, too wide."""
    none = verdict_of_record(MODEL)
    assert (none.level, none.source, none.reason, none.measured) == \
        ('OK', 'layout', 'no load cells', None)
    assert none.verdict is none.layout and none.source_text == 'from the layout: no load cells'
    record = none.record()
    assert (record['measured_level'], record['measured_equivalent_grade'],
            record['measured_by'], record['coefficients']) == (None, None, None, None)
    assert record['equivalent_grade'] == pytest.approx(grade_by_hand(DECLARED), rel=1e-12)
    named = verdict_of_record(MODEL, no_measurement='no coefficients for this machine',
                              coefficients={'file': 'x.yaml'})
    assert (named.reason, named.coefficients) == ('no coefficients for this machine',
                                                  {'file': 'x.yaml'})
    empty = verdict_of_record(MODEL, estimate(DECLARED, identifiable=False, readings=0))
    assert (empty.level, empty.source, empty.reason, empty.measured_by) == (
        'OK', 'layout', 'no load-cell readings while this layout was in force', SENSORS)
    few = verdict_of_record(MODEL, estimate(DECLARED, identifiable=False, readings=5))
    assert few.reason == (f'{SENSORS} cannot tell yet: too few readings or revolutions, or '
                          'no speed')
    assert few.record()['measured_by'] is None
    cells = verdict_of_record(MODEL, estimate(DECLARED, by=evidence.LOAD_CELLS,
                                              identifiable=False, readings=5))
    assert cells.reason == evidence.CANNOT_TELL
    # Too wide: plane I's radius over a quarter of its share (plane II's too: the first).
    variance = (0.3 * SHARES[0]) ** 2 / CHI2
    for by, said in ((SENSORS, f'the 95 % interval of {SENSORS}'),
                     (evidence.LOAD_CELLS, "the load cells' 95 % interval")):
        wide = verdict_of_record(MODEL, estimate(DECLARED, variance, by=by))
        assert (wide.source, wide.level, wide.measured.level) == ('layout', 'OK', 'OK')
        assert wide.measured_by == by and wide.layout.level == 'OK'
        assert wide.reason == (f'{said} is too wide yet (plane I: '
                               f'{0.3 * SHARES[0] * 1e6:.0f} g mm against its permissible '
                               f'{SHARES[0] * 1e6:.0f} g mm)')
    # Just inside a quarter of each share: measured.
    inside = (0.249 * min(SHARES)) ** 2 / CHI2
    assert verdict_of_record(MODEL, estimate(DECLARED, inside)).source == 'measured'
    # No service speed and the rotor has not turned: neither can tell.
    still = dict(GANTRY, balancing={k: v for k, v in GANTRY['balancing'].items()
                                    if k != 'service_speed'})
    model = RotorModel.from_layout(parse_layout(still))
    stopped = verdict_of_record(model, estimate(DECLARED))
    assert (stopped.level, stopped.source, stopped.reason, stopped.measured_by) == (
        'NOT JUDGED', 'layout', 'no service speed and the rotor has not turned', SENSORS)
    assert stopped.equivalent_grade is None and stopped.measured is not None
    record = stopped.record()
    assert (record['finest_grade_met'], record['within_grade'],
            record['layout_equivalent_grade'], record['measured_equivalent_grade']) == \
        (None, None, None, None)
    turning = verdict_of_record(model, estimate(DECLARED), top_speed=23.27)
    assert turning.source == 'measured'
    assert turning.equivalent_grade == pytest.approx(grade_by_hand(DECLARED), rel=1e-12)


def test_a_residual_over_half_its_share_warns_an_ok_rotor_and_a_custom_share():
    """OK measured, residual 0.6 of plane II's share: WARN; residual_warn 0.7: OK."""
    turn = 1j * DECLARED[1] / abs(DECLARED[1])
    measured = [DECLARED[0], DECLARED[1] + 0.6 * SHARES[1] * turn]
    assert grade_by_hand(measured) < 0.8 * 6.3
    assert verdict_of_record(MODEL, estimate(measured)).level == 'WARN'
    calm = verdict_of_record(MODEL, estimate(measured), residual_warn=0.7)
    assert (calm.level, calm.disagreements) == ('OK', ())
    # A grade asked for (G 2.5): the same rotor out of it, measured.
    strict = verdict_of_record(MODEL, estimate(measured), grade=2.5)
    assert strict.level == 'ERROR' and strict.words == 'OUT OF G 2.5'
    # The layout judged at G 2.5 too: its 2.4995 within, over 0.8 of it: WARN.
    declared = grade_by_hand(DECLARED)
    assert 0.8 * 2.5 < declared <= 2.5
    assert (strict.layout.words, strict.layout.level) == ('WITHIN G 2.5, NEAR ITS LIMIT', 'WARN')
    warned = verdict_of_record(MODEL, estimate(measured), warn_fraction=0.3)
    assert 0.3 * 6.3 < declared < grade_by_hand(measured)
    assert (warned.measured.level, warned.layout.level) == ('WARN', 'WARN')


def test_a_disagreement_said_for_people_by_hand():
    d = Disagreement('static', None, -0.002 - 0.002j, 0.0001, 0.004)
    assert d.fraction == pytest.approx(math.sqrt(8e-6) / 0.004, rel=1e-15)
    assert d.describe(brief=True) == 'static unbalance +2828 g mm at 225.0 deg'
    assert d.describe() == ('static unbalance +2828 g mm at 225.0 deg (95 % radius 100 g mm; '
                            '0.71 of its permissible 4000 g mm)')
    assert d.record() == {'plane': 'static', 'z': None,
                          'g_mm': pytest.approx(2828.42712474619, rel=1e-14),
                          'angle_deg': 225.0, 'ci95_g_mm': pytest.approx(100.0, rel=1e-14),
                          'permissible_g_mm': 4000.0, 'fraction': d.fraction}
    assert evidence.disagreement_text(()) == ''
    assert evidence.disagreement_text((d,)) == \
        f'the rotor is not what its layout says: {d.describe()}'
    # Exactly half the share (0.5 x 0.08 = 0.04 to the bit): no disagreement.
    assert evidence.disagreeing([('I', -0.12, 0.04, 0.01, 0.08)]) == ()
    assert evidence.disagreeing([('I', -0.12, 0.04 + 1e-12, 0.01, 0.08)])[0].z == -0.12
    assert evidence.disagreement_text((d, d), 'why') == (
        f'the rotor is not what its layout says: {d.describe()}, {d.describe()}; why')


def test_the_worst_level():
    assert worst(['OK', 'NOT JUDGED']) == 'OK'
    assert worst(['WARN', 'ERROR', 'OK']) == 'ERROR'
    assert worst(['NOT JUDGED', 'WARN']) == 'WARN'
    assert worst(['NOT JUDGED']) == 'NOT JUDGED'


def residual_of(planes):
    """Return the residual of measured planes against the layout (identify.estimate's)."""
    from cvc_balance.identify.estimate import identified_unbalance, layout_unbalance, residual
    return residual(identified_unbalance(MODEL, estimate(planes)), layout_unbalance(MODEL))


def test_explanations_by_hand_each_candidate():
    """
    Explain each kind of candidate by hand.

    A part heavier by a factor, missing, turned round; an unlisted mass between the planes;
    nothing (no residual, or one no candidate explains within a quarter): each by hand.
    """
    def split(mass, radius, degrees, z):
        u = mass * radius * cmath.exp(1j * math.radians(degrees))
        return [u * (0.12 - z) / 0.24, u * (z + 0.12) / 0.24]

    def plus(*changes):
        return [DECLARED[k] + sum(c[k] for c in changes) for k in (0, 1)]
    cooling = ('tube_cooling', 45.0, 0.55, 300.0, 0.06)     # config/ct_gantry.yaml
    heavier = split(3.0, 0.55, 300.0, 0.06)
    assert evidence.explain(MODEL, residual_of(plus(heavier))) == \
        'as if tube_cooling were +3 kg heavier (its 45 kg at 0.55 m, 300 deg)'
    lighter = split(-1.5, 0.55, 300.0, 0.06)
    assert evidence.explain(MODEL, residual_of(plus(lighter))) == \
        'as if tube_cooling were -1.5 kg lighter (its 45 kg at 0.55 m, 300 deg)'
    missing = split(-cooling[1], 0.55, 300.0, 0.06)
    assert evidence.explain(MODEL, residual_of(plus(missing))) == \
        'as if tube_cooling were missing'
    turned = [a - b for a, b in zip(split(45.0, 0.55, 330.0, 0.06), split(45.0, 0.55, 300.0,
                                                                          0.06))]
    assert evidence.explain(MODEL, residual_of(plus(turned))) == \
        'as if tube_cooling had moved +30 deg round the axis'
    unlisted = split(0.2, 0.68, 45.0, -0.03)
    assert evidence.explain(MODEL, residual_of(plus(unlisted))) == (
        'as if an unlisted 200 g at the correction radius 0.68 m were at 45 deg, z -0.030 m '
        '(or a part there heavier than the layout says)')
    # Nothing to explain: no residual, or one not finite.
    from types import SimpleNamespace as Plane

    def diff(*values):
        return Plane(planes=[(z, Plane(value=v, ci95=0.0))
                             for z, v in zip((-0.12, 0.12), values)])
    assert evidence.explain(MODEL, diff(0j, 0j)) is None
    assert evidence.explain(MODEL, diff(complex(math.nan, 0.0), 1e-3)) is None
    assert evidence.explain(MODEL, diff(complex(0.0, math.inf), 1e-3)) is None


# -- explain's thresholds on a bench rotor where every candidate is worked out by hand -------

def bench(extra=0, planes=True, radius=1.0, parts=True):
    """
    Return a bench rotor whose candidates are worked out by hand.

    A hub on the axis (no moment: never a candidate) and part A, 1 kg at 0.5 m, 0 deg, z 0.5
    m: with planes at -+0.5 m its plane vectors are e = (0, 0.5) kg m. ``extra`` tiny parts
    on the axis; no planes: one support; ``radius`` the correction radius (None: none).
    """
    parts_ = [{'name': 'hub', 'mass': 10.0, 'radius': 0.0, 'angle_deg': 0.0, 'z': 0.0}]
    if parts:
        parts_.append({'name': 'A', 'mass': 1.0, 'radius': 0.5, 'angle_deg': 0.0, 'z': 0.5})
    parts_ += [{'name': f'p{k}', 'mass': 0.001, 'radius': 0.0, 'angle_deg': 0.0, 'z': 0.0}
               for k in range(extra)]
    balancing = {'grade': 6.3, 'service_speed': 10.0}
    if radius:
        balancing['correction_radius'] = radius
    if planes:
        balancing['planes'] = [-0.5, 0.5]
        supports = [{'name': 'left', 'z': -0.5}, {'name': 'right', 'z': 0.5, 'axial': True}]
    else:
        supports = [{'name': 'only', 'z': 0.0, 'axial': True}]
    return RotorModel.from_layout(parse_layout({
        'name': 'bench', 'components': parts_, 'supports': supports,
        'gravity': [0.0, -9.8, 0.0], 'balancing': balancing}))


def residual_vectors(v_i, v_ii, ci95=0.0):
    from types import SimpleNamespace as Plane
    return Plane(planes=[(-0.5, Plane(value=v_i, ci95=ci95)),
                         (0.5, Plane(value=v_ii, ci95=ci95))])


HEAVIER = 'as if A were +2 kg heavier (its 1 kg at 0.5 m, 0 deg)'


def test_an_explanation_within_a_quarter_of_the_residual_or_its_radius_by_hand():
    """
    Explain within a quarter of the residual or within its radius, not beyond.

    Residual (a i, 1): A heavier by the real projection 2 Re(v_II) (left |a|), an unlisted
    mass leaving sqrt 2 |m| |Im(v_II / m)|, m = 1 + a i (more). Offered when |a| <= a
    quarter of sqrt(a^2 + 1) (a = 0.255: 0.2580; a = 0.27: 0.2589 < 0.27), or within the
    residual's radius sqrt(2) c (c = 0.195: 0.2758; 0.1: 0.1414; inf: not told, 0).
    """
    model = bench()
    for a in (0.255, 0.27):
        unlisted = math.sqrt(2) * abs(1 + a * 1j) * abs((1 / (1 + a * 1j)).imag)
        assert unlisted > 0.25 * math.sqrt(a * a + 1)
    assert 0.255 <= 0.25 * math.sqrt(0.255 ** 2 + 1) and 0.27 > 0.25 * math.sqrt(0.27 ** 2 + 1)
    assert evidence.explain(model, residual_vectors(0.255j, 1.0)) == HEAVIER
    assert evidence.explain(model, residual_vectors(0.27j, 1.0)) is None
    assert evidence.explain(model, residual_vectors(0.27j, 1.0, 0.195)) == HEAVIER
    assert evidence.explain(model, residual_vectors(0.27j, 1.0, 0.1)) is None
    assert evidence.explain(model, residual_vectors(0.27j, 1.0, math.inf)) is None


def test_a_listed_part_only_when_it_fits_as_well_to_1e_9_of_the_residual():
    """
    Prefer a listed part only when it fits as well, to 1e-9 of the residual.

    Residual (1e-6, 1e-5) kg m: an unlisted mass fits exactly (both planes at 0 deg), A
    heavier leaves 1e-6, a tenth of it: the unlisted mass, 0.011 g at 1 m, z 0.409 m.
    Residual (0, -0.45): A's scale exactly -0.9 (not offered: more than 90 % lighter),
    missing leaves 0.05; the unlisted mass fits exactly.
    """
    model = bench()
    assert evidence.explain(model, residual_vectors(1e-6, 1e-5)) == (
        'as if an unlisted 0 g at the correction radius 1 m were at 0 deg, z 0.409 m (or a '
        'part there heavier than the layout says)')
    assert -0.5 + 1e-5 / 1.1e-5 == pytest.approx(0.409, abs=5e-4)
    assert (0.5 * -0.45) / 0.5 ** 2 == -0.9
    assert evidence.explain(model, residual_vectors(0j, -0.45)) == (
        'as if an unlisted 450 g at the correction radius 1 m were at 180 deg, z 0.500 m (or '
        'a part there heavier than the layout says)')


def test_explanations_of_a_static_residual_and_without_a_correction_radius():
    """
    Explain a static residual, and without a correction radius in g mm.

    One support, no planes: the static residual 0.2 i kg m; A (moment 0.5) heavier leaves
    0.2, turned round leaves 0.04, an unlisted 200 g at 1 m, 90 deg fits exactly.
    Every part on the axis and no correction radius: the unlisted mass in g mm.
    """
    from types import SimpleNamespace as Static
    model = bench(planes=False)
    assert model.layout.correction_planes() is None
    static = Static(planes=[], static=Static(value=0.2j, ci95=0.0))
    assert evidence.explain(model, static) == (
        'as if an unlisted 200 g at the correction radius 1 m were at 90 deg (or a part '
        'there heavier than the layout says)')
    axis = bench(radius=None, parts=False)
    assert axis.layout.correction_radius() == 0.0
    assert evidence.explain(axis, residual_vectors(0.001, 0.002)) == (
        'as if an unlisted 3000 g mm were at 0 deg, z 0.167 m (or a part there heavier than '
        'the layout says)')


def test_parts_searched_in_layouts_of_up_to_2000_components():
    """Residual (0, 0.25): A +0.5 kg heavier among 2000 parts; beyond, the unlisted mass."""
    assert evidence.MAX_CANDIDATES == 2000
    many = bench(extra=1998)
    assert len(many.layout.components) == 2000
    assert evidence.explain(many, residual_vectors(0j, 0.25)) == \
        'as if A were +0.5 kg heavier (its 1 kg at 0.5 m, 0 deg)'
    more = bench(extra=1999)
    assert evidence.explain(more, residual_vectors(0j, 0.25)) == (
        'as if an unlisted 250 g at the correction radius 1 m were at 0 deg, z 0.500 m (or a '
        'part there heavier than the layout says)')


def test_a_static_verdict_of_a_rotor_with_one_support_by_hand():
    """
    Judge a rotor on one support by its static unbalance, by hand.

    The bench rotor on one support (no planes): its static unbalance judged against
    U_per = G m / Omega = 6.3e-3 x 11 / 10 kg m. Measured 0.51 kg m where it lists 0.5:
    a static residual of 10000 g mm, beyond half of 6930; an interval of 3000 g mm (a
    radius sqrt(chi2 (v + v)) of u_I + u_II) is too wide.
    """
    model = bench(planes=False)
    per = 6.3e-3 * 11.0 / 10.0
    measured = PlaneEstimate((-0.5, 0.5), (0j, 0.51 + 0j), ((1e-10, 0.0), (0.0, 1e-10)),
                             SENSORS)
    verdict = verdict_of_record(model, measured)
    (static,) = verdict.disagreements
    assert (static.plane, static.z) == ('static', None)
    assert abs(static.residual - 0.01) < 1e-12
    assert static.permissible == pytest.approx(per, rel=1e-12)
    assert static.describe(brief=True) == 'static unbalance +10000 g mm at 0.0 deg'
    assert verdict.level == 'ERROR' and verdict.source == 'measured'
    assert verdict.equivalent_grade == pytest.approx(6.3 * 0.51 / per, rel=1e-9)
    v = (0.003 ** 2) / CHI2 / 2
    wide = verdict_of_record(model, PlaneEstimate((-0.5, 0.5), (0j, 0.51 + 0j),
                                                  ((v, 0.0), (0.0, v)), SENSORS))
    assert wide.reason == (f'the 95 % interval of {SENSORS} is too wide yet (static '
                           f'unbalance: 3000 g mm against its permissible {per * 1e6:.0f} g '
                           'mm)')
    assert f'{per * 1e6:.0f}' == '6930'


def test_an_unlisted_mass_of_exactly_1_kg_m_and_a_pure_couple():
    """
    Explain an unlisted mass of exactly 1 kg m; nothing for a pure couple.

    (0.4, 0.6) kg m: one mass of 1 kg m (to the bit) at z = -0.5 + 0.6 m fits exactly.
    A pure couple (0.1, -0.1): no single mass; A lighter leaves 0.1, over a quarter of
    0.141: nothing offered.
    """
    model = bench()
    assert 0.4 + 0.6 == 1.0
    assert evidence.explain(model, residual_vectors(0.4 + 0j, 0.6 + 0j)) == (
        'as if an unlisted 1000 g at the correction radius 1 m were at 0 deg, z 0.100 m (or '
        'a part there heavier than the layout says)')
    assert evidence.explain(model, residual_vectors(0.1 + 0j, -0.1 + 0j)) is None
