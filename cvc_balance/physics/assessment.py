"""
A rotor's balance against its ISO 21940-11 grade: the service engineer's view.

Combines :mod:`cvc_balance.physics.unbalance` (where the unbalance is, what corrects
it) with :mod:`cvc_balance.physics.iso21940` (how much is allowed) for one speed.
SI inside (kg m, rad/s, rad); the grade in mm/s as the standard names it.
"""

from dataclasses import dataclass

from cvc_balance.physics import iso21940
from cvc_balance.physics.frames import polar
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance


@dataclass(frozen=True)
class BalanceAssessment:
    """
    Unbalance of a rotor and its verdict against a grade at a speed.

    ``planes`` is (plane I, plane II) or () when the layout has no two
    correction planes; ``plane_permissible`` the U_per share (kg m) of each.
    ``equivalent_grade`` (mm/s) is the grade the rotor achieves (None
    without planes: then the static unbalance alone is judged).
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
