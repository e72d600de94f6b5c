"""
The node's load cells: each support's ``supports/<name>/measured_load``, the live fit, its outputs.

One :class:`LoadCells` per layout in force (its supports name the cells). Readings go to
an O(1) sliding fit over revolutions (:class:`cvc_balance.identify.live.SlidingFit`);
at each completed revolution the fit is solved and ``identified_unbalance`` and
``unbalance_residual`` are published (WrenchStamped, rotor frame, the convention of
``unbalance``: force U omega^2, torque omega^2 (-P_yz, P_xz, 0) about the centre of
mass, at the speed of the sample that completed the revolution). The fit's estimate feeds
the node's verdict of record (:mod:`cvc_balance.identify.evidence`); the second
diagnostic status gets what the cells measured, the residual per plane and the fit.
"""

from functools import partial
import struct

from geometry_msgs.msg import WrenchStamped

from cvc_balance.identify.estimate import identified_unbalance, layout_unbalance, residual
from cvc_balance.identify.fit import Estimate
from cvc_balance.identify.live import SlidingFit
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import read_wrench_stamped
from cvc_balance.physics import assessment
from cvc_balance.physics.frames import degrees_360, g_mm
from cvc_balance.physics.motion import stamp_seconds
from cvc_balance.physics.unbalance import unbalance_wrench


class LoadCells:
    """The cells of one layout's supports (see the module's description)."""

    def __init__(self, node, model, window_revs, qos, emit):
        """
        Subscribe to the cells of ``model``'s supports.

        ``emit(topic, sec, nanosec, force, torque)`` publishes a rotor-frame wrench (and
        records it when the node records).
        """
        self.node, self.model, self.emit = node, model, emit
        self.fit = SlidingFit(model.supports, model.gravity[2], window_revs)
        self.declared = layout_unbalance(model)
        self.readings = {s.name: 0 for s in model.supports}
        self.found = None           # (estimate, RotorUnbalance identified, residual)
        self._solved_at = 0
        self._subscriptions = [
            node.create_subscription(WrenchStamped, topics.measured_load(s.name),
                                     partial(self._on_reading, s.name), qos, raw=True)
            for s in model.supports]

    def close(self):
        """Stop listening (the layout is no longer in force)."""
        for subscription in self._subscriptions:
            self.node.destroy_subscription(subscription)
        self._subscriptions = []

    def _on_reading(self, support, data):
        """Take a WrenchStamped's CDR bytes (raw: 1 us to read, against rclpy's 20 us)."""
        try:
            sec, nanosec, force, torque = read_wrench_stamped(data)
        except (ValueError, struct.error):
            self.fit.dropped += 1
            return
        moment = torque[:2] if len(self.model.supports) == 1 else None
        if self.fit.reading(support, stamp_seconds(sec, nanosec), force[:2], moment):
            self.readings[support] += 1

    def motion(self, sec, nanosec, angle, omega, alpha):
        """Take a motion sample; at each completed revolution solve and publish."""
        self.fit.motion(stamp_seconds(sec, nanosec), angle, omega, alpha)
        if self.fit.revolutions == self._solved_at or not any(self.readings.values()):
            return
        self._solved_at = self.fit.revolutions
        estimate = self.fit.estimate()
        found = identified_unbalance(self.model, estimate)
        self.found = (estimate, found, residual(found, self.declared))
        if not estimate.identifiable:
            return
        for topic, unbalance in ((topics.IDENTIFIED_UNBALANCE, found),
                                 (topics.UNBALANCE_RESIDUAL, self.found[2])):
            static, couple = unbalance.static.value, unbalance.couple.value
            self.emit(topic, sec, nanosec, *unbalance_wrench(
                (static.real, static.imag), (couple.real, couple.imag), omega))

    @property
    def estimate(self):
        """
        Return the latest fit, for the verdict of record; None when no cell has read yet.

        Before the first whole revolution: an estimate that cannot tell (the layout's
        verdict then stands, labelled so).
        """
        if not any(self.readings.values()):
            return None
        if self.found is None:
            return Estimate.unknown(len(self.model.supports), sum(self.readings.values()))
        return self.found[0]

    def diagnose(self, of_record):
        """
        Return (verdict level, message, values) of what the cells measured, or None.

        ``of_record``: the node's :class:`~cvc_balance.identify.evidence.VerdictOfRecord`
        (made from :attr:`estimate`): its measured verdict, why it cannot tell, and where
        the rotor is not what its layout says, with the identified values behind them.
        """
        values = {f'cell {name} readings': count for name, count in self.readings.items()}
        values['cell readings dropped'] = self.fit.dropped
        if not any(self.readings.values()):
            return None
        if self.found is None or of_record.measured is None:
            return (assessment.NOT_JUDGED, of_record.reason, values)
        estimate, found, diff = self.found
        values.update({'fit window [rev]': min(self.fit.revolutions, self.fit.window_revs),
                       'fit readings': estimate.readings, 'fit sigma [N]': estimate.sigma})
        measured = of_record.measured
        values['measured verdict'] = measured.text
        values['measured static [g mm]'] = g_mm(found.static.amount)
        values['measured static angle [deg]'] = degrees_360(found.static.angle)
        values['measured static 95% radius [g mm]'] = g_mm(found.static.ci95)
        judged = measured.assessment
        for label, (z, got), (_, off), allowed in zip(
                ('I', 'II'), found.planes, diff.planes,
                judged.plane_permissible if judged is not None else (None, None)):
            values.update({f'measured plane {label} [g mm]': g_mm(got.amount),
                           f'measured plane {label} angle [deg]': degrees_360(got.angle),
                           f'measured plane {label} 95% radius [g mm]': g_mm(got.ci95),
                           f'residual plane {label} [g mm]': g_mm(off.amount),
                           f'residual plane {label} angle [deg]': degrees_360(off.angle)})
            if allowed:
                values[f'residual plane {label} / permissible'] = off.amount / allowed
        message = f'measured: {measured.text}'
        if of_record.reason:
            message += f' (not yet the verdict of record: {of_record.reason})'
        if of_record.disagreements:
            message += f'; {of_record.disagreement_text}'
        return of_record.level if of_record.source == 'measured' else measured.level, \
            message, values
