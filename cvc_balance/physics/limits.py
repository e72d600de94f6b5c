"""
The range of every number the package accepts from people: one table, units and reasons.

A number can be valid by its sign and still mean nothing (a grade of 5e-324 mm/s, two
bearings 5e-324 m apart, a weight of 1e-300 kg): such values divide to inf or nan far
from where they were typed. Each quantity here has a range that every reader (layouts,
tolerance files, scenarios, the commands' options) checks, with SI units (the grade in
mm/s, as ISO 21940-11 names it) and why. Within these ranges the engine's loads, the
unbalance, the verdict, correction masses and the plausibility warnings stay finite
(``test/test_validation_limits.py`` draws layouts at the limits and checks it).

:func:`check` raises ``ValueError`` (or the reader's own error type) with one line naming
the field, the value, the range and its unit.
"""

from dataclasses import dataclass
import math
import os

MAX_MAGNITUDE = 1e12
"""Largest magnitude of a layout's numbers (kg, m, kg m^2, m/s^2): products stay finite."""
MAX_ANGLE = 1e9
"""Largest |angle|, rad: within it the angles' reduction is exact (1e-32, measured to 1e12)."""


@dataclass(frozen=True)
class Limit:
    """
    The accepted range of one quantity: ``low`` <= value <= ``high``, in ``unit``.

    ``reason``: why the range is what it is (said in the error, briefly).
    """

    low: float
    high: float
    unit: str
    reason: str

    def describe(self):
        """Say the range for people, e.g. 'from 0.1 to 4000 mm/s'."""
        unit = f' {self.unit}' if self.unit else ''
        if self.low == -self.high:
            return f'within +-{_text(self.high)}{unit}'
        return f'from {_text(self.low)} to {_text(self.high)}{unit}'

    def message(self, where, value):
        """Return the one line saying that ``value`` at ``where`` is out of this range."""
        unit = f' {self.unit}' if self.unit else ''
        shown = str(value)
        if isinstance(value, float):      # the shorter of two texts that read back as it
            short = f'{value:g}'
            shown = short if float(short) == value and len(short) <= len(repr(value)) \
                else repr(value)
        return f'{where} must be {self.describe()} ({self.reason}), got {shown}{unit}'

    def contains(self, value):
        """Tell whether ``value`` (a number) is within the range (NaN is not)."""
        return self.low <= value <= self.high


def _text(number):
    """Return a limit's end for people: whole numbers whole, others as %g."""
    return str(number) if isinstance(number, int) else f'{number:g}'


def check(value, limit, where, error=ValueError):
    """
    Return ``value`` when ``limit`` contains it, else raise ``error`` naming it.

    ``value``: a finite number (the caller checked its type); ``where``: the field, as the
    error should name it ('layout: field balancing.grade').
    """
    if not limit.contains(value):
        raise error(limit.message(where, value))
    return value


# -- layouts ------------------------------------------------------------------------------

MASS = Limit(1e-6, MAX_MAGNITUDE, 'kg', 'a milligram or more: lighter is no part, and '
             'divides mass ratios to inf')
"""A component's mass."""
RADIUS = Limit(0.0, MAX_MAGNITUDE, 'm', '0 on the spin axis')
"""A component's radius: where its centre of mass is, never a divisor."""
POSITION = Limit(-MAX_MAGNITUDE, MAX_MAGNITUDE, 'm', 'products of positions stay finite')
"""An axial position z: a component's, a support's, a correction plane's."""
ANGLE = Limit(-MAX_ANGLE, MAX_ANGLE, 'rad', 'the reduction to a turn stays exact')
"""An angle, rad."""
ANGLE_DEG = Limit(-math.degrees(MAX_ANGLE), math.degrees(MAX_ANGLE), 'deg',
                  'the reduction to a turn stays exact')
"""An angle, degrees (``angle_deg``, ``angles_deg``)."""
SHAPE_LENGTH = Limit(1e-6, MAX_MAGNITUDE, 'm', 'a micrometre or more: no solid part is '
                     'thinner, and a density is the mass over the volume')
"""A shape's radius, length or size."""
INERTIA = Limit(-MAX_MAGNITUDE, MAX_MAGNITUDE, 'kg m^2', 'products stay finite')
"""An inertia tensor's element."""
GRAVITY = Limit(-MAX_MAGNITUDE, MAX_MAGNITUDE, 'm/s^2', 'products stay finite')
"""A component of gravity."""
SPACING = Limit(1e-3, 2.0 * MAX_MAGNITUDE, 'm', 'a millimetre or more: closer is one '
                'bearing or plane, and moments are divided by the spacing')
"""Distance between the two supports, or between the two correction planes."""
DIVISOR_RADIUS = Limit(1e-6, MAX_MAGNITUDE, 'm', 'a micrometre or more: a correction '
                       'mass is the unbalance over it')
"""A radius a correction mass goes at: ``balancing.correction_radius``, a weight site's."""
GRADE = Limit(0.1, 4000.0, 'mm/s', 'ISO 21940-11 grades run from G 0.4 to G 4000')
"""A balance quality grade G."""
SPEED = Limit(1e-3, 1e5, 'rad/s', 'a turn in 100 minutes to 955 000 rpm: slower is no '
              'balancing speed, faster no rotor')
"""A rotor speed the balance is judged at, or the largest plausible one (|omega|)."""
WEIGHT_MASS = Limit(1e-6, MAX_MAGNITUDE, 'kg', 'a milligram or more: a plan counts '
                    'weights as the unbalance divided by their mass')
"""A balancing weight's mass (a kit's sizes)."""
WARN_FRACTION = Limit(0.01, 1.0, '', 'of the grade')
"""The fraction of the grade beyond which the verdict warns."""

# -- bearings (a support's ``bearing``: ISO 281's basic rating life) --------------------

LOAD_RATING = Limit(1.0, 1e9, 'N', "a newton or more: the loads are divided by it, and "
                    "the largest slewing bearings' C is below 10^8 N")
"""A bearing's basic dynamic load rating C."""
LOAD_FACTOR = Limit(0.0, 10.0, '', "ISO 281's factors are below 3, a thrust bearing's "
                    'up to 10')
"""A bearing's radial or axial load factor, X or Y."""
LIMIT_RATIO = Limit(0.01, 10.0, '', "the Fa / Fr at which ISO 281's factors switch")
"""A bearing's e: beyond Fa / Fr = e, P = X Fr + Y Fa; up to it, P = Fr."""
RELIABILITY_FACTOR = Limit(0.05, 1.0, '', 'ISO 281 a1: 1 at 90 % reliability (L10), '
                           '0.05 beyond 99.95 %')
"""A bearing's life adjustment factor for reliability a1."""
LIMITING_SPEED = Limit(0.1, 1e5, 'rad/s', "a maker's limiting speed: 1 rpm to 955 000 rpm")
"""A bearing's limiting speed (``limit_speed``)."""

# -- tolerance files ----------------------------------------------------------------------

LENGTH_TOLERANCE = Limit(0.0, MAX_MAGNITUDE, 'm', 'a +- tolerance, within the positions')
"""A +- tolerance of a radius or a z."""

# -- scenarios and simulated fleets -------------------------------------------------------

SAMPLE_RATE = Limit(1.0, 1e5, 'Hz', 'an encoder or a load cell: every sample is held in '
                    'memory')
"""Samples per second of a simulated encoder or load cell."""
SAMPLES = Limit(1, 50_000_000, 'samples', 'about 3 GB of arrays')
"""Most samples a simulated run may have (duration x rate)."""
START = Limit(0.0, 4e9, 's', 'stamps in nanoseconds since 1970 stay within 2^63')
"""A simulated run's start, s since the epoch."""
NOISE = Limit(0.0, MAX_MAGNITUDE, '', 'a standard deviation')
"""A simulated noise's standard deviation (rad, rad/s, N)."""

# -- the commands' options (and the node's parameters of the same name) -------------------

OMEGA = Limit(-1e5, 1e5, 'rad/s', "within SPEED's 955 000 rpm, either way")
"""A speed sample given as an option (``solve --omega``): signed, 0 at rest."""
ACCELERATION = Limit(-1e6, 1e6, 'rad/s^2', "SPEED's top in a tenth of a second, either way")
"""An angular acceleration given as an option (``solve --alpha``)."""
TIME_CONSTANT = Limit(1e-4, 100.0, 's', "the alpha estimate's slope window")
"""The time constant of the least-squares slope that estimates alpha (node and replay)."""
STAMP_JUMP = Limit(1e-3, 1e6, 's', 'a millisecond to 11.6 days between samples')
"""The largest jump between motion samples' stamps (node and replay)."""
EVERY = Limit(1, 100_000, 'samples', 'a picture per this many samples')
"""Samples per logged sample in the rerun view."""
WINDOW_REVS = Limit(1, 100_000, 'revolutions', "the identification's window")
"""Revolutions over which the load cells' fit runs."""
SEGMENT = Limit(1, 1_000_000, '', "a layout segment's number")
"""A layout segment of a run, counted from 1."""
PLAY_RATE = Limit(0.01, 1000.0, 'x', 'times real time: faster than the node takes samples')
"""Playback rate, times real time."""
WAIT = Limit(0.01, 3600.0, 's', 'an hour at most')
"""Seconds a command waits for the node or its topics."""
CHUNK_KIB = Limit(1, 65_536, 'KiB', 'a chunk is held in memory until written')
"""Size of an MCAP chunk written by ``record``."""
POINTS = Limit(2, 2001, 'points', 'per parameter; a map takes at most 501 a side')
"""Grid points of a sweep along one parameter (``sweep --points``)."""
MAP_POINTS = 501
"""Grid points a side of a two-parameter sweep (a map)."""
DRAWS = Limit(1, 20_000_000, 'draws', 'about 2 GB of draws and statistics')
"""Monte-Carlo draws of ``tolerance``."""
SEED = Limit(0, 2**63 - 1, '', 'a 64-bit seed')
"""A random seed."""
MAX_WEIGHTS = Limit(1, 10_000, 'weights', 'the plan is a mixed-integer problem')
"""Most weights a correction plan may use."""
TIME_LIMIT = Limit(0.01, 86_400.0, 's', 'a day')
"""Time limit of the weight plan's solver."""
SPEED_TOLERANCE = Limit(0.001, 100.0, '%', 'of the speed')
"""How far a run's steady speed may be from the calibration's, percent."""
WORKERS = Limit(1, 4 * (os.cpu_count() or 1), 'processes', 'four per core: more only '
                'queue, each a Python of about 150 MB')
"""Local worker processes of ``fleet``."""
BATCH = Limit(1, 10_000, 'bags', 'bags per task')
"""Bags per analysis task of ``fleet``."""
TOP = Limit(1, 1_000_000, 'machines', 'lines listed')
"""Machines listed by ``trends --top``."""
MACHINES = Limit(1, 1000, 'machines', 'a folder of bags each')
"""Machines of a simulated fleet."""
RUNS = Limit(1, 1000, 'runs', 'a bag each')
"""Runs per machine of a simulated fleet."""
DAYS = Limit(0.001, 36_500.0, 'days', 'a century')
"""Span of a simulated fleet's runs."""
STEADY = Limit(0.01, 86_400.0, 's', 'a day at most')
"""Time of each simulated run at the service speed."""
