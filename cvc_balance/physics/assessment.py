"""
A rotor's balance against its ISO 21940-11 grade: the service engineer's view.

Combines :mod:`cvc_balance.physics.unbalance` (where the unbalance is, what corrects
it) with :mod:`cvc_balance.physics.iso21940` (how much is allowed) for one speed.
SI inside (kg m, rad/s, rad); the grade in mm/s as the standard names it.

**The verdict** (one definition, used by the node, ``solve``, ``replay`` and the
rerun view): the unbalance is a property of the layout and does not change with
speed; ISO 21940-11 judges it against U_per = G m / Omega at the maximum service
speed. So the balance is judged at the layout's ``balancing.service_speed``, or,
when the layout names none, at the top speed seen (the speed asked for in
``solve``; the top |omega| of the accepted samples live or in a bag). The live
speed decides only whether a sample counts towards that top speed, never the
limit itself. Levels: ``ERROR`` beyond the grade, ``WARN`` within it but beyond
``warn_fraction`` of it (default 0.8), ``OK`` within, ``NOT JUDGED`` with no
speed to judge at.
"""

from dataclasses import dataclass

from cvc_balance.physics import iso21940, limits
from cvc_balance.physics.frames import degrees_360, g_mm, polar
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance

WARN_FRACTION = 0.8
"""Default: WARN when the achieved grade is beyond this fraction of the grade."""

OK, WARN, ERROR, NOT_JUDGED = 'OK', 'WARN', 'ERROR', 'NOT JUDGED'
"""Verdict levels (the node maps them onto diagnostic_msgs levels)."""

SERVICE_SPEED, TOP_SPEED = 'service speed', 'top speed seen'
"""Where the judging speed came from."""


@dataclass(frozen=True)
class BalanceAssessment:
    """
    Unbalance of a rotor and its verdict against a grade at a speed.

    ``planes`` is (plane I, plane II) or () when the layout has no two
    correction planes; ``plane_permissible`` the U_per share (kg m) of each.
    ``equivalent_grade`` (mm/s) is the grade the rotor achieves (without
    planes the static unbalance alone is judged).
    """

    omega: float
    grade: float
    static_amount: float
    static_angle: float
    couple_amount: float
    couple_angle: float
    permissible: float
    planes: tuple
    plane_permissible: tuple
    equivalent_grade: float
    finest_grade_met: float

    @property
    def within_grade(self):
        """Tell whether every plane (or the static unbalance) is within its U_per share."""
        return self.equivalent_grade <= self.grade

    @property
    def fractions(self):
        """
        Each plane's unbalance as a fraction of its own U_per share (1.0 = its limit).

        Without planes: the static unbalance over U_per, as a 1-tuple. The largest
        fraction times the grade is the equivalent grade.
        """
        if not self.planes:
            return (self.static_amount / self.permissible,)
        return tuple(p.amount / allowed
                     for p, allowed in zip(self.planes, self.plane_permissible))


def assess_balance(model, omega=None, grade=None):
    """
    Assess ``model`` (a RotorModel) at ``omega`` rad/s against ``grade`` (mm/s).

    Defaults: the layout's service speed and grade. Raises ValueError when
    there is no speed > 0 to judge at.
    """
    layout = model.layout
    if omega is None:
        omega = layout.balancing.service_speed
    if omega is None or not omega > 0.0:
        raise ValueError('a service speed > 0 rad/s is needed to judge the balance grade')
    if grade is None:
        grade = layout.balancing.grade
    static = polar(*static_unbalance(model))
    couple = polar(*couple_unbalance(model))
    u_per = iso21940.permissible_unbalance(grade, model.mass, omega)
    planes_z = layout.correction_planes()
    if planes_z is None:
        planes, shares = (), ()
        equivalent = static[0] * omega / model.mass * 1e3
    else:
        planes = plane_unbalances(model, *planes_z, layout.correction_radius())
        shares = iso21940.plane_shares(model.s_z / model.mass, *planes_z)
        equivalent = iso21940.equivalent_grade([p.amount for p in planes], shares,
                                               model.mass, omega)
    return BalanceAssessment(omega, grade, *static, *couple, u_per,
                             planes, tuple(u_per * s for s in shares), equivalent,
                             iso21940.finest_grade_met(equivalent))


def judging_speed(layout, top_speed=0.0):
    """
    Return (speed rad/s, source) at which ``layout``'s balance is judged.

    The layout's service speed if it names one, else ``top_speed`` (the top
    |omega| seen, rad/s) if it is a speed a grade means something at (at least
    :data:`limits.SPEED`'s 1e-3 rad/s: slower, U_per = G m / omega has no bound);
    (None, None) when there is neither.
    """
    service = layout.balancing.service_speed
    if service is not None and service > 0.0:
        return service, SERVICE_SPEED
    top = abs(top_speed)
    if top >= limits.SPEED.low:
        return top, TOP_SPEED
    return None, None


@dataclass(frozen=True)
class Verdict:
    """
    The balance verdict of a layout: level, the assessment behind it, and its text.

    ``assessment`` is None when not judged (no service speed and no speed seen).
    """

    level: str
    grade: float
    assessment: BalanceAssessment = None
    speed_source: str = None
    warn_fraction: float = WARN_FRACTION

    @property
    def words(self):
        """'WITHIN G 6.3', 'WITHIN G 6.3, NEAR ITS LIMIT', 'OUT OF G 6.3' or 'NOT JUDGED'."""
        grade = f'G {self.grade:g}'
        return {OK: f'WITHIN {grade}', WARN: f'WITHIN {grade}, NEAR ITS LIMIT',
                ERROR: f'OUT OF {grade}', NOT_JUDGED: 'NOT JUDGED'}[self.level]

    @property
    def text(self):
        """One line for people, e.g. 'G 7.39 at the service speed 23.27 rad/s: OUT OF G 6.3'."""
        a = self.assessment
        if a is None:
            return ('balance grade not judged: the layout names no service speed '
                    '(balancing.service_speed) and the rotor has not turned')
        return (f'G {a.equivalent_grade:.3g} at the {self.speed_source} {a.omega:.4g} rad/s: '
                f'{self.words}')


def judge_balance(model, top_speed=0.0, grade=None, warn_fraction=WARN_FRACTION):
    """
    Judge ``model``'s balance: its Verdict (see the module's description).

    ``top_speed`` rad/s: the top |omega| seen, used only when the layout has no
    service speed; ``grade`` mm/s (default the layout's).
    """
    grade = grade or model.layout.balancing.grade
    speed, source = judging_speed(model.layout, top_speed)
    if speed is None:
        return Verdict(NOT_JUDGED, grade, warn_fraction=warn_fraction)
    assessment = assess_balance(model, speed, grade)
    achieved = assessment.equivalent_grade
    if achieved > grade:
        level = ERROR
    elif achieved > warn_fraction * grade:
        level = WARN
    else:
        level = OK
    return Verdict(level, grade, assessment, source, warn_fraction)


def verdict_record(verdict):
    """
    Return ``verdict`` as JSON-able data: ``solve --json``'s and ``replay --json``'s balance.

    None when not judged. Planes: z, unbalance (g mm, deg), permissible share (g mm),
    fraction of it, correction mass (kg) at its radius (m) and angle (deg).
    """
    assessment = verdict.assessment
    if assessment is None:
        return None
    return {
        'grade': assessment.grade, 'service_speed': assessment.omega,
        'speed_source': verdict.speed_source,
        'permissible_g_mm': g_mm(assessment.permissible),
        'planes': [{'z': p.z, 'g_mm': g_mm(p.amount), 'angle_deg': degrees_360(p.angle),
                    'permissible_g_mm': g_mm(allowed), 'fraction': fraction,
                    'correction_mass_kg': p.correction_mass,
                    'correction_radius': p.correction_radius,
                    'correction_angle_deg': degrees_360(p.correction_angle)}
                   for p, allowed, fraction in zip(assessment.planes,
                                                   assessment.plane_permissible,
                                                   assessment.fractions)],
        'equivalent_grade': assessment.equivalent_grade,
        'finest_grade_met': assessment.finest_grade_met,
        'within_grade': assessment.within_grade,
        'level': verdict.level,
        'verdict': verdict.words,
    }
