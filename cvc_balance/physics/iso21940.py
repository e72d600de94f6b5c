"""
ISO 21940-11 balance quality grades for rigid rotors.

Permissible residual unbalance U_per = G m / Omega (SI: G in m/s, U_per in
kg m); the standard quotes G in mm/s and U_per in g mm, where
U_per [g mm] = 1000 G [mm/s] m [kg] / Omega [rad/s]. Grades are named by G in
mm/s ("G 6.3") at the edges; SI inside. For a rotor between bearings U_per
is allocated to two correction planes A, B as U_per,A = U_per L_B / L and
U_per,B = U_per L_A / L (L_A, L_B: distances from the centre of mass to the
planes), each share kept within 0.3-0.7 of U_per (secondary sources; see
shared/domain/FACTS.md). A centre of mass outside the planes gets the clamped
shares too, which the standard treats by other rules: indicative there.
"""

GRADES = (0.4, 1.0, 2.5, 6.3, 16.0, 40.0, 100.0, 250.0, 630.0, 1600.0, 4000.0)
"""Balance quality grades G, mm/s, finest first."""

SHARE_LIMITS = (0.3, 0.7)


def permissible_unbalance(grade, mass, omega):
    """U_per in kg m for grade G (mm/s), rotor mass (kg) at omega (rad/s)."""
    return grade * 1e-3 * mass / omega


def plane_shares(z_com, z_a, z_b):
    """Fractions of U_per allowed in planes A (z_a) and B (z_b) for a rotor between bearings."""
    span = z_b - z_a
    low, high = SHARE_LIMITS
    share_a = min(max((z_b - z_com) / span, low), high)
    share_b = min(max((z_com - z_a) / span, low), high)
    return share_a, share_b


def equivalent_grade(plane_amounts, shares, mass, omega):
    """
    Return the G (mm/s) at which the worst plane just meets its allocated U_per.

    ``plane_amounts`` kg m per plane, ``shares`` from :func:`plane_shares`.
    """
    return max(amount / share for amount, share in zip(plane_amounts, shares)) \
        * omega / mass * 1e3


def finest_grade_met(grade_value):
    """
    Return the finest standard grade G (mm/s) that a rotor of this equivalent grade meets.

    None when it is coarser than G 4000.
    """
    for grade in GRADES:
        if grade_value <= grade:
            return grade
    return None
