"""
The live fit: O(1) per reading over a sliding window of revolutions (plain Python floats).

The node feeds motion samples (:meth:`SlidingFit.motion`) and cell readings
(:meth:`SlidingFit.reading`) as they come. A reading's angle, speed and acceleration are
those of the latest motion sample carried to the reading's stamp (q + omega dt +
alpha dt^2 / 2): cells and encoder need not share a clock tick. Readings are summed per
revolution of the rotor; the window is the last ``window_revs`` whole revolutions plus
the one under way, re-added from the per-revolution sums at each new revolution (no
drift from subtracting).
"""

from collections import deque
import math

from cvc_balance.identify.batch import channels, MAX_READING
from cvc_balance.identify.fit import Sums
from cvc_balance.identify.regressors import moment_coefficients, support_coefficients, turning

TWO_PI = 2.0 * math.pi
MAX_EXTRAPOLATION = 0.05
"""Seconds a reading may lie from the latest motion sample (else it is dropped)."""


class SlidingFit:
    """Live identification for one layout (see the module's description)."""

    def __init__(self, supports, g_z, window_revs=10):
        """Fit the readings of ``supports`` (a layout's) under axial gravity ``g_z`` m/s^2."""
        if not window_revs >= 1:
            raise ValueError(f'window must be >= 1 revolution, got {window_revs}')
        self.supports = tuple(supports)
        self.g_z = float(g_z)
        self.window_revs = int(window_revs)
        self._channels = channels(self.supports)
        self._index = {s.name: k for k, s in enumerate(self.supports)}
        self._force_channel = {k: self._channels.index((k, 'force'))
                               for k in range(len(self.supports))}
        self._blocks = deque()
        self._current = Sums(len(self._channels))
        self._window = Sums(len(self._channels))
        self._motion = None           # (time, angle, omega, alpha) of the latest sample
        self._turned = 0.0            # angle turned since the current block began, rad
        self.dropped = 0
        self.revolutions = 0

    def motion(self, time, angle, omega, alpha):
        """Take a motion sample (s, rad, rad/s, rad/s^2); close a block each revolution."""
        if self._motion is not None:
            step = math.remainder(angle - self._motion[1], TWO_PI)
            self._turned += abs(step)
            if self._turned >= TWO_PI:
                self._turned -= TWO_PI
                self._close_block()
        self._motion = (time, angle, omega, alpha)

    def _close_block(self):
        self._blocks.append(self._current)
        self._current = Sums(len(self._channels))
        while len(self._blocks) > self.window_revs:
            self._blocks.popleft()
        window = Sums(len(self._channels))
        for block in self._blocks:
            window = window.combine(block)
        self._window = window
        self.revolutions += 1

    def reading(self, support, time, force, moment=None):
        """
        Add a cell reading: ``support`` name, stamp (s), force (x, y) N, stator frame.

        ``moment`` (x, y) N m is used for a single support (its tilting moment).
        Returns False (and counts it dropped) when it cannot be used: unknown support,
        not finite or beyond :data:`~cvc_balance.identify.batch.MAX_READING`, no motion
        yet, or too far in time from the latest motion sample.
        """
        index = self._index.get(support)
        state = self._motion
        if index is None or state is None or not all(
                abs(v) <= MAX_READING for v in (*force, *(moment or ()))):
            self.dropped += 1
            return False
        last_time, angle, omega, alpha = state
        dt = time - last_time
        if not abs(dt) <= MAX_EXTRAPOLATION:
            self.dropped += 1
            return False
        turn = turning(angle + omega * dt + 0.5 * alpha * dt * dt)
        omega += alpha * dt
        c_s, c_p = support_coefficients(self.supports, index, turn, omega, alpha, self.g_z)
        channel = self._force_channel[index]
        self._current.add(channel, c_s, c_p, complex(force[0], force[1]))
        if len(self.supports) == 1 and moment is not None:
            c_s, c_p = moment_coefficients(self.supports[0], turn, omega, alpha, self.g_z)
            self._current.add(channel + 1, c_s, c_p, complex(moment[0], moment[1]))
        return True

    def sums(self):
        """Return the window's sums: the last whole revolutions and the one under way."""
        return self._window.combine(self._current)

    def estimate(self):
        """Return the window's :class:`~cvc_balance.identify.fit.Estimate`."""
        return self.sums().solve()
