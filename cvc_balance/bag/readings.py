"""
The 1x readings of a bag's vibration channels against its keyphasor, per steady stretch.

What a field balancing instrument shows: for every stretch at steady speed (judged over
several revolutions of the keyphasor's marks, :func:`cvc_balance.physics.keyphasor.
steady_stretches`), each channel's once-per-revolution amplitude and phase, fitted over
the stretch's whole revolutions by :func:`cvc_balance.field.order_tracking.track` with the
rotor angle interpolated between the marks (0 at each mark).

**Phase** (degrees, 0-360) is the phase LAG from the mark to the channel's first positive
peak, as most instruments give it (shared/domain/FACTS.md, "Field balancing practice"):
the angle the rotor turns after the mark before the 1x component peaks. In
order_tracking's terms, x ~ c + |X| cos(q + arg X) peaks at q = -arg X, so the lag is
-arg X mod 360 (order_tracking's ``phase`` read in the other sense). The 95 % radius is
sqrt(chi2_2(0.95)) times the phasor's standard error (circular), in the channel's unit.
Times s since the epoch (the keyphasor's clock), speeds rad/s.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from cvc_balance.bag.channels import channel_samples, read_keyphasor, vibration_channels
from cvc_balance.bag.mcap_reader import BagError
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.field import SteadyWindow, track
from cvc_balance.field.influence import CHI2_2DOF_95
from cvc_balance.field.order_tracking import DEFAULT_TOLERANCE
from cvc_balance.physics.keyphasor import MIN_STRETCH_REVS, steady_stretches

RADIUS_95 = math.sqrt(CHI2_2DOF_95)
"""A circular 95 % radius in standard errors (2.448)."""


@dataclass(frozen=True)
class ChannelReading:
    """One channel's 1x over a stretch: amplitude and 95 % radius (its unit), lag deg."""

    name: str
    unit: str
    amplitude: float
    phase_deg: float
    ci95: float
    samples: int
    phasor: object


@dataclass(frozen=True)
class StretchReadings:
    """A steady stretch (``start``/``end`` s, ``speed`` rad/s, ``revolutions``) and readings."""

    start: float
    end: float
    speed: float
    revolutions: int
    channels: list


@dataclass
class BagReadings:
    """The readings of a bag: its keyphasor, stretches, and what could not be read."""

    bag: str
    keyphasor: object
    segments: list
    problems: list = field(default_factory=list)


def phase_lag_deg(phasor):
    """Return the phase lag (deg, [0, 360)) from the mark to the 1x peak of a Phasor."""
    return (-math.degrees(phasor.phase)) % 360.0


def bag_readings(bag_path, keyphasor=None, edge='rising', threshold=None, units=None,
                 tolerance=DEFAULT_TOLERANCE, min_revolutions=MIN_STRETCH_REVS):
    """
    Return the :class:`BagReadings` of a bag (see the module's description).

    ``keyphasor`` its topic (default ``keyphasor``), ``edge`` and ``threshold`` for a
    sampled tach; ``units`` {topic: unit}; ``tolerance`` the relative speed band of a
    steady stretch. Raises BagError naming what is missing.
    """
    bag = open_bag(bag_path)
    tach = read_keyphasor(bag, keyphasor, edge, threshold)
    sources = vibration_channels(bag, units, exclude=(tach.channel.topic,))
    if not sources:
        raise BagError(f'{bag.path}: no vibration channel (std_msgs/Float64, '
                       'geometry_msgs/Vector3Stamped or sensor_msgs/Imu topics besides the '
                       f'keyphasor {tach.channel.topic})')
    marks = tach.marks
    stretches = steady_stretches(marks, tolerance, min_revolutions)
    if not stretches:
        speed = marks.mark_speed()
        speed = speed[np.isfinite(speed)]
        raise BagError(f'{bag.path}: no steady stretch of {min_revolutions} revolutions '
                       f'within +-{tolerance:.1%} of its speed: the keyphasor reads '
                       f'{speed.min():.4g}-{speed.max():.4g} rad/s over {marks.revolutions} '
                       'revolutions')
    problems = list(bag.problems) + tach.problems
    if marks.missed or marks.doubled or marks.irregular:
        problems.append(tach.summary())
    mark_angle = 2.0 * math.pi * np.arange(len(marks.time))
    columns, cache = [], {}
    for source in sources:
        samples = channel_samples(bag, source, cache)
        if samples.rejected and source.axis in (None, 0):
            problems.append(f'{source.channel.topic}: {samples.rejected} messages not '
                            f'readable as {source.channel.msg_type}; left out')
        columns.append((source, tach.seconds(samples.time), samples.values))
    segments = []
    for stretch in stretches:
        window = SteadyWindow(stretch.start, stretch.end, stretch.speed, stretch.revolutions,
                              0.0)
        readings = []
        for source, time, values in columns:
            try:
                phasor = track(time, values, marks.time, mark_angle, window)
            except ValueError as error:
                problems.append(f'channel {source.name} over {_absolute(tach, stretch.start):.3f}'
                                f'-{_absolute(tach, stretch.end):.3f} s: {error}')
                continue
            readings.append(ChannelReading(source.name, source.unit, phasor.amplitude,
                                           phase_lag_deg(phasor), RADIUS_95 * phasor.sigma,
                                           phasor.samples, phasor))
        segments.append(StretchReadings(_absolute(tach, stretch.start),
                                        _absolute(tach, stretch.end), stretch.speed,
                                        stretch.revolutions, readings))
    return BagReadings(str(bag_path), tach, segments, problems)


def _absolute(tach, seconds):
    """Return s since the epoch of ``seconds`` after the keyphasor's origin."""
    return tach.origin_ns * 1e-9 + seconds


def readings_summary(readings):
    """Return the JSON object of :class:`BagReadings` (the command's ``--json``)."""
    return {'segments': [{
        'from': s.start, 'to': s.end, 'speed': s.speed, 'revolutions': s.revolutions,
        'channels': [{'name': c.name, 'unit': c.unit, 'amplitude': c.amplitude,
                      'phase_deg': c.phase_deg, 'ci95': c.ci95} for c in s.channels]}
        for s in readings.segments]}
