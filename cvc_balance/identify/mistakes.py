"""
Mistakes in wiring sensors to the monitor, told from the data: units, senses, supports.

Two checks, numpy only, for the live node (on its recent input) and offline commands:

- :func:`motion_units`: the joint's position against its velocity. Over a window, the
  angle's rate (its steps, unwrapped at the period the position wraps at) is compared with
  the velocity (trapezoid over the same steps); a ratio of 57.3 says the position is in
  degrees, 1/9.55 that the velocity is in rpm, -1 that the senses disagree; a position
  that wraps at 360 is named too.
- :func:`cell_mistakes`: each load cell's static load (the constant the live fit finds
  beside the unbalance: the cell's bias, stator frame) against the layout's weight share
  of its support (:func:`static_loads`, from the engine): a sign reversed, a scale off,
  kN for N, kgf for N, axes turned, or the share of another support (cells swapped or on
  the wrong support).

Each returns :class:`Finding` objects: ``cause`` (a short key), ``message`` (one line
naming the mistake, for a person) and the figure it rests on. Offline commands check a
whole run as the node checks its recent input: :func:`run_motion_findings` over windows
of :data:`MOTION_WINDOW` samples, :func:`measured_static_loads` of a fitted segment.
"""

import cmath
from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.identify.batch import channels
from cvc_balance.physics.engine import sample_loads

DEGREES_PER_RADIAN = 180.0 / math.pi
"""57.2958: a position in degrees advances this many times faster than in radians."""
RPM_PER_RAD_S = 30.0 / math.pi
"""9.5493: a speed in rpm reads this many times its value in rad/s."""
GRAVITY = 9.80665
"""m/s^2: a force in kgf reads 1/9.80665 of its value in N."""

RATIO_TOLERANCE = 0.1
"""Relative tolerance of a named ratio (57.3 x, 1/9.55 x, ...)."""
MIN_TURN = 1.0
"""rad the velocity must have turned over the window (the ratio is judged from it)."""
MIN_STEPS = 20
"""Steps a window must hold to be judged."""
MAX_STEP = math.pi / 2
"""rad: a step over which the velocity turns further (a pause) is left out: it may alias."""
SHARE_TOLERANCE = 0.25
"""A cell's static load may differ from its support's share by this fraction of the share..."""
ZERO_TOLERANCE = 0.05
"""...plus this fraction of the rotor's radial weight (a cell's zero offset)."""
ANGLE_TOLERANCE = math.radians(25.0)
"""rad: a cell whose static load is turned less than this from its share is not "turned"."""
MIN_SHARE = 0.2
"""Shares smaller than this fraction of the rotor's radial weight are not judged."""
MOTION_WINDOW = 2000
"""Motion samples the position/velocity check looks at once (the node's: 2 s at 1 kHz)."""
RUN_WINDOWS = 16
"""Most windows of a recorded run checked (evenly spread over it)."""


@dataclass(frozen=True)
class Finding:
    """A mistake found: ``cause`` (a short key), ``message`` (one line), its ``figure``."""

    cause: str
    message: str
    figure: float


@dataclass(frozen=True)
class MotionCheck:
    """
    What :func:`motion_units` measured.

    ``ratio``: the angle's rate over the velocity; ``period``: what the position wraps at
    (2 pi, 360, another value, or None when no wrap was seen); ``turned``: rad by the
    velocity over the steps judged; ``finding``: the mistake, or None when the position and
    the velocity agree (radians and rad/s).
    """

    ratio: float
    period: float
    turned: float
    finding: Finding


def wrap_period(steps):
    """
    Return what a position wraps at: 2 pi, 360, the jump seen, or None when it does not wrap.

    ``steps``: the position's successive differences (pauses left out). A wrap is a step
    much longer than the typical one (three times, and more than pi / 2); the period is the
    wrap's length from the step its neighbours make, taken as 2 pi or 360 within 10 %, and
    as a power of two (an encoder's counts) within 1 %.
    """
    steps = np.asarray(steps, float)
    if len(steps) < 3:
        return None
    typical = float(np.median(np.abs(steps)))
    big = np.abs(steps) > max(3.0 * typical, math.pi / 2)
    if not big.any():
        return None
    # A wrap between two ordinary steps (noise at the boundary can wrap back and forth).
    inner = np.flatnonzero(big[1:-1]) + 1
    alone = inner[~big[inner - 1] & ~big[inner + 1]]
    if len(alone):
        beside = 0.5 * (steps[alone - 1] + steps[alone + 1])
        period = float(np.median(np.abs(steps[alone] - beside)))
    else:
        period = float(np.median(np.abs(steps[big]))) + typical
    for known in (2 * math.pi, 360.0):
        if abs(period - known) <= 0.1 * known:
            return known
    counts = 2.0 ** round(math.log2(period)) if period > 0 else 0.0
    return counts if abs(period - counts) <= 0.01 * counts else period


def motion_units(time, angle, omega):
    """
    Compare a joint's position with its velocity over a window; return a MotionCheck or None.

    ``time`` s (increasing), ``angle`` the position as sent (rad if right), ``omega`` the
    velocity as sent (rad/s if right). Steps over which the velocity turns more than
    :data:`MAX_STEP` (pauses) are left out. None when the window cannot tell: too few
    steps, the velocity turned less than :data:`MIN_TURN` rad, or the position moves more
    than 1/8 of its period a step (2 pi if it is not seen to wrap: samples too sparse for
    the speed, the steps may alias).
    """
    time, angle, omega = (np.asarray(a, float) for a in (time, angle, omega))
    if len(time) < MIN_STEPS + 1:
        return None
    steps, spacing = np.diff(angle), np.diff(time)
    implied = 0.5 * (omega[1:] + omega[:-1]) * spacing
    keep = (np.abs(implied) <= MAX_STEP) & np.isfinite(steps)
    # The wrap is seen on the regular steps: one over a pause holds motion besides.
    period = wrap_period(steps[keep & (spacing <= 5.0 * np.median(spacing))])
    if period is not None:
        steps = np.remainder(steps + period / 2, period) - period / 2
    # What is left a jump was not explained by a wrap seen (one over a pause, a glitch).
    keep &= np.abs(steps) <= max(3.0 * np.median(np.abs(steps[keep])) if keep.any() else 0.0,
                                 math.pi / 2)
    turned = float(implied[keep].sum())
    if keep.sum() < MIN_STEPS or abs(turned) < MIN_TURN:
        return None
    if np.median(np.abs(steps[keep])) > (period or 2 * math.pi) / 8:
        return None             # too sparse for the speed: the steps may alias
    ratio = float(steps[keep].sum()) / turned
    return MotionCheck(ratio, period, turned, _motion_finding(ratio, period))


def run_motion_findings(time, angle, omega, window=MOTION_WINDOW, most=RUN_WINDOWS):
    """
    Return [(Finding, windows it was found in, windows that could tell)] of a recorded run.

    :func:`motion_units` over up to ``most`` windows of ``window`` samples spread evenly
    over the run (as the node looks at its last ``window``); one entry per cause, its
    first window's Finding. ``time`` s, ``angle`` and ``omega`` as sent.
    """
    n = len(time)
    starts = np.unique(np.linspace(0, max(n - window, 0), most).astype(np.int64))
    found, told = {}, 0
    for start in starts.tolist():
        check = motion_units(time[start:start + window], angle[start:start + window],
                             omega[start:start + window])
        if check is None:
            continue
        told += 1
        if check.finding is not None:
            finding, count = found.get(check.finding.cause, (check.finding, 0))
            found[check.finding.cause] = (finding, count + 1)
    return [(finding, count, told) for finding, count in found.values()]


def _near(value, target):
    return abs(value - target) <= RATIO_TOLERANCE * abs(target)


def _motion_finding(ratio, period):
    """Name what a ratio (and the wrap period) says, or return None when all is well."""
    size = abs(ratio)
    sense = '' if ratio > 0 else '; and its sign is opposite to the velocity\'s'
    wraps = '' if period in (None, 2 * math.pi) else f', and it wraps at {period:.4g}'
    if _near(size, 1.0):
        if period == 360.0:
            return Finding('wraps at 360', 'joint position wraps at 360 and its rate equals '
                           'the velocity: both look like degrees (deg, deg/s), not rad and '
                           f'rad/s{sense}', ratio)
        if ratio < 0:
            return Finding('reversed', 'joint velocity has the opposite sign of the '
                           "position's rate: the senses disagree (ratio -1)", ratio)
        if period is None or period == 2 * math.pi:
            return None
        return Finding('wraps', f'joint position wraps at {period:.4g}, not 2 pi: it is not '
                       'radians', ratio)
    if _near(size, DEGREES_PER_RADIAN):
        return Finding('degrees', 'joint position looks like degrees: its rate is '
                       f'{size:.1f} x the velocity{wraps}{sense}', ratio)
    if _near(size, 1.0 / RPM_PER_RAD_S):
        return Finding('rpm', 'joint velocity looks like rpm: it is '
                       f"{1.0 / size:.2f} x the position's rate{wraps}{sense}", ratio)
    if _near(size, 1.0 / DEGREES_PER_RADIAN):
        return Finding('deg/s', 'joint velocity looks like degrees/s: it is '
                       f"{1.0 / size:.1f} x the position's rate{wraps}{sense}", ratio)
    if _near(size, DEGREES_PER_RADIAN / RPM_PER_RAD_S):
        return Finding('degrees and rpm', 'joint position looks like degrees and velocity '
                       f'like rpm: the position\'s rate is {size:.2f} x the velocity{wraps}'
                       f'{sense}', ratio)
    return Finding('ratio', f"joint position's rate is {ratio:.3g} x the velocity (units, "
                   f'a gear ratio or another joint?){wraps}', ratio)


def static_loads(model):
    """
    Return {support name: complex N}: the layout's weight share of each support.

    The force (x + i y, stator frame) a cell under the support reads at rest, averaged
    over a turn: the engine's support load at omega = alpha = 0 at four angles (what
    turns with the rotor cancels). It is the constant the fit finds as the cell's bias.
    """
    shares = {support.name: 0j for support in model.supports}
    for q in (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi):
        for name, (force, _) in sample_loads(model, q, 0.0, 0.0).supports.items():
            shares[name] += 0.25 * complex(force[0], force[1])
    return shares


def measured_static_loads(model, estimate, read):
    """
    Return {support name: complex N}: the static load each cell reads (its fitted bias).

    ``estimate``: a fit of ``model``'s cells (identifiable); ``read``: {support name:
    readings taken}, the cells without readings left out.
    """
    layout = channels(model.supports)
    return {support.name: estimate.biases[layout.index((k, 'force'))]
            for k, support in enumerate(model.supports) if read.get(support.name)}


def _matches(measured, expected, weight):
    """Whether a measured static load is ``expected`` within the tolerances (N)."""
    return abs(measured - expected) <= SHARE_TOLERANCE * abs(expected) + ZERO_TOLERANCE * weight


def cell_mistakes(expected, measured):
    """
    Return [Finding]: the cells whose static load is not their support's share.

    ``expected``: {support: complex N} (:func:`static_loads`); ``measured``: {support:
    complex N} the cells' static loads (the fit's biases) for the cells that read. A
    cell matches when it is within :data:`SHARE_TOLERANCE` of its share plus
    :data:`ZERO_TOLERANCE` of the rotor's radial weight (the shares' sum); shares under
    :data:`MIN_SHARE` of that weight are not judged (a vertical axis carries no radial
    weight). A cell that reads another support's share is named so, two that read each
    other's as swapped.
    """
    weight = abs(sum(expected.values()))
    judged = {name: value for name, value in measured.items()
              if name in expected and abs(expected[name]) >= MIN_SHARE * weight > 0.0}
    elsewhere = {}
    findings = []
    for name, got in judged.items():
        share = expected[name]
        if _matches(got, share, weight):
            continue
        others = [other for other, value in expected.items() if other != name
                  and not _matches(value, share, weight) and _matches(got, value, weight)]
        if others:
            elsewhere[name] = others[0]
        else:
            findings.append(_cell_finding(name, got, share, weight))
    swapped = set()
    for name, other in elsewhere.items():
        if elsewhere.get(other) == name and name not in swapped:
            swapped.update((name, other))
            findings.append(Finding('swapped', f'cells {name} and {other} look swapped: '
                                    f"{name} reads the {other} support's static load "
                                    f'({abs(judged[name]):.0f} N where {name} carries '
                                    f'{abs(expected[name]):.0f} N) and {other} reads '
                                    f"{name}'s", abs(judged[name] / expected[name])))
    for name, other in elsewhere.items():
        if name not in swapped:
            findings.append(Finding('wrong support', f'cell {name} reads the {other} '
                                    f"support's static load ({abs(judged[name]):.0f} N "
                                    f'where {name} carries {abs(expected[name]):.0f} N): '
                                    'on the wrong support?', abs(judged[name] / expected[name])))
    return findings


def _cell_finding(name, got, share, weight):
    """Name what is wrong with one cell's static load (not its support's share)."""
    ratio = got / share
    size, turned = abs(ratio), math.degrees(cmath.phase(ratio))
    figures = f'({abs(got):.4g} N where its support carries {abs(share):.4g} N)'
    if _matches(-got, share, weight):
        return Finding('sign', f"cell {name} reads its support's static load with the sign "
                       f'reversed {figures}', ratio.real)
    for scale, cause, words in ((1e-3, 'kN', '1/1000'), (1.0 / GRAVITY, 'kgf', '1/9.81')):
        if _matches(got / scale, share, weight):
            return Finding(cause, f"cell {name} reads {words} of its support's static load: "
                           f'{cause} for N? {figures}', size)
    if abs(turned) <= math.degrees(ANGLE_TOLERANCE):
        return Finding('scale', f"cell {name}'s scale looks off: it reads {size:.3g} x its "
                       f"support's static load {figures}", size)
    if abs(size - 1.0) <= SHARE_TOLERANCE:
        return Finding('axes', f"cell {name}'s axes look turned by {turned:.0f} deg: its "
                       f"static load points elsewhere than its support's {figures}", turned)
    return Finding('static load', f"cell {name} reads {size:.3g} x its support's static "
                   f'load, turned by {turned:.0f} deg {figures}', size)
