"""
What a load cell under a support reads, as a linear function of the rotor's unbalance.

The engine's equations (:mod:`cvc_balance.physics.engine`) in complex notation: a planar
vector (x, y) is x + i y, and a rotor-frame vector turns into the stator frame by
e^{iq}. With the static unbalance S = S_x + i S_y (kg m) and the products of inertia
about O, P = P_xz + i P_yz (kg m^2), the load on the stator is, stator frame,

    F = m g_s + e^{iq} (omega^2 - i alpha) S
    M = i S_z g_s + e^{iq} [(alpha + i omega^2) P - i g_z S]         (about O)

with g_s = g_x + i g_y and g_z the stator-frame gravity. Two supports at z_a < z_b
(span L) carry F_a = (z_b F + i M) / L and F_b = -(z_a F + i M) / L; one support at z_s
carries F and the tilting moment M - i z_s F. So each cell's reading (its force, and its
moment for a single support) is c_S S + c_P P + a constant: the constant (weight, the
axial position of the centre of mass, the cell's zero) is the same in every sample and is
fitted as the cell's bias. ``test/test_identify.py`` checks these coefficients against
the engine evaluated with unit aggregates, so a change of the engine's conventions
fails there.

Works on Python complex numbers (the live per-message path) and on numpy arrays.
"""

import cmath


def turning(q):
    """Return e^{iq} for a float rotor angle q (rad); numpy arrays: use numpy.exp(1j q)."""
    return cmath.rect(1.0, q)


def support_coefficients(supports, index, turn, omega, alpha, g_z):
    """
    Return (c_S, c_P) of the force on support ``index`` (complex, stator frame).

    ``supports``: the layout's supports; ``turn`` e^{iq}; omega rad/s, alpha rad/s^2,
    ``g_z`` the stator-frame axial gravity, m/s^2. Floats or numpy arrays.
    """
    centrifugal = omega * omega - 1j * alpha          # F = e^{iq} (w^2 - i a) S + ...
    couple = 1j * alpha - omega * omega               # i (a + i w^2): P's part of i M
    if len(supports) == 1:
        return turn * centrifugal, 0.0 * turn
    a, b = supports
    span = b.z - a.z
    if index == 0:
        return turn * (b.z * centrifugal + g_z) / span, turn * couple / span
    return -turn * (a.z * centrifugal + g_z) / span, -turn * couple / span


def moment_coefficients(support, turn, omega, alpha, g_z):
    """
    Return (c_S, c_P) of a single support's tilting moment (complex, stator frame, N m).

    The moment about the support point at ``support.z``: M - i z_s F.
    """
    centrifugal = omega * omega - 1j * alpha
    return -1j * turn * (g_z + support.z * centrifugal), turn * (alpha + 1j * omega * omega)
