"""
The field notation of vectors and trial weights, as people type them.

``AMPLITUDE@PHASE_DEG`` is a reading (any unit) or a mass at an angle: 170@112 is 170 at
112 degrees. A trial on a bag's run is ``PLANE:MASS_KG@ANGLE_DEG,RADIUS_M`` (I:0.2@0,0.68).
Degrees here only; the values returned are complex numbers and radians. Each parser raises
ValueError with one line naming what is wrong.
"""

import cmath
import math
import re

from cvc_balance.field.influence import Trial
from cvc_balance.physics.layout import MAX_MAGNITUDE, short

PLANE_NAME = re.compile(r'[A-Za-z0-9_]{1,40}')
"""A correction plane's name: I, II, front, 1, ... (letters, digits, _)."""
MAX_DEGREES = 1e6
"""Largest |angle| in degrees accepted at the edge."""


def _number(text, what, minimum=None):
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f'{what}: not a number: {short(text)}') from None
    if not math.isfinite(value) or abs(value) > MAX_MAGNITUDE:
        raise ValueError(f'{what} must be finite and within +-{MAX_MAGNITUDE:g}, '
                         f'got {short(text)}')
    if minimum is not None and value < minimum:
        raise ValueError(f'{what} must be >= {minimum:g}, got {short(text)}')
    return value


def polar_pair(text, what='reading'):
    """Return (amplitude >= 0, angle rad) of ``AMPLITUDE@PHASE_DEG``."""
    if not isinstance(text, str) or text.count('@') != 1:
        raise ValueError(f'{what}: give AMPLITUDE@PHASE_DEG (e.g. 170@112), got {short(text)}')
    amplitude, degrees = text.split('@')
    amplitude = _number(amplitude.strip(), f'{what} {short(text)}: amplitude', minimum=0.0)
    degrees = _number(degrees.strip(), f'{what} {short(text)}: phase')
    if abs(degrees) > MAX_DEGREES:
        raise ValueError(f'{what} {short(text)}: phase must be within +-{MAX_DEGREES:g} deg')
    return amplitude, math.radians(degrees)


def reading(text, what='reading'):
    """Return the complex reading of ``AMPLITUDE@PHASE_DEG``."""
    amplitude, angle = polar_pair(text, what)
    return cmath.rect(amplitude, angle)


def plane_name(text, what='plane'):
    """Return a checked correction-plane name."""
    if not isinstance(text, str) or not PLANE_NAME.fullmatch(text):
        raise ValueError(f'{what}: a plane name is 1-40 letters, digits or _, '
                         f'got {short(text)}')
    return text


def hand_trial(plane, text):
    """
    Return the :class:`Trial` of a plane name and ``MASS@ANGLE_DEG`` (any mass unit).

    ``MASS_KG@ANGLE_DEG,RADIUS_M`` gives the radius too: then kg and m.
    """
    radius = 1.0
    if isinstance(text, str) and text.count(',') == 1:
        text, radius_text = text.split(',')
        radius = _number(radius_text.strip(), f'trial weight of plane {short(plane)}: radius',
                         minimum=0.0)
        if not radius > 0.0:
            raise ValueError(f'trial weight of plane {short(plane)}: the radius must be > 0 m')
    mass, angle = polar_pair(text, f'trial weight of plane {short(plane)}')
    if not mass > 0.0:
        raise ValueError(f'trial weight of plane {short(plane)}: the mass must be > 0, '
                         f'got {short(text)}')
    return Trial(plane_name(plane), mass, angle, radius)


def bag_trial(text):
    """Return the :class:`Trial` of ``PLANE:MASS_KG@ANGLE_DEG,RADIUS_M`` (kg, m)."""
    form = 'give PLANE:MASS_KG@ANGLE_DEG,RADIUS_M (e.g. I:0.2@0,0.68)'
    if not isinstance(text, str) or text.count(':') != 1 or text.count(',') != 1:
        raise ValueError(f'--trial: {form}, got {short(text)}')
    plane, rest = text.split(':')
    try:
        return hand_trial(plane.strip(), rest.strip())
    except ValueError as error:
        raise ValueError(f'--trial {short(text)}: {error}') from None


def polar_text(value, digits=4):
    """Return a complex value as people write it: ``AMPLITUDE@PHASE_DEG`` (0-360 deg)."""
    degrees = math.degrees(cmath.phase(value)) % 360.0
    return f'{abs(value):.{digits}g}@{degrees:.1f}'


def weight_on(text):
    """
    Return (plane, ('angle', rad) or ('hole', n), mass kg) of ``PLANE:SITE:MASS_KG``.

    SITE is the site's angle in degrees (I:15:0.2) or its hole number (I:#7:0.2): a weight
    bolted on already.
    """
    form = 'give PLANE:SITE:MASS_KG, SITE an angle in degrees or #HOLE (I:15:0.2, I:#7:0.2)'
    if not isinstance(text, str) or text.count(':') != 2:
        raise ValueError(f'--weights-on: {form}, got {short(text)}')
    plane, site, mass = (part.strip() for part in text.split(':'))
    plane = plane_name(plane, f'--weights-on {short(text)}: plane')
    mass = _number(mass, f'--weights-on {short(text)}: mass', minimum=0.0)
    if not mass > 0.0:
        raise ValueError(f'--weights-on {short(text)}: the mass must be > 0 kg')
    if site.startswith('#'):
        if not site[1:].isdigit() or not 1 <= int(site[1:]) <= 100_000:
            raise ValueError(f'--weights-on {short(text)}: a hole is #1, #2, ...')
        return plane, ('hole', int(site[1:])), mass
    degrees = _number(site, f'--weights-on {short(text)}: site angle')
    if abs(degrees) > MAX_DEGREES:
        raise ValueError(f'--weights-on {short(text)}: the angle must be within '
                         f'+-{MAX_DEGREES:g} deg')
    return plane, ('angle', math.radians(degrees)), mass
