"""
Independent references for whole pipelines: Pinocchio's RNEA per sample, statics by hand.

Nothing here uses cvc_balance's physics. A :class:`PinocchioRotor` builds the Pinocchio
model of a layout mapping once (as :func:`reference.pinocchio_model` does) and gives,
per motion sample, the load on the stator and the drive torque by RNEA; the split of a
load over the supports is solved as a linear system of the statics (force and moment
balance about O, the axial force on the support marked axial), not by the engine's
formulas; the unbalance comes from Pinocchio's own mass properties.
"""

import math

import numpy as np
import pinocchio as pin

from reference import pinocchio_model


class PinocchioRotor:
    """A layout mapping as a Pinocchio model, built once; loads per sample by RNEA."""

    def __init__(self, layout):
        """Build the model of ``layout`` (a mapping in the layout file format)."""
        self.layout = layout
        self.model = pinocchio_model(layout)
        self.data = self.model.createData()
        self.supports = layout['supports']

    def loads(self, q, omega, alpha, gravity=None):
        """
        Return a dict: force/moment on the stator (stator frame, about O), drive torque.

        ``supports``: {name: (force, moment)}, stator frame, by :func:`split_by_hand`.
        """
        self.model.gravity.linear = np.asarray(
            self.layout.get('gravity', [0.0, -9.80665, 0.0]) if gravity is None else gravity,
            dtype=float)
        tau = pin.rnea(self.model, self.data, np.array([q]), np.array([omega]),
                       np.array([alpha]))
        wrench = self.data.f[1]            # stator -> rotor through the joint, rotor frame
        force, moment = -np.array(wrench.linear), -np.array(wrench.angular)
        moment[2] = 0.0                    # about Z: the drive's, not the bearings'
        turn = pin.utils.rotate('z', q)
        force, moment = turn @ force, turn @ moment
        return {'force': force, 'moment': moment, 'drive_torque': float(tau[0]),
                'force_rotor': turn.T @ force, 'moment_rotor': turn.T @ moment,
                'supports': split_by_hand(self.supports, force, moment)}

    def unbalance(self, omega):
        """
        Return the unbalance topic's wrench at ``omega`` (rotor frame), by Pinocchio.

        Force U omega^2 with U = m c_xy; torque omega^2 (-P_yz, P_xz, 0) with the product
        integrals P = int x z dm, int y z dm about the centre of mass (minus the tensor's
        elements): the convention of the README's topic table.
        """
        body = self.model.inertias[1]
        mass, com, inertia = body.mass, np.array(body.lever), np.array(body.inertia)
        p_xz, p_yz = -inertia[0, 2], -inertia[1, 2]
        w2 = omega * omega
        return (np.array([w2 * mass * com[0], w2 * mass * com[1], 0.0]),
                np.array([-w2 * p_yz, w2 * p_xz, 0.0]))

    def mass_properties(self):
        """Return (mass kg, centre of mass m, inertia about the centre of mass kg m^2)."""
        body = self.model.inertias[1]
        return body.mass, np.array(body.lever), np.array(body.inertia)


def split_by_hand(supports, force, moment):
    """
    Per support (force, moment) that carry ``force`` and ``moment`` (about O) by statics.

    Supports are points (0, 0, z) on the axis. Two: unknown forces F_a, F_b with
    F_a + F_b = F and (0, 0, z_a) x F_a + (0, 0, z_b) x F_b = M (x, y parts), solved as
    one 4x4 linear system; the axial force F_z goes to the support marked axial (at the
    axis, it has no moment about O). One: the force, and the moment about its point.
    """
    force, moment = np.asarray(force, float), np.asarray(moment, float)
    if len(supports) == 1:
        z = supports[0]['z']
        about_support = moment - np.cross([0.0, 0.0, z], force)
        return {supports[0]['name']: (force, about_support)}
    a, b = supports
    # Unknowns (F_ax, F_ay, F_bx, F_by); (0, 0, z) x F = (-z F_y, z F_x, 0).
    system = np.array([[1.0, 0.0, 1.0, 0.0],
                       [0.0, 1.0, 0.0, 1.0],
                       [0.0, -a['z'], 0.0, -b['z']],
                       [a['z'], 0.0, b['z'], 0.0]])
    f_ax, f_ay, f_bx, f_by = np.linalg.solve(system, [force[0], force[1], moment[0],
                                                      moment[1]])
    axial_a = force[2] if a.get('axial', False) else 0.0
    axial_b = force[2] if b.get('axial', False) else 0.0
    zero = np.zeros(3)
    return {a['name']: (np.array([f_ax, f_ay, axial_a]), zero),
            b['name']: (np.array([f_bx, f_by, axial_b]), zero)}


def tilted(tilt_deg):
    """Gravity of a gantry tilted by ``tilt_deg`` about stator X, m/s^2 (stator frame)."""
    tilt = math.radians(tilt_deg)
    return [0.0, -9.80665 * math.cos(tilt), 9.80665 * math.sin(tilt)]
