"""
Trial-weight advice before the trial runs: large enough to see, small enough to be safe.

A trial weight u (kg m) in plane j changes sensor s's 1x reading by |alpha_sj| |u|, alpha
the layout's predicted coefficients (:func:`cvc_balance.field.model_check.
predicted_coefficients`). Against the baseline's standard errors sigma_s it is seen
``standard_errors`` times when

    |u| = standard_errors / max_s (|alpha_sj| / (sqrt(2) sigma_s)),

sqrt(2) sigma_s the standard error of a change between two runs as long as the baseline
(as ``calibrate`` counts a trial's visibility).

Two caps keep the trial run safe (ISO 20806 practice, instrument manuals; FACTS.md "Field
balancing practice"): the trial alone adds no more unbalance than the grade allows in
its plane (:data:`GRADE_SHARE` of the plane's permissible unbalance), and its rotating
force at each bearing stays within :data:`BEARING_SHARE` (10 %) of the static load the
bearing carries (the rotor's weight share). Without standard errors the advice is the
common starting rule: the trial that makes that 10 % force, within the grade's cap.
SI inside: kg, m, kg m, N, rad/s.
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.physics import iso21940
from cvc_balance.physics.engine import RotorModel, sample_loads

DEFAULT_STANDARD_ERRORS = 20.0
"""How many standard errors of the baseline a trial should move the readings by."""
GRADE_SHARE = 1.0
"""Largest trial unbalance as a share of its plane's permissible unbalance."""
BEARING_SHARE = 0.1
"""Largest rotating force of the trial at a bearing as a share of its static load."""
MAX_STACKS = 100_000
"""Most kit stacks enumerated for the advice."""


@dataclass(frozen=True)
class TrialAdvice:
    """
    The trial weight advised for one plane.

    ``unbalance`` kg m at ``radius`` m (``mass`` kg); ``standard_errors`` how far it moves
    the readings (None without the baseline's noise); ``wanted`` the unbalance that would
    move them the asked number of standard errors (None without noise); ``grade_cap`` and
    ``bearing_cap`` kg m; ``capped_by`` 'grade', 'bearing load' or None; ``kit`` the
    smallest stack of the plane's kit at least ``mass`` (kg, a tuple) and ``kit_errors``
    what it moves by, or None; ``note`` one line, or ''.
    """

    plane: str
    z: float
    radius: float
    unbalance: float
    mass: float
    standard_errors: float
    wanted: float
    grade_cap: float
    bearing_cap: float
    capped_by: str
    kit: tuple
    kit_errors: float
    note: str


def static_bearing_loads(layout):
    """Return {support: |static radial load| N}: the weight share each bearing carries."""
    model = RotorModel.from_layout(layout)
    quarters = [sample_loads(model, k * math.pi / 2.0, 0.0).supports for k in range(4)]
    return {s.name: math.hypot(sum(q[s.name][0][0] for q in quarters) / 4.0,
                               sum(q[s.name][0][1] for q in quarters) / 4.0)
            for s in layout.supports}


def advise(layout, planes, z, predicted, sensors, speed, sigma=None,
           standard_errors=DEFAULT_STANDARD_ERRORS):
    """
    Return one :class:`TrialAdvice` per plane.

    ``planes`` names with ``z`` m; ``predicted`` (sensors, planes) complex reading per
    kg m at ``speed`` rad/s (NaN where not predicted) for channel names ``sensors``;
    ``sigma`` (sensors,) the baseline's standard errors or None. The grade's cap uses the
    layout's grade and service speed (``speed`` without one).
    """
    model = RotorModel.from_layout(layout)
    service = layout.balancing.service_speed or speed
    u_per = iso21940.permissible_unbalance(layout.balancing.grade, model.mass, service)
    shares = iso21940.plane_shares(model.s_z / model.mass, *layout.correction_planes())
    share_of = dict(zip(('I', 'II'), shares))
    statics = static_bearing_loads(layout)
    out = []
    for j, plane in enumerate(planes):
        column = predicted[:, j]
        known = ~np.isnan(column.real)
        grade_cap = GRADE_SHARE * u_per * share_of.get(plane, 1.0)
        bearing_cap = math.inf
        for s, name in enumerate(sensors):
            support, _, component = name.rpartition('/')
            if known[s] and component in ('force_x', 'force_y') and abs(column[s]) > 0.0:
                bearing_cap = min(bearing_cap, BEARING_SHARE * statics[support] / abs(column[s]))
        wanted = None
        seen = None
        if sigma is not None:
            # The change's own standard error: the baseline's and the trial run's, alike.
            noise = math.sqrt(2.0) * np.asarray(sigma, float)
            ratio = np.where(known, np.abs(np.nan_to_num(column)) / noise, 0.0)
            seen = float(ratio.max())
            wanted = standard_errors / seen if seen > 0.0 else math.inf
        target = bearing_cap if wanted is None else wanted
        unbalance, capped_by = target, None
        for cap, name in ((grade_cap, 'grade'), (bearing_cap, 'bearing load')):
            if unbalance > cap:
                unbalance, capped_by = cap, name
        sites = layout.balancing.sites_of(plane)
        radius = sites.radius if sites is not None else layout.correction_radius()
        mass = unbalance / radius
        kit, kit_errors = None, None
        notes = []
        if sites is not None:
            kit = kit_stack(mass, min(grade_cap, bearing_cap) / radius, sites)
            if kit is None:
                notes.append('every stack of the kit is over the cap')
            elif seen is not None:
                kit_errors = sum(kit) * radius * seen
        errors = None if seen is None else unbalance * seen
        if wanted is not None and capped_by is not None:
            more = (standard_errors / errors) ** 2 if errors else math.inf
            notes.append(f'capped by the {capped_by}: it moves the readings only '
                         f'{errors:.3g} standard errors (under {standard_errors:g}); a '
                         f'baseline about {more:.2g} times longer (standard errors fall as '
                         'one over the root of the revolutions) would let a safe trial show')
        if wanted is None:
            notes.append('no baseline noise known: the common starting rule (a force of '
                         f'{BEARING_SHARE:.0%} of the bearing\'s static load)'
                         + (f', capped by the {capped_by}' if capped_by else ''))
        out.append(TrialAdvice(plane, z[j], radius, unbalance, mass, errors, wanted,
                               grade_cap, bearing_cap, capped_by, kit, kit_errors,
                               '; '.join(notes)))
    return out


def kit_stack(mass, cap, sites):
    """
    Return the kit's stack (kg, heaviest first) for a trial of ``mass`` kg under ``cap`` kg.

    The lightest stack of at least ``mass`` if within ``cap``, else the heaviest within it;
    None when no stack of the kit is within the cap.
    """
    level, stacks = {0.0: ()}, {}
    for _ in range(sites.stack):
        grown = {}
        for total, stack in level.items():
            for size in sites.masses:
                if not stack or size <= stack[-1]:   # each multiset once
                    grown.setdefault(round(total + size, 12), stack + (size,))
        for total, stack in grown.items():
            stacks.setdefault(total, stack)          # the fewest plates for a total
        level = {t: s for t, s in grown.items() if t < max(mass, cap)}
        if not level or len(stacks) > MAX_STACKS:
            break
    above = [t for t in stacks if t >= mass * (1.0 - 1e-12) and t <= cap * (1.0 + 1e-12)]
    if above:
        return stacks[min(above)]
    below = [t for t in stacks if t <= cap * (1.0 + 1e-12)]
    return stacks[max(below)] if below else None
