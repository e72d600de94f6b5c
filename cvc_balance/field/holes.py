"""
Hole numbers as a technician counts them: from the gantry's reference mark, one way round.

A plane's sites (:class:`~cvc_balance.physics.layout.WeightSites`) may say which site is hole
1 (``first_hole``, the reference mark), which way the numbers run against the rotor's turning
(``numbering``: 'with_rotation' or 'against_rotation') and that turning (``rotation``:
'positive' turns rotor X toward rotor Y). Hole numbers then run over the sites in that
direction; a site is named "hole 7, 90 deg from the mark against the rotation" beside its
angle in the rotor frame. Angles rad inside, degrees in the text.
"""

import math

TWO_PI = 2.0 * math.pi
SAME = 1e-6
"""Angles within this (rad) are the same site."""


def direction(sites):
    """Return +1 when the numbers run toward increasing rotor angle, -1 the other way."""
    forward = (sites.numbering == 'with_rotation') == (sites.rotation == 'positive')
    return 1 if forward else -1


def from_mark(sites, angle):
    """Return the angle from hole 1 to ``angle`` counted the numbers' way, rad [0, 2 pi)."""
    return (direction(sites) * (angle - sites.first_hole)) % TWO_PI


def hole_numbers(sites):
    """Return {site angle: hole number} (1 = the mark), or {} when the sites are not numbered."""
    if sites is None or sites.numbering is None:
        return {}
    order = sorted(sites.angles, key=lambda a: from_mark(sites, a) if
                   abs(math.remainder(a - sites.first_hole, TWO_PI)) >= SAME else -1.0)
    return {angle: k + 1 for k, angle in enumerate(order)}


def hole_of(sites, angle):
    """Return the hole number of the site at ``angle`` (rad), or None."""
    for site, number in hole_numbers(sites).items():
        if abs(math.remainder(site - angle, TWO_PI)) < SAME:
            return number
    return None


def site_of_hole(sites, number):
    """Return the angle (rad) of hole ``number``; ValueError naming the holes there are."""
    numbers = hole_numbers(sites)
    if not numbers:
        raise ValueError(f'plane {sites.plane}: its sites are not numbered (balancing.sites.'
                         f'{sites.plane}: first_hole_angle_deg and numbering): give the angle')
    for angle, n in numbers.items():
        if n == number:
            return angle
    raise ValueError(f'plane {sites.plane} has holes 1 to {len(numbers)}, not {number}')


def hole_text(sites, angle):
    """Return 'hole 7, 90 deg from the mark against the rotation', or '' (not numbered)."""
    number = hole_of(sites, angle)
    if number is None:
        return ''
    way = 'with' if sites.numbering == 'with_rotation' else 'against'
    offset = math.degrees(from_mark(sites, angle))
    return f'hole {number}, {round(offset, 1) % 360.0:g} deg from the mark {way} the rotation'
