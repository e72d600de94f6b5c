"""
Identify a rotor's unbalance from a run's load-cell readings at once (vectorised).

The motion (encoder angle, speed, acceleration) is sampled at its own times; each cell
reads at its own. The motion is interpolated at each reading's stamp (the angle unwrapped
first), readings outside the motion's time span are dropped and counted, and every reading
adds its row to the normal equations (:class:`~cvc_balance.identify.fit.Sums`).
"""

from dataclasses import dataclass

import numpy as np

from cvc_balance.identify.fit import Sums
from cvc_balance.identify.regressors import moment_coefficients, support_coefficients


@dataclass
class CellReadings:
    """One support's load cell: stamps (s), force (n, 3) N and torque (n, 3) N m, stator."""

    support: str
    time: np.ndarray
    force: np.ndarray
    torque: np.ndarray


@dataclass
class Motion:
    """Motion samples: time (s, increasing), angle (rad), omega (rad/s), alpha (rad/s^2)."""

    time: np.ndarray
    angle: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray

    def at(self, time):
        """Return (angle, omega, alpha) interpolated at ``time`` (s; inside the span)."""
        unwrapped = np.unwrap(self.angle)
        return (np.interp(time, self.time, unwrapped), np.interp(time, self.time, self.omega),
                np.interp(time, self.time, self.alpha))

    def revolutions(self):
        """Return the turns the rotor made over these samples."""
        if len(self.angle) < 2:
            return 0.0
        unwrapped = np.unwrap(self.angle)
        return float(abs(unwrapped[-1] - unwrapped[0]) / (2 * np.pi))


def channels(supports):
    """Return the reading channels of a layout's supports: (support index, 'force'|'moment')."""
    if len(supports) == 1:
        return [(0, 'force'), (0, 'moment')]
    return [(k, 'force') for k in range(len(supports))]


MAX_READING = 1e12
"""Largest |force| (N) or |moment| (N m) component a cell reading may have: no bearing
carries 10^12 N, and the fit's sums of squares of such readings stay finite."""


def add_readings(sums, supports, g_z, motion, cells):
    """
    Add every cell reading inside the motion's span to ``sums``; return how many were dropped.

    ``cells``: {support name: CellReadings}; readings of unknown supports, outside the
    motion's span, not finite or beyond :data:`MAX_READING` are dropped.
    """
    names = [s.name for s in supports]
    dropped = 0
    for channel, (index, kind) in enumerate(channels(supports)):
        cell = cells.get(names[index])
        if cell is None:
            continue
        force, torque = np.asarray(cell.force, float), np.asarray(cell.torque, float)
        inside = (cell.time >= motion.time[0]) & (cell.time <= motion.time[-1]) \
            & np.all(np.abs(force) <= MAX_READING, axis=1) \
            & np.all(np.abs(torque) <= MAX_READING, axis=1)        # NaN: False
        if kind == 'force':
            dropped += int((~inside).sum())
        if not inside.any():
            continue
        angle, omega, alpha = motion.at(cell.time[inside])
        turn = np.exp(1j * angle)
        if kind == 'force':
            c_s, c_p = support_coefficients(supports, index, turn, omega, alpha, g_z)
            y = force[inside, 0] + 1j * force[inside, 1]
        else:
            c_s, c_p = moment_coefficients(supports[index], turn, omega, alpha, g_z)
            y = torque[inside, 0] + 1j * torque[inside, 1]
        sums.add_arrays(channel, np.broadcast_to(c_s, y.shape), np.broadcast_to(c_p, y.shape), y)
    dropped += sum(len(c.time) for name, c in cells.items() if name not in names)
    return dropped


def fit(model, motion, cells):
    """Return (Estimate, readings dropped) of one layout's run (``model``: its RotorModel)."""
    supports = model.supports
    sums = Sums(len(channels(supports)))
    dropped = add_readings(sums, supports, model.gravity[2], motion, cells)
    return sums.solve(), dropped
