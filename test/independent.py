"""
Independent references for whole pipelines: Pinocchio's RNEA per sample, statics by hand.

Nothing here uses cvc_balance's physics. A :class:`PinocchioRotor` builds the Pinocchio
model of a layout mapping once (as :func:`reference.pinocchio_model` does) and gives,
per motion sample, the load on the stator and the drive torque by RNEA; the split of a
load over the supports is solved as a linear system of the statics (force and moment
balance about O, the axial force on the support marked axial), not by the engine's
formulas; the unbalance comes from Pinocchio's own mass properties. Input bags carry
exact motions (:func:`ramp`) in messages serialised by rosbags; outputs are read back
with rosbags.
"""

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
from rosbags.typesys import get_typestore, Stores

from cvc_balance.bag.mcap_writer import BagWriter
from reference import pinocchio_model

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


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
        elements): the convention of the `unbalance` topic (docs: frames).
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


def write_input_bag(path, stamps, angle, omega, layouts=(), names=('gantry_joint',)):
    """
    Write an input bag: messages serialised by rosbags, in the project's MCAP writer.

    ``layouts``: (log time ns, layout text) pairs on /layout. ``angle`` None: speed only,
    std_msgs/Float64 on /speed with the stamps as log times. (Files from other MCAP
    writers keep their channels inside chunks, which the bag reader does not read yet:
    issue 11.)
    """
    joint_type, string_type = 'sensor_msgs/msg/JointState', 'std_msgs/msg/String'
    with BagWriter(path, chunk_bytes=8192) as writer:
        layout = writer.add_channel('/layout', string_type, latched=True)
        for log_time, text in layouts:
            writer.write(layout, int(log_time), TYPESTORE.serialize_cdr(
                TYPESTORE.types[string_type](data=text), string_type).tobytes())
        if angle is None:
            speed_type = 'std_msgs/msg/Float64'
            speed = writer.add_channel('/speed', speed_type, best_effort=True)
            for ns, w in zip(stamps, omega):
                writer.write(speed, int(ns), TYPESTORE.serialize_cdr(
                    TYPESTORE.types[speed_type](data=float(w)), speed_type).tobytes())
            return path
        joints = writer.add_channel('/joint_states', joint_type, best_effort=True)
        state = TYPESTORE.types[joint_type]
        header = TYPESTORE.types['std_msgs/msg/Header']
        stamp_type = TYPESTORE.types['builtin_interfaces/msg/Time']
        for ns, q, w in zip(stamps, angle, omega):
            msg = state(header=header(stamp=stamp_type(sec=int(ns) // 10**9,
                                                       nanosec=int(ns) % 10**9),
                                      frame_id=''),
                        name=list(names), position=np.array([q]), velocity=np.array([w]),
                        effort=np.array([], dtype=float))
            writer.write(joints, int(ns), TYPESTORE.serialize_cdr(msg, joint_type).tobytes())
    return path


def read_outputs(path):
    """{topic: {stamp ns: [fx, fy, fz, tx, ty, tz]}} by rosbags."""
    from rosbags.highlevel import AnyReader
    out = {}
    with AnyReader([Path(path)]) as reader:
        for connection, _, raw in reader.messages():
            if connection.msgtype != 'geometry_msgs/msg/WrenchStamped':
                continue
            msg = reader.deserialize(raw, connection.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            w = msg.wrench
            out.setdefault(connection.topic, {})[stamp] = [
                w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]
    return out


def ramp(omega0, alpha, rate=200.0, seconds=4.0):
    """Exact motion from angle 0: stamps (ns), angle (wrapped), omega."""
    t = np.arange(int(seconds * rate)) / rate
    angle = np.remainder(omega0 * t + 0.5 * alpha * t * t + math.pi, 2 * math.pi) - math.pi
    return 5 * 10**9 + np.round(t * 1e9).astype(np.int64), angle, omega0 + alpha * t
