"""
The node's load cells: each support's ``supports/<name>/measured_load``, the live fit, its outputs.

One :class:`LoadCells` per layout in force (its supports name the cells). Readings go to
an O(1) sliding fit over revolutions (:class:`cvc_balance.identify.live.SlidingFit`);
at each completed revolution the fit is solved and ``identified_unbalance`` and
``unbalance_residual`` are published (WrenchStamped, rotor frame, the convention of
``unbalance``: force U omega^2, torque omega^2 (-P_yz, P_xz, 0) about the centre of
mass, at the speed of the sample that completed the revolution). The diagnostics get
the identified verdict (the one definition, ``judge_balance``, on the measured rotor),
the residual per plane against ``residual_warn`` of its permissible share, and the fit.
"""

from functools import partial

from geometry_msgs.msg import WrenchStamped

from cvc_balance.identify.estimate import (identified_unbalance, layout_unbalance, residual,
                                           rotor_with)
from cvc_balance.identify.live import SlidingFit
from cvc_balance.messages import topics
from cvc_balance.physics import assessment
from cvc_balance.physics.frames import degrees, g_mm
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
                                     partial(self._on_reading, s.name), qos)
            for s in model.supports]

    def close(self):
        """Stop listening (the layout is no longer in force)."""
        for subscription in self._subscriptions:
            self.node.destroy_subscription(subscription)
        self._subscriptions = []

    def _on_reading(self, support, msg):
        stamp, wrench = msg.header.stamp, msg.wrench
        moment = (wrench.torque.x, wrench.torque.y) if len(self.model.supports) == 1 else None
        if self.fit.reading(support, stamp.sec + stamp.nanosec * 1e-9,
                            (wrench.force.x, wrench.force.y), moment):
            self.readings[support] += 1

    def motion(self, sec, nanosec, angle, omega, alpha):
        """Take a motion sample; at each completed revolution solve and publish."""
        self.fit.motion(sec + nanosec * 1e-9, angle, omega, alpha)
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

    def diagnose(self, top_speed, grade, warn_fraction, residual_warn):
        """
        Return (verdict level, message, values) of what the cells measured, or None.

        Levels of :mod:`cvc_balance.physics.assessment`: the measured rotor's verdict;
        WARN at least when a plane's residual is beyond ``residual_warn`` of its
        permissible share and beyond its 95 % radius (the layout does not describe the
        rotor).
        """
        values = {f'cell {name} readings': count for name, count in self.readings.items()}
        values['cell readings dropped'] = self.fit.dropped
        if self.found is None:
            return None if not any(self.readings.values()) else (
                assessment.NOT_JUDGED, 'load cells: not a whole revolution yet', values)
        estimate, found, diff = self.found
        values.update({'fit window [rev]': min(self.fit.revolutions, self.fit.window_revs),
                       'fit readings': estimate.readings})
        if not estimate.identifiable:
            return (assessment.NOT_JUDGED, 'load cells: the readings cannot tell the '
                    'unbalance yet (too few readings, no rotation or no speed)', values)
        values['fit sigma [N]'] = estimate.sigma
        measured = rotor_with(self.model, estimate.static, estimate.products)
        verdict = assessment.judge_balance(measured, top_speed, grade, warn_fraction)
        level, message = verdict.level, f'measured: {verdict.text}'
        judged = verdict.assessment
        values['measured verdict'] = verdict.text
        values['measured static [g mm]'] = g_mm(found.static.amount)
        values['measured static angle [deg]'] = degrees(found.static.angle)
        values['measured static 95% radius [g mm]'] = g_mm(found.static.ci95)
        worst = []
        for label, (z, got), (_, off), allowed in zip(
                ('I', 'II'), found.planes, diff.planes,
                judged.plane_permissible if judged is not None else (None, None)):
            values.update({f'measured plane {label} [g mm]': g_mm(got.amount),
                           f'measured plane {label} angle [deg]': degrees(got.angle),
                           f'measured plane {label} 95% radius [g mm]': g_mm(got.ci95),
                           f'residual plane {label} [g mm]': g_mm(off.amount),
                           f'residual plane {label} angle [deg]': degrees(off.angle)})
            if allowed:
                fraction = off.amount / allowed
                values[f'residual plane {label} / permissible'] = fraction
                if fraction > residual_warn and off.amount > off.ci95:
                    worst.append(f'plane {label} {g_mm(off.amount):.0f} g mm at '
                                 f'{degrees(off.angle):.0f} deg ({fraction:.2f} of its '
                                 'permissible)')
        if worst:
            message += '; the rotor is not what its layout says: residual ' + ', '.join(worst)
            if level in (assessment.OK, assessment.NOT_JUDGED):
                level = assessment.WARN
        return level, message, values
