"""
Bearing life: ISO 281's basic rating life from the loads the engine computes.

A support's bearing (:class:`cvc_balance.physics.layout.Bearing`) carries the support's
force (stator frame, N): its radial part Fr = |(F_x, F_y)|, its axial part Fa = |F_z|.
Per sample, the dynamic equivalent load is

    P = X Fr + Y Fa                 (given e: P = Fr while Fa / Fr <= e)

and over a run of variable load and speed (Palmgren-Miner), with dRev the revolutions
between two samples (the angle's step, its whole turns told by the speed: the step
nearest omega dt, either sense) and (P / C)^p taken as the trapezoid over each step:

    revolutions   N   = sum dRev
    damage        D   = sum (P / C)^p dRev            (revolutions at the load C)
    mean load     P_m = C (D / N)^(1/p) = (sum P^p dRev / sum dRev)^(1/p)
    life used         = D / 10^6 / a1                 (1: the whole rating life, a1 L10)
    rating life       = hours / life used             (hours at the run's duty)

At a constant load and speed n (rpm) the rating life is ISO 281's
L10h = a1 (C / P)^p 10^6 / (60 n); with a1 = 1 it is L10h (90 % survive).
The unbalance's cost: the same run of the rotor balanced (:func:`balanced`), compared
(:func:`more_life_used`: "this unbalance uses X % more of the bearing's life").

:class:`LifeCounters` accumulates the bearings of a layout's supports sample by sample
(plain floats, O(1): the live node) or block by block (numpy arrays: replay), carrying
the last sample across blocks. numpy only.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from cvc_balance.physics.engine import loads

MILLION = 1e6
"""Revolutions in ISO 281's unit of life (L10 is in millions of revolutions)."""
PI, TWO_PI = math.pi, 2.0 * math.pi
sqrt = math.sqrt      # one name to look up per sample, not two
HALF_TURN = 0.5 / TWO_PI
"""Half the turns of an angle (rad): the trapezoid's weight."""
HOUR = 3600.0
"""Seconds per hour."""


@dataclass(frozen=True)
class LifeUse:
    """
    What a run did to one bearing: revolutions, damage and the time it took.

    ``revolutions`` turns; ``damage`` sum (P / C)^p dRev (revolutions at the load C);
    ``seconds`` s of the run (between its first and last sample). The rest follows.
    """

    bearing: object
    revolutions: float
    damage: float
    seconds: float

    @property
    def equivalent_load(self):
        """Return P_m, N: the constant load that would do the same damage (None: no turn)."""
        if not self.revolutions > 0.0:
            return None
        return self.bearing.C * (self.damage / self.revolutions) ** (1.0 / self.bearing.exponent)

    @property
    def life_used(self):
        """Return the fraction of the rating life (a1 L10) used: damage / 10^6 / a1."""
        return self.damage / MILLION / self.bearing.a1

    @property
    def hours(self):
        """Return the run's duration, h."""
        return self.seconds / HOUR

    @property
    def rating_life_hours(self):
        """Return the rating life at the run's duty, h: hours / life used (None: no use)."""
        used = self.life_used
        return self.hours / used if used > 0.0 and self.seconds > 0.0 else None

    @property
    def rate(self):
        """Return the life used per hour of the run (None: no time)."""
        return self.life_used / self.hours if self.seconds > 0.0 else None

    def record(self, balanced=None):
        """
        Return it as JSON-able data: equivalent_load_N, life_used, l10_hours, unbalance_share.

        ``balanced``: the same run's LifeUse of the rotor balanced; ``unbalance_share`` is
        :func:`more_life_used` (None without it).
        """
        return {'equivalent_load_N': self.equivalent_load, 'life_used': self.life_used,
                'l10_hours': self.rating_life_hours,
                'unbalance_share': None if balanced is None
                else more_life_used(self, balanced)}


def more_life_used(actual, balanced):
    """
    Return how much more life ``actual`` used than ``balanced`` (LifeUse), as a fraction.

    0.032: "this unbalance uses 3.2 % more of the bearing's life" than the same run of the
    rotor balanced. None when the balanced run used none.
    """
    if not balanced.damage > 0.0:
        return None
    return actual.damage / balanced.damage - 1.0


def balanced(model):
    """
    Return ``model`` (a RotorModel) with its unbalance removed: S_x = S_y = P_xz = P_yz = 0.

    Its centre of mass on the axis and its principal axis along it; mass, S_z and I_zz kept.
    """
    return replace(model, s_x=0.0, s_y=0.0, p_xz=0.0, p_yz=0.0)


def equivalent_load(bearing, radial, axial):
    """
    Return ISO 281's dynamic equivalent load P, N (arrays or floats).

    ``radial`` Fr >= 0 and ``axial`` Fa >= 0, N. P = X Fr + Y Fa; given ``bearing.e``, P = Fr
    while Fa <= e Fr (ISO 281's factors switch at Fa / Fr = e).
    """
    combined = bearing.X * radial + bearing.Y * axial
    if bearing.e is None:
        return combined
    return np.where(axial > bearing.e * radial, combined, radial)


def load_rate(bearing, force):
    """
    Return (P / C)^p per sample: the damage per revolution, revolutions at C per turn.

    ``force``: (n, 3) support forces, N (stator frame: x, y radial, z axial).
    """
    force = np.asarray(force, dtype=float)
    radial = np.hypot(force[:, 0], force[:, 1])
    ratio = equivalent_load(bearing, radial, np.abs(force[:, 2])) / bearing.C
    if bearing.type == 'ball':
        return ratio * ratio * ratio
    return ratio ** bearing.exponent


def turns(time, angle, omega):
    """
    Return the revolutions between consecutive samples, (n - 1,), each >= 0.

    ``time`` s, ``angle`` rad (wrapped or not), ``omega`` rad/s: the angle's step, plus the
    whole turns that bring it nearest the speed's omega dt (trapezoid).
    """
    step = np.diff(angle)
    expected = 0.5 * (omega[1:] + omega[:-1]) * np.diff(time)
    step = step + TWO_PI * np.round((expected - step) / TWO_PI)
    return np.abs(step) / TWO_PI


class LifeCounter:
    """
    The life one bearing used: revolutions, damage and seconds, accumulated.

    ``revolutions``, ``damage`` (see :class:`LifeUse`) and ``seconds`` start from the
    values given (a count carried over from before). Fed by :class:`LifeCounters`.
    """

    __slots__ = ('name', 'bearing', 'revolutions', 'damage', 'seconds', 'last_rate', 'cube',
                 'exponent', 'inverse')

    def __init__(self, name, bearing, revolutions=0.0, damage=0.0, seconds=0.0):
        """Start counting bearing ``bearing`` of support ``name`` from the values given."""
        self.name, self.bearing = name, bearing
        self.revolutions, self.damage, self.seconds = revolutions, damage, seconds
        self.last_rate = None         # (P / C)^p of the last sample counted
        self.cube = bearing.type == 'ball'
        self.exponent = bearing.exponent
        self.inverse = 1.0 / bearing.C

    def use(self):
        """Return what it counted as a :class:`LifeUse`."""
        return LifeUse(self.bearing, self.revolutions, self.damage, self.seconds)


class LifeCounters:
    """
    The life used by the bearings of a layout's supports (those that describe one).

    Each sample's support forces come from the engine (:func:`sample_loads` one at a time,
    :func:`loads` in blocks); the steps between samples from their time, angle and speed.
    """

    def __init__(self, supports, counters=None, last=None):
        """
        Count the bearings of ``supports`` (a layout's).

        ``counters``: {support name: LifeCounter} to go on from where a support keeps its
        bearing (a layout change, a count read back); ``last``: the last sample (time s,
        angle rad, omega rad/s) counted before (:attr:`last`), so the step from it counts.
        """
        counters = counters or {}
        self.counters = {}
        for support in supports:
            if support.bearing is None:
                continue
            counter = counters.get(support.name)
            if counter is None or counter.bearing != support.bearing:
                counter = LifeCounter(support.name, support.bearing)
            self.counters[support.name] = counter
        # The step from the last sample counts only when every bearing has its last load.
        known = all(c.last_rate is not None for c in self.counters.values())
        self.last = last if known else None
        self._constants = tuple(
            (c, name, c.bearing.X, c.bearing.Y, c.bearing.e, c.inverse, c.cube, c.exponent)
            for name, c in self.counters.items())        # what add_sample reads, at hand
        self._half_turns = self._seconds = 0.0     # shared by the counters, not yet added

    def __bool__(self):
        """Tell whether any support has a bearing to count."""
        return bool(self.counters)

    def flush(self):
        """Add the revolutions and seconds counted one sample at a time to every counter."""
        if self._half_turns or self._seconds:
            for counter in self.counters.values():
                counter.revolutions += 2.0 * self._half_turns
                counter.seconds += self._seconds
            self._half_turns = self._seconds = 0.0

    def restart(self):
        """Forget the last sample: the next starts anew (a new time line, a gap)."""
        self.flush()
        self.last = None
        for counter in self.counters.values():
            counter.last_rate = None

    def add_sample(self, time, angle, omega, supports):
        """
        Count one sample: plain floats, O(1) (the live node).

        ``time`` s, ``angle`` rad, ``omega`` rad/s; ``supports``: {name: (force, moment)}
        as :class:`~cvc_balance.physics.engine.SampleLoads` holds them, stator frame.
        The revolutions and seconds reach the counters at :meth:`flush` (:meth:`uses`
        flushes).
        """
        last = self.last
        self.last = (time, angle, omega)
        if last is None:
            half = None
        else:
            elapsed = time - last[0]
            step = angle - last[1]
            drift = (omega + last[2]) * 0.5 * elapsed - step
            if drift > PI or drift < -PI:      # whole turns (a wrap) in between
                step += TWO_PI * round(drift / TWO_PI)
            half = (step if step >= 0.0 else -step) * HALF_TURN      # half the turns
            self._half_turns += half
            self._seconds += elapsed
        for counter, name, x, y, e, inverse, cube, exponent in self._constants:
            fx, fy, fz = supports[name][0]
            radial = sqrt(fx * fx + fy * fy)
            axial = fz if fz >= 0.0 else -fz
            if e is None or axial > e * radial:
                radial = x * radial + y * axial
            ratio = radial * inverse
            rate = ratio * ratio * ratio if cube else ratio ** exponent
            if half is not None:
                counter.damage += (rate + counter.last_rate) * half
            counter.last_rate = rate

    def add(self, time, angle, omega, support_force):
        """
        Count a block of samples: arrays (replay, the view).

        ``time`` s, ``angle`` rad, ``omega`` rad/s, (n,); ``support_force``: {name: (n, 3)
        N} as :class:`~cvc_balance.physics.engine.Loads` holds them. Returns {name: (n,)
        cumulative life used at each sample} (for plots).
        """
        self.flush()
        time, angle, omega = (np.asarray(v, dtype=float) for v in (time, angle, omega))
        if not len(time):
            return {name: np.zeros(0) for name in self.counters}
        joined = self.last is not None       # the step from the last sample counts too
        if joined:
            time, angle, omega = (np.concatenate([[b], v]) for b, v in zip(self.last,
                                                                           (time, angle, omega)))
        steps = turns(time, angle, omega)
        elapsed = np.diff(time)
        revolutions, seconds = float(steps.sum()), float(elapsed.sum())
        out = {}
        for name, counter in self.counters.items():
            rate = load_rate(counter.bearing, support_force[name])
            if joined:       # every counter has its last load (see __init__, restart)
                rate = np.concatenate([[counter.last_rate], rate])
            damage = np.cumsum(0.5 * (rate[1:] + rate[:-1]) * steps)
            used = (counter.damage + np.concatenate([[0.0], damage])) / MILLION \
                / counter.bearing.a1
            counter.damage += float(damage[-1]) if len(damage) else 0.0
            counter.revolutions += revolutions
            counter.seconds += seconds
            counter.last_rate = float(rate[-1])
            out[name] = used[1:] if joined else used
        self.last = (float(time[-1]), float(angle[-1]), float(omega[-1]))
        return out

    def uses(self):
        """Return {support name: LifeUse} of what was counted."""
        self.flush()
        return {name: counter.use() for name, counter in self.counters.items()}


def steady_rates(model, omega, points=720):
    """
    Return {support name: mean (P / C)^p over a revolution} at constant ``omega``.

    ``model``: a RotorModel; ``omega`` rad/s, alpha 0, the layout's gravity; the mean over
    ``points`` angles (the trapezoid on a periodic function: converges geometrically).
    The rating life at that speed is a1 10^6 / (mean x revolutions per hour) hours.
    """
    angle = np.linspace(0.0, TWO_PI, points, endpoint=False)
    result = loads(model, angle, omega, 0.0)
    return {s.name: float(np.mean(load_rate(s.bearing, result.support_force[s.name])))
            for s in model.supports if s.bearing is not None}


def steady_life_hours(bearing, mean_rate, omega):
    """Return the rating life (h) of ``bearing`` at a mean (P / C)^p turning at ``omega``."""
    per_hour = abs(omega) * HOUR / TWO_PI
    if not mean_rate > 0.0 or not per_hour > 0.0:
        return None
    return bearing.a1 * MILLION / (mean_rate * per_hour)
