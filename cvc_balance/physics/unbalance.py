"""
Static, couple and dynamic unbalance of a rotor, and its correction masses.

Everything here is a property of the layout (no motion sample needed) and is
read off the aggregates of :class:`cvc_balance.physics.engine.RotorModel`, O(1):

* static unbalance U = int r_xy dm = (S_x, S_y), kg m;
* couple unbalance (P_xz, P_yz) about the centre of mass, kg m^2, with
  P_xz = int x z dm: for equal and opposite unbalances in two planes its
  angle is that of the one at greater z;
* dynamic unbalance resolved into two correction planes z_I < z_II: the
  unbalances U_I, U_II with U_I + U_II = U and z_I U_I + z_II U_II = P_O
  (P_O = (P_xz, P_yz) about O), i.e. ISO 21940-2's two-plane split
  U_I = sum U_i (z_II - z_i) / b, U_II = sum U_i (z_i - z_I) / b;
* correction masses: at the correction radius, opposite each plane's
  unbalance, so that adding them leaves no static and no couple unbalance.

Amounts SI (kg m, kg m^2, kg), angles rad in the rotor frame.
"""

from dataclasses import dataclass
import math

from cvc_balance.physics.frames import polar


@dataclass(frozen=True)
class PlaneUnbalance:
    """
    Unbalance in one correction plane and the mass that cancels it.

    ``amount`` kg m at ``angle`` rad (rotor frame); ``correction_mass`` kg at
    ``correction_radius`` m and ``correction_angle`` rad, in the plane at ``z`` m
    (None when the correction radius is 0: every component a point on the axis).
    """

    z: float
    amount: float
    angle: float
    correction_mass: float
    correction_radius: float
    correction_angle: float

    @property
    def vector(self):
        """(x, y) components, kg m."""
        return self.amount * math.cos(self.angle), self.amount * math.sin(self.angle)


def unbalance_wrench(static, couple, omega):
    """
    Return the unbalance's load at speed ``omega``, rotor frame: (force, torque).

    Force U omega^2 (static unbalance ``static`` = (U_x, U_y), kg m); torque
    omega^2 (-P_yz, P_xz, 0), the couple ``couple`` = (P_xz, P_yz) about the centre of
    mass (kg m^2), with the signs of the engine's bearing moment. Plain arithmetic:
    floats (the node) or arrays (replay).
    """
    w2 = omega * omega
    (u_x, u_y), (p_xz, p_yz) = static, couple
    return (w2 * u_x, w2 * u_y, 0.0), (-w2 * p_yz, w2 * p_xz, 0.0)


def static_unbalance(model):
    """(U_x, U_y) = int r_xy dm, kg m, rotor frame."""
    return model.s_x, model.s_y


def couple_unbalance(model):
    """(P_xz, P_yz) about the rotor's centre of mass, kg m^2, rotor frame."""
    z_com = model.s_z / model.mass
    return model.p_xz - model.s_x * z_com, model.p_yz - model.s_y * z_com


def plane_unbalances(model, z_i, z_ii, correction_radius):
    """
    Dynamic unbalance resolved into planes at z_i < z_ii (m).

    Returns (plane I, plane II) as :class:`PlaneUnbalance`.
    """
    split = two_plane_split((model.s_x, model.s_y), (model.p_xz, model.p_yz), z_i, z_ii)
    planes = []
    for z, (u_x, u_y) in zip((z_i, z_ii), split):
        amount, angle = polar(u_x, u_y)
        mass = amount / correction_radius if correction_radius > 0.0 else None
        planes.append(PlaneUnbalance(z, amount, angle, mass, correction_radius,
                                     _opposite(angle)))
    return tuple(planes)


def two_plane_split(first_moment, products, z_i, z_ii):
    """
    Split the dynamic unbalance into planes z_i < z_ii (m): ((U_Ix, U_Iy), (U_IIx, U_IIy)).

    From the first moment (S_x, S_y) (kg m) and the products (P_xz, P_yz) about
    O (kg m^2): U_I = (z_II S - P_O) / b, U_II = (P_O - z_I S) / b, kg m. Plain
    arithmetic, linear in its first two arguments: floats or numpy arrays (the
    design tools split derivatives and Monte-Carlo draws with it).
    """
    span = z_ii - z_i
    (s_x, s_y), (p_xz, p_yz) = first_moment, products
    return (((z_ii * s_x - p_xz) / span, (z_ii * s_y - p_yz) / span),
            ((p_xz - z_i * s_x) / span, (p_yz - z_i * s_y) / span))


def _opposite(angle):
    """Return the angle half a turn away, kept in (-pi, pi]."""
    return angle - math.pi if angle > 0.0 else angle + math.pi
