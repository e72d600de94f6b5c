"""
Frames, signs and units of cvc_balance: the one module that owns them.

Frames (REP-103 / REP-105 style, right-handed, SI units):

* ``stator`` frame: fixed to the machine base. Z is the spin axis; the origin O
  is on the axis at z = 0. Gravity is given in this frame.
* ``rotor`` frame: turns with the rotor about the common Z axis. The rotor
  angle q (rad) is the angle from stator X to rotor X, positive about +Z.
* A component's own frame is (radial, tangential, axial) at its angle theta:
  x points from the axis through the component's centre of mass, y is x
  turned by +90 deg about Z, z is the spin axis (the thesis's X_phi Y_phi Z).

Signs:

* Inertia tensors hold tensor elements, as URDF does: ``ixy = -int x y dm``.
  The thesis's (and balancing practice's) products of inertia are the
  positive integrals ``P_xy = int x y dm``; :func:`products_of_inertia`
  converts.
* Loads are what the rotor puts on the stator through its supports (what a
  load cell on the stator reads), i.e. minus the support reaction on the rotor.
* The drive torque is the torque the drive applies to the rotor about +Z.

Angles are radians everywhere inside the code; degrees only at the edges
(layout files may say ``angle_deg``; the command line prints degrees).

Units for people: unbalance is printed in g mm (static, per plane) and g mm^2
(couple), as balancing practice and ISO 21940 quote them; :func:`g_mm` and
:func:`g_mm2` convert from SI (1 kg m = 10^6 g mm, 1 kg m^2 = 10^9 g mm^2).

For drawing: the **lab** frame has gravity along -Y; :func:`stator_tilt` turns
the stator into it (a gantry tilted about stator X by beta has gravity
(0, -g cos beta, g sin beta) in the stator frame).
"""

import math

import numpy as np

STATOR_FRAME = 'stator'
ROTOR_FRAME = 'rotor'

STANDARD_GRAVITY = 9.80665
"""m/s^2, the conventional value (CGPM 1901)."""

DEFAULT_GRAVITY = (0.0, -STANDARD_GRAVITY, 0.0)
"""Gravity in the stator frame, m/s^2: stator Y points up, Z is horizontal."""


def turn_xy(x, y, cos_a, sin_a):
    """
    Turn the XY part of a vector by the angle whose cosine and sine are given.

    With (cos q, sin q) this maps rotor-frame components to the stator frame;
    with (cos q, -sin q) stator to rotor. Works on floats and on numpy arrays
    alike (plain arithmetic, no numpy calls), so the per-message path and the
    vectorised path share it.
    """
    return cos_a * x - sin_a * y, sin_a * x + cos_a * y


def products_of_inertia(tensor):
    """
    Products of inertia (P_xy, P_xz, P_yz) = (int xy dm, int xz dm, int yz dm).

    ``tensor`` is a 3x3 inertia tensor (tensor elements, ixy = -int xy dm);
    returns kg m^2.
    """
    return -tensor[0, 1], -tensor[0, 2], -tensor[1, 2]


def tensor_from_elements(ixx, iyy, izz, ixy, ixz, iyz):
    """3x3 inertia tensor from URDF-style elements (ixy = -int xy dm)."""
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)


def tensors_from_elements(elements):
    """Stack of 3x3 tensors (n, 3, 3) from rows of elements (n, 6), as above."""
    elements = np.asarray(elements, dtype=float).reshape(-1, 6)
    tensors = np.empty((len(elements), 3, 3))
    for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        tensors[:, i, j] = tensors[:, j, i] = elements[:, k]
    return tensors


TWO_PI = 2.0 * math.pi


def wrap_angle(angle):
    """
    Angle(s) in rad brought to [-pi, pi] (nearest turn; math.remainder's convention).

    A float stays in plain Python (the per-message path); arrays go through numpy.
    """
    if isinstance(angle, float):
        return math.remainder(angle, TWO_PI)
    return angle - TWO_PI * np.round(np.asarray(angle) / TWO_PI)


def polar(x, y):
    """Amount and angle (rad, from X toward Y) of a planar vector."""
    return math.hypot(x, y), math.atan2(y, x)


G_MM_PER_KG_M = 1e6
"""g mm in one kg m (10^3 g times 10^3 mm)."""

G_MM2_PER_KG_M2 = 1e9
"""g mm^2 in one kg m^2 (10^3 g times 10^6 mm^2)."""


def g_mm(kg_m):
    """Unbalance (or any mass times length) from kg m to g mm, for people."""
    return kg_m * G_MM_PER_KG_M


def g_mm2(kg_m2):
    """Couple unbalance (mass times length squared) from kg m^2 to g mm^2, for people."""
    return kg_m2 * G_MM2_PER_KG_M2


def stator_tilt(gravity):
    """
    Rotation (unit axis, angle rad) from the stator frame to the lab frame.

    The lab frame has gravity along -Y; the rotation is the smallest one that
    turns ``gravity`` (m/s^2, stator frame) onto -Y: about stator X by beta
    for a gantry tilted by beta. No gravity (or gravity along -Y already):
    no rotation. Gravity along +Y: half a turn about X.
    """
    g_x, g_y, g_z = (float(v) for v in gravity)
    size = math.sqrt(g_x * g_x + g_y * g_y + g_z * g_z)
    if size == 0.0:
        return (1.0, 0.0, 0.0), 0.0
    a_x, a_y, a_z = g_x / size, g_y / size, g_z / size
    # axis = a x (0, -1, 0) = (a_z, 0, -a_x); cos(angle) = a . (0, -1, 0) = -a_y
    sin_angle = math.hypot(a_z, a_x)
    angle = math.atan2(sin_angle, -a_y)
    if sin_angle < 1e-15:
        return (1.0, 0.0, 0.0), angle
    return (a_z / sin_angle, 0.0, -a_x / sin_angle), angle


def degrees(angle):
    """Radians to degrees, for people (output edges only)."""
    return math.degrees(angle)


def degrees_360(angle):
    """
    Radians to degrees in [0, 360), for people: every angle a person reads (text, JSON).

    One range everywhere, as a protractor and a gantry's hole count read them; -0.0 and
    values that round to 360 read as 0.
    """
    value = math.degrees(angle) % 360.0
    return 0.0 if value >= 360.0 or value == 0.0 else value


def radians(angle_deg):
    """Degrees to radians, for people's input (layout files, command line)."""
    return math.radians(angle_deg)
