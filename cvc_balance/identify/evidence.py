"""
The verdict of record: what the machine's own evidence says, checked against its layout.

A monitor holds two views of a rotor: the declared layout (the model) and, when load cells
are read, the unbalance they measure; or, without cells, the unbalance per correction plane
that vibration sensors' 1x readings give through stored influence coefficients of the
machine type (:class:`PlaneEstimate`). The verdict people read first is the MEASURED
rotor's whenever the measurement can tell; the layout's verdict is shown beside it as what
the layout expects. While the measurement cannot tell (no cells, too few readings or
revolutions, no speed, its 95 % interval too wide against the limit) the layout's verdict
stands, labelled so. When the two disagree beyond the measurement's 95 % radius and
beyond ``residual_warn`` of a plane's permissible share, that is itself a WARN (ERROR
when the measured rotor is out of grade): "the rotor is not what its layout says", with the
residual and what would explain it (a part heavier or lighter, missing, moved round, or a
mass the layout does not list).

One definition for every surface: the node's ``/diagnostics``, ``replay``, ``identify``,
``play``'s summary, the rerun view, the field report and the fleet. Numpy-free arithmetic
on the identified estimate (:class:`cvc_balance.identify.fit.Estimate`); SI inside (kg m,
rad), g mm and degrees only in the text and the JSON record.
"""

from dataclasses import dataclass
import cmath
import math

from cvc_balance.identify.estimate import (identified_unbalance, layout_unbalance, residual,
                                           rotor_with)
from cvc_balance.physics import assessment
from cvc_balance.physics.frames import degrees, degrees_360, g_mm
from cvc_balance.physics.unbalance import two_plane_split

MEASURED, LAYOUT = 'measured', 'layout'
"""Where the verdict of record comes from."""
RESIDUAL_WARN = 0.5
"""Default: a plane's residual beyond this fraction of its permissible share (and beyond its
95 % radius) means the rotor is not what its layout says (the node's ``residual_warn``).
A bare significance test would flag every rotor whose layout is a few grams off; the
share keeps the alarm for differences that matter to the grade."""
MAX_INTERVAL = 0.25
"""The measurement can tell the verdict when each plane's 95 % radius is at most this
fraction of the plane's permissible share (else: its interval is too wide)."""
EXPLAINED = 0.25
"""An explanation is offered when it leaves at most this fraction of the residual (norm over
the planes) unexplained, or no more than the measurement's own 95 % radius."""
MAX_CANDIDATES = 2000
"""Layouts with more components than this are not searched part by part for an explanation."""
NO_CELLS = 'no load cells'
NO_READINGS = 'no load-cell readings while this layout was in force'
CANNOT_TELL = ('the load cells cannot tell yet: too few readings or revolutions, or no '
               'speed')
LEVEL_ORDER = {assessment.NOT_JUDGED: 0, assessment.OK: 1, assessment.WARN: 2,
               assessment.ERROR: 3}
LOAD_CELLS = 'the load cells'
"""What measured the rotor when an estimate does not say (a load cells' fit)."""
CHI2_2DOF_95 = 5.991464547107979
"""95 % quantile of chi-square with 2 degrees of freedom: a complex error's 95 % circle."""


@dataclass(frozen=True)
class PlaneEstimate:
    """
    A measured unbalance given per correction plane, not fitted from load cells.

    What vibration readings give through stored influence coefficients (readings = C u):
    ``values`` (u_I, u_II) complex kg m at the layout's correction planes ``z`` (m);
    ``covariance`` 2x2 (nested tuples) of their errors per x and y component, kg^2 m^2;
    ``measured_by`` names the instrument for people ('the vibration sensors through
    coefficients FILE'); ``coefficients`` the coefficients' record named (plain data) or
    None; ``readings`` how many samples the 1x readings used. Reads as the load cells'
    fit does (``static`` S, ``products`` P about O, ``ci95``), so one verdict serves both.
    """

    z: tuple
    values: tuple
    covariance: tuple
    measured_by: str
    coefficients: dict = None
    readings: int = 0
    identifiable: bool = True

    @property
    def static(self):
        """Return S = u_I + u_II, kg m."""
        return complex(self.values[0] + self.values[1])

    @property
    def products(self):
        """Return P about O = z_I u_I + z_II u_II, kg m^2 (the planes' moment)."""
        return complex(self.z[0] * self.values[0] + self.z[1] * self.values[1])

    def ci95(self, weights):
        """Radius of the 95 % circle of w_S S + w_P P (its units)."""
        w_s, w_p = weights
        a = [w_s + z * w_p for z in self.z]        # the same quantity in (u_I, u_II)
        variance = sum((a[i] * self.covariance[i][j] * a[j].conjugate()).real
                       for i in range(2) for j in range(2))
        return math.sqrt(CHI2_2DOF_95 * max(variance, 0.0))


@dataclass(frozen=True)
class Disagreement:
    """A plane (or, without planes, the static unbalance) where rotor and layout differ."""

    plane: str              # 'I', 'II' or 'static'
    z: float                # m (None for 'static')
    residual: complex       # measured - layout, kg m, rotor frame
    ci95: float             # its 95 % radius, kg m
    permissible: float      # the plane's permissible share, kg m

    @property
    def fraction(self):
        """Return the residual over the permissible share."""
        return abs(self.residual) / self.permissible

    def describe(self, brief=False):
        """
        Return one phrase for people, e.g. 'plane II +149160 g mm at 130.6 deg (...)'.

        ``brief``: without the 95 % radius and the share (a status line's length).
        """
        where = 'static unbalance' if self.plane == 'static' else f'plane {self.plane}'
        text = (f'{where} +{g_mm(abs(self.residual)):.0f} g mm at '
                f'{degrees_360(cmath.phase(self.residual)):.1f} deg')
        if brief:
            return text
        return (f'{text} (95 % radius {g_mm(self.ci95):.0f} g mm; {self.fraction:.2f} of its '
                f'permissible {g_mm(self.permissible):.0f} g mm)')

    def record(self):
        """Return it as JSON-able data (g mm, degrees 0..360)."""
        return {'plane': self.plane, 'z': self.z, 'g_mm': g_mm(abs(self.residual)),
                'angle_deg': degrees_360(cmath.phase(self.residual)),
                'ci95_g_mm': g_mm(self.ci95), 'permissible_g_mm': g_mm(self.permissible),
                'fraction': self.fraction}


@dataclass(frozen=True)
class VerdictOfRecord:
    """
    The verdict people read first, where it comes from, and the layout's beside it.

    ``layout``: the layout's :class:`~cvc_balance.physics.assessment.Verdict`;
    ``measured``: the measured rotor's (None without an identifiable measurement);
    ``source``: MEASURED when the measurement can tell, else LAYOUT; ``reason``: why the
    layout's verdict stands (None when measured); ``disagreements``: planes where the
    rotor is not what its layout says; ``explanation``: what would explain them (or None);
    ``measured_by``: what measured the rotor ('the load cells', or the vibration sensors
    through coefficients); ``coefficients``: the coefficients' record named (or None).
    """

    level: str
    source: str
    layout: object
    measured: object = None
    reason: str = None
    disagreements: tuple = ()
    explanation: str = None
    measured_by: str = LOAD_CELLS
    coefficients: dict = None

    @property
    def verdict(self):
        """Return the Verdict of the source (the measured rotor's or the layout's)."""
        return self.measured if self.source == MEASURED else self.layout

    @property
    def equivalent_grade(self):
        """Return the source's achieved grade (mm/s), None when not judged."""
        judged = self.verdict.assessment
        return None if judged is None else judged.equivalent_grade

    @property
    def words(self):
        """'OUT OF G 6.3', 'WITHIN G 6.3', ...: the source's words."""
        return self.verdict.words

    @property
    def source_text(self):
        """'measured by the load cells' (or what measured it) or 'from the layout: <why>'."""
        if self.source == MEASURED:
            return f'measured by {self.measured_by}'
        return f'from the layout: {self.reason}'

    @property
    def disagreement_text(self):
        """Return 'the rotor is not what its layout says: ...', or '' when they agree."""
        return disagreement_text(self.disagreements, self.explanation)

    @property
    def statement(self):
        """Return the verdict and its source: 'G 9.17 at ... OUT OF G 6.3 (measured by ...)'."""
        return f'{self.verdict.text} ({self.source_text})'

    @property
    def headline(self):
        """Return the headline: 'ERROR: G 9.17 at ... OUT OF G 6.3 (measured by the cells)'."""
        return f'{self.level}: {self.statement}'

    @property
    def text(self):
        """
        Return the statement and, when rotor and layout disagree, where (one line, no level).

        The short form a status line holds; :attr:`disagreement_text` has the radii, the
        shares and the explanation.
        """
        if self.disagreements:
            return (f'{self.statement}; the rotor is not what its layout says: '
                    + ', '.join(d.describe(brief=True) for d in self.disagreements))
        return self.statement

    @property
    def layout_text(self):
        """Return what the layout expects: 'the layout expects OK: G 2.5 at ... WITHIN G 6.3'."""
        return f'the layout expects {self.layout.level}: {self.layout.text}'

    def record(self):
        """
        Return it as JSON-able data: one ``verdict`` object per segment.

        Keys: level, verdict, equivalent_grade, finest_grade_met, within_grade, source,
        source_text, headline,
        layout_expects, disagreement (text), layout_level,
        layout_verdict, layout_equivalent_grade, measured_level, measured_equivalent_grade,
        reason, disagreements, explanation, measured_by, coefficients. None (null) where
        nothing was computed.
        """
        layout, measured = self.layout, self.measured
        judged = self.verdict.assessment
        return {
            'level': self.level, 'verdict': self.words,
            'equivalent_grade': self.equivalent_grade,
            'finest_grade_met': None if judged is None else judged.finest_grade_met,
            'within_grade': None if judged is None else judged.within_grade,
            'source': self.source,
            'source_text': self.source_text, 'headline': self.headline,
            'layout_expects': self.layout_text, 'disagreement': self.disagreement_text or None,
            'layout_level': layout.level, 'layout_verdict': layout.words,
            'layout_equivalent_grade': _grade_of(layout),
            'measured_level': None if measured is None else measured.level,
            'measured_equivalent_grade': None if measured is None else _grade_of(measured),
            'reason': self.reason,
            'disagreements': [d.record() for d in self.disagreements],
            'explanation': self.explanation,
            'measured_by': self.measured_by if self.measured is not None else None,
            'coefficients': self.coefficients,
        }


def _grade_of(verdict):
    return None if verdict.assessment is None else verdict.assessment.equivalent_grade


def verdict_of_record(model, estimate=None, top_speed=0.0, grade=None,
                      warn_fraction=assessment.WARN_FRACTION, residual_warn=RESIDUAL_WARN,
                      no_measurement=NO_CELLS, coefficients=None):
    """
    Return the :class:`VerdictOfRecord` of ``model`` (the layout's RotorModel).

    ``estimate``: the load cells' fit (:class:`cvc_balance.identify.fit.Estimate`) or a
    :class:`PlaneEstimate` (vibration readings through coefficients), None when there is
    no measurement: then ``no_measurement`` says why the layout's verdict stands (and
    ``coefficients`` names the record that could not be used); ``top_speed`` rad/s,
    ``grade`` mm/s and ``warn_fraction`` as
    :func:`cvc_balance.physics.assessment.judge_balance`.
    """
    grade = grade or model.layout.balancing.grade
    layout = assessment.judge_balance(model, top_speed, grade, warn_fraction)
    if estimate is None:
        return VerdictOfRecord(layout.level, LAYOUT, layout, reason=no_measurement,
                               coefficients=coefficients)
    by = getattr(estimate, 'measured_by', LOAD_CELLS)
    named = dict(measured_by=by, coefficients=getattr(estimate, 'coefficients', None))
    if not estimate.identifiable:
        return VerdictOfRecord(layout.level, LAYOUT, layout, **named,
                               reason=NO_READINGS if not estimate.readings
                               else CANNOT_TELL.replace(LOAD_CELLS, by))
    measured = assessment.judge_balance(rotor_with(model, estimate.static, estimate.products),
                                        top_speed, grade, warn_fraction)
    judged = measured.assessment
    if judged is None:          # no speed to judge at: neither can tell
        return VerdictOfRecord(layout.level, LAYOUT, layout, measured, **named,
                               reason='no service speed and the rotor has not turned')
    found = identified_unbalance(model, estimate)
    diff = residual(found, layout_unbalance(model))
    limits = _limits(found, diff, judged)
    too_wide = [(label, ci, allowed) for label, _, _, ci, allowed in limits
                if not ci <= MAX_INTERVAL * allowed]
    if too_wide:
        label, ci, allowed = too_wide[0]
        where = 'static unbalance' if label == 'static' else f'plane {label}'
        interval = "the load cells' 95 % interval" if by == LOAD_CELLS \
            else f'the 95 % interval of {by}'
        reason = (f"{interval} is too wide yet ({where}: "
                  f'{g_mm(ci):.0f} g mm against its permissible {g_mm(allowed):.0f} g mm)')
        return VerdictOfRecord(layout.level, LAYOUT, layout, measured, reason=reason, **named)
    disagreements = disagreeing(limits, residual_warn)
    level = measured.level
    if disagreements and LEVEL_ORDER[level] < LEVEL_ORDER[assessment.WARN]:
        level = assessment.WARN
    explanation = explain(model, diff) if disagreements else None
    return VerdictOfRecord(level, MEASURED, layout, measured, None, disagreements,
                           explanation, **named)


def disagreeing(rows, residual_warn=RESIDUAL_WARN):
    """
    Return the :class:`Disagreement` of each row where rotor and layout differ (the rule).

    ``rows``: (plane label, z m, residual complex kg m, its 95 % radius kg m, permissible
    share kg m). A residual differs when it is beyond its 95 % radius AND beyond
    ``residual_warn`` of the share (see :data:`RESIDUAL_WARN`).
    """
    return tuple(Disagreement(label, z, value, ci, allowed)
                 for label, z, value, ci, allowed in rows
                 if abs(value) > ci and abs(value) > residual_warn * allowed)


def disagreement_text(disagreements, explanation=None):
    """Return 'the rotor is not what its layout says: ...' ('' for none), one line."""
    if not disagreements:
        return ''
    text = 'the rotor is not what its layout says: ' + ', '.join(
        d.describe() for d in disagreements)
    return text + (f'; {explanation}' if explanation else '')


def _limits(found, diff, judged):
    """[(label, z, residual, 95 % radius, permissible share)] per plane, or the static one."""
    if judged.planes:
        return [(label, z, off.value, got.ci95, allowed)
                for label, (z, got), (_, off), allowed in zip(
                    ('I', 'II'), found.planes, diff.planes, judged.plane_permissible)]
    return [('static', None, diff.static.value, found.static.ci95, judged.permissible)]


def explain(model, diff):
    """
    Return what would explain a residual (measured - layout), one phrase, or None.

    Candidates, each fitted to the residual's plane vectors (or, without planes, its
    static unbalance): one component heavier or lighter (its mass times radius scaled by
    a real factor), missing, or moved round its axis; or one mass the layout does not
    list, at the axial place the two planes' shares put it. The best candidate is offered
    when it leaves at most ``EXPLAINED`` of the residual unexplained (or no more than the
    measurement's 95 % radius).
    """
    target = _target(model, diff)
    if target is None:
        return None
    vector, noise = target
    size = math.sqrt(sum(abs(v) ** 2 for v in vector))
    if size == 0.0:
        return None
    candidates = []
    components = model.layout.components
    # A part-by-part search is for layouts people wrote; a generated one of 10^6 parts
    # gets the unlisted-mass explanation only (this runs every diagnostics period).
    for component in components if len(components) <= MAX_CANDIDATES else ():
        moment = component.mass * component.radius
        if moment <= 0.0:
            continue
        effect = _effect(model, moment * cmath.exp(1j * component.angle), component.z)
        candidates += [(left, 0, phrase)
                       for left, phrase in _component_candidates(component, effect, vector)]
    # A part the layout lists explains better than a mass it does not, when both fit.
    candidates += [(left, 1, phrase) for left, phrase in _unlisted_candidates(model, vector)]
    if not candidates:
        return None
    best = min(left for left, *_ in candidates)
    left, _, phrase = min((c for c in candidates if c[0] <= best + 1e-9 * size),
                          key=lambda c: (c[1], c[0]))
    if left <= max(EXPLAINED * size, noise):
        return phrase
    return None


def _target(model, diff):
    """Return the residual as a vector (per plane, or static) and its 95 % radius, or None."""
    if diff.planes:
        vector = [v.value for _, v in diff.planes]
        noise = math.sqrt(sum(v.ci95 ** 2 for _, v in diff.planes))
    else:
        vector, noise = [diff.static.value], diff.static.ci95
    if not all(cmath.isfinite(v) for v in vector):
        return None
    return vector, noise if math.isfinite(noise) else 0.0


def _effect(model, moment, z):
    """Return the residual a mass moment (kg m, complex) at ``z`` adds (planes, or static)."""
    planes = model.layout.correction_planes()
    if planes is None:
        return [moment]
    split = two_plane_split((moment.real, moment.imag), (moment.real * z, moment.imag * z),
                            *planes)
    return [complex(*u) for u in split]


def _left(vector, fitted):
    return math.sqrt(sum(abs(v - f) ** 2 for v, f in zip(vector, fitted)))


def _component_candidates(component, effect, vector):
    """(unexplained, phrase) for one component heavier/lighter, missing, or moved round."""
    energy = sum(abs(a) ** 2 for a in effect)
    ratio = sum(a.conjugate() * v for a, v in zip(effect, vector)) / energy
    name, mass = component.name, component.mass
    found = []
    scale = ratio.real                     # mass x radius scaled by (1 + scale)
    if scale > -0.9:
        found.append((_left(vector, [scale * a for a in effect]),
                      f'as if {name} were {scale * mass:+.3g} kg '
                      f'{"heavier" if scale > 0 else "lighter"} (its {mass:g} kg at '
                      f'{component.radius:g} m, {degrees_360(component.angle):.0f} deg)'))
    found.append((_left(vector, [-a for a in effect]), f'as if {name} were missing'))
    turned = cmath.phase(1.0 + ratio)      # moved round by this angle, mass unchanged
    if abs(turned) > 1e-9:
        step = cmath.exp(1j * turned) - 1.0
        found.append((_left(vector, [step * a for a in effect]),
                      f'as if {name} had moved {degrees(turned):+.0f} deg round the axis'))
    return found


def _unlisted_candidates(model, vector):
    """(unexplained, phrase) for one mass the layout does not list."""
    planes = model.layout.correction_planes()
    radius = model.layout.correction_radius() or 0.0
    if planes is None:
        (moment,) = vector
        where = ''
        fitted = [moment]
    else:
        z_i, z_ii = planes
        moment = vector[0] + vector[1]
        if abs(moment) == 0.0:
            return []
        # A point mass at z puts U (z_II - z)/b and U (z - z_I)/b into the planes: its z
        # from the real share of plane II (the imaginary part is what it cannot explain).
        share = (vector[1] / moment).real
        z = z_i + share * (z_ii - z_i)
        fitted = _effect(model, moment, z)
        where = f', z {z:.3f} m'
    mass = f'{abs(moment) / radius * 1e3:.0f} g at the correction radius {radius:g} m' \
        if radius > 0.0 else f'{g_mm(abs(moment)):.0f} g mm'
    angle = degrees_360(cmath.phase(moment))
    return [(_left(vector, fitted), f'as if an unlisted {mass} were at {angle:.0f} deg{where} '
             '(or a part there heavier than the layout says)')]


def worst(levels):
    """Return the most severe of assessment levels (NOT JUDGED < OK < WARN < ERROR)."""
    return max(levels, key=LEVEL_ORDER.__getitem__)


__all__ = ['CANNOT_TELL', 'Disagreement', 'disagreeing', 'disagreement_text', 'explain',
           'LAYOUT', 'LOAD_CELLS', 'MEASURED', 'NO_CELLS', 'PlaneEstimate',
           'RESIDUAL_WARN', 'verdict_of_record', 'VerdictOfRecord', 'worst']
