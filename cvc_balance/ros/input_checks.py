"""
The node's checks of its own inputs against each other: units, senses, the cells' supports.

Wires :mod:`cvc_balance.identify.mistakes` to the live input: the joint's recent samples
(position against velocity) and the load cells' static loads (the live fit's biases)
against the layout's weight shares. The result is a second diagnostics status of the
node, and one log line per mistake when it is first seen (and one when all is well again).
"""

from collections import deque

from cvc_balance.identify.mistakes import (cell_mistakes, measured_static_loads,
                                           motion_units, MOTION_WINDOW)
from cvc_balance.physics import assessment

WINDOW = MOTION_WINDOW
"""Motion samples the position/velocity check looks back over (2 s at 1 kHz)."""


class InputChecks:
    """What the inputs say about their own units and wiring (see the module's description)."""

    def __init__(self):
        """Start with no samples and nothing found."""
        self._recent = deque(maxlen=WINDOW)
        self.motion = None          # the last MotionCheck that could tell
        self.findings = ()             # the messages of the last status
        self.reported = frozenset()     # those logged

    def sample(self, time, angle, omega):
        """Take an accepted JointState sample: stamp s, position and velocity as sent."""
        self._recent.append((time, angle, omega))

    def restart(self):
        """Forget the samples (a new time line: a driver restarted, perhaps mended)."""
        self._recent.clear()

    def status(self, active):
        """
        Return (level, message, values) of the checks for the layout in force ``active``.

        Levels of :mod:`cvc_balance.physics.assessment`: WARN when a mistake is found,
        OK otherwise (also while nothing can be told yet: the values say so).
        """
        values, findings, measured = {}, [], {}
        if len(self._recent) > 1:
            check = motion_units(*zip(*self._recent))
            if check is not None:
                self.motion = check
        if self.motion is None:
            values['joint position rate / velocity'] = 'not told yet'
        else:
            values['joint position rate / velocity'] = self.motion.ratio
            values['joint position wraps at'] = self.motion.period or 'no wrap seen'
            if self.motion.finding is not None:
                findings.append(self.motion.finding)
        cells = active.cells
        if cells.found is not None and cells.found[0].identifiable:
            measured = measured_static_loads(cells.model, cells.found[0], cells.readings)
            for name, got in measured.items():
                values[f'cell {name} static load [N]'] = abs(got)
                values[f'cell {name} share of the weight [N]'] = abs(active.shares[name])
            findings += cell_mistakes(active.shares, measured)
        values['input mistakes'] = ' | '.join(f.message for f in findings)
        self.findings = tuple(f.message for f in findings)
        if findings:
            return assessment.WARN, '; '.join(self.findings), values
        agree = (['joint position and velocity (rad, rad/s)'] if self.motion else []) + \
            (["the cells and their supports' shares"] if measured else [])
        return assessment.OK, ('inputs agree: ' + ' and '.join(agree) if agree else
                               'inputs: nothing to check yet (no turn, no fit of the cells)'), \
            values

    def news(self):
        """Return [(severity, text)] to log after :meth:`status`: new mistakes, or all well."""
        found = frozenset(self.findings)
        out = [('warning', f'input mistake? {text}') for text in self.findings
               if text not in self.reported]
        if self.reported and not found:
            out.append(('info', 'inputs agree again'))
        self.reported = found
        return out
