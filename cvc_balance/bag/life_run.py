"""
The bearings' life in a recorded run: per layout segment and support, layout and measured.

From the layout: the replay's loads (:func:`cvc_balance.bag.replay.replay` counts each
segment's bearings, :class:`~cvc_balance.physics.bearing_life.LifeCounters`), and the same
run of the rotor balanced (its unbalance removed). Measured, where a support's load cell
(``supports/<name>/measured_load``) read during the segment and the fit could tell its
zero (:mod:`cvc_balance.bag.identify_run`): the cell's force less its zero. The fit's bias
holds the zero and the static load together, which the cells cannot tell apart, so the
static part is the layout's (as the verdict of record takes the mass and the axial centre
of mass from the layout, :mod:`cvc_balance.identify.evidence`); the same for the axial
force, whose mean is the layout's. The measured rotor balanced is the reading less the
load of the unbalance the cells identified, told only when the verdict of record is the
measured rotor's (the cells can tell).

:func:`support_records` is what ``cvc-balance life --json`` and ``replay --json`` (each
segment's ``life``) print; :func:`life_lines` the text.
"""

from dataclasses import replace

import numpy as np

from cvc_balance.identify.batch import channels
from cvc_balance.identify.evidence import MEASURED
from cvc_balance.physics.bearing_life import balanced, LifeCounters
from cvc_balance.physics.engine import loads

FIELD = 'supports[].bearing'
"""Where a layout describes a support's bearing: named when a bag's layouts have none."""
NO_BEARINGS = (f'no bearing data: give each support a field bearing ({FIELD}: C, the basic '
               'dynamic load rating in N, and type ball or roller; optional X, Y, e, a1, '
               'limit_speed), in the bag\'s layout or with --layout-file')
"""The one line said when no layout of a bag describes a bearing."""


def bearing_record(bearing):
    """Return a Bearing as JSON-able data: its fields as the layout names them, and p."""
    return {'C': bearing.C, 'type': bearing.type, 'p': bearing.exponent, 'X': bearing.X,
            'Y': bearing.Y, 'e': bearing.e, 'a1': bearing.a1,
            'limit_speed': bearing.limit_speed}


def measured_uses(identified, of_record):
    """
    Return {support name: (LifeUse, LifeUse of the rotor balanced, or None)} from the cells.

    ``identified``: the segment's :class:`~cvc_balance.bag.identify_run.IdentifiedSegment`;
    ``of_record``: its verdict of record. Only supports with a bearing and a cell that
    read at least twice within the motion; none when the fit cannot tell the cells' zeros.
    """
    estimate, model = identified.estimate, identified.model
    if not estimate.identifiable:
        return {}
    motion, cells = identified.motion, identified.cells
    quiet = balanced(model)
    measured_rotor = replace(model, s_x=estimate.static.real, s_y=estimate.static.imag,
                             p_xz=estimate.products.real, p_yz=estimate.products.imag)
    tell = of_record is not None and of_record.source == MEASURED
    reading = channels(model.supports)
    uses = {}
    for k, support in enumerate(model.supports):
        cell = cells.get(support.name)
        if support.bearing is None or cell is None:
            continue
        inside = (cell.time >= motion.time[0]) & (cell.time <= motion.time[-1]) \
            & np.all(np.isfinite(cell.force), axis=1)
        time = cell.time[inside]
        if len(time) < 2:
            continue
        angle, omega, alpha = motion.at(time)
        # The static load (constant in the stator frame for the balanced rotor) where the
        # bias had it: the cell's reading, less its zero.
        static = loads(quiet, angle[:1], 0.0, 0.0).support_force[support.name][0]
        bias = estimate.biases[reading.index((k, 'force'))]
        force = np.array(cell.force[inside], dtype=float)
        force[:, 0] += static[0] - bias.real
        force[:, 1] += static[1] - bias.imag
        force[:, 2] += static[2] - force[:, 2].mean()
        use = _counted(support, time, angle, omega, force)
        without = None
        if tell:
            # The load of the unbalance the cells identified (linear in S and P), taken out.
            unbalance = (loads(measured_rotor, angle, omega, alpha).support_force[support.name]
                         - loads(quiet, angle, omega, alpha).support_force[support.name])
            without = _counted(support, time, angle, omega, force - unbalance)
        uses[support.name] = (use, without)
    return uses


def _counted(support, time, angle, omega, force):
    """Return the LifeUse of one support's bearing under ``force`` (n, 3) at these samples."""
    counters = LifeCounters([support])
    counters.add(time, angle, omega, {support.name: force})
    return counters.uses()[support.name]


def support_records(segment, identified=None, of_record=None):
    """
    Return [one record per support with a bearing] of a replay segment, or None: no bearing.

    ``segment``: a :class:`~cvc_balance.bag.replay.Segment` (its ``life`` counted);
    ``identified``: the segment's IdentifiedSegment when the bag has load cells, and
    ``of_record`` its verdict of record. Each record: name, bearing, revolutions,
    ``layout`` and ``measured`` (null without a cell that can tell), each
    :meth:`~cvc_balance.physics.bearing_life.LifeUse.record` (equivalent_load_N,
    life_used, l10_hours, unbalance_share).
    """
    if segment.life is None:
        return None
    actual, quiet = segment.life.uses(), segment.balanced_life.uses()
    measured = measured_uses(identified, of_record) if identified is not None else {}
    records = []
    for name, use in actual.items():
        found = measured.get(name)
        records.append({
            'name': name, 'bearing': bearing_record(use.bearing),
            'revolutions': use.revolutions,
            'layout': use.record(quiet[name]),
            'measured': None if found is None else found[0].record(found[1])})
    return records


def life_lines(records, top_speed=None, indent='  '):
    """
    Describe a segment's bearing records (:func:`support_records`) for people.

    Per support: its bearing, the revolutions and hours; then from the layout and, where
    the cells tell, measured: the mean equivalent load, the life used, the rating life at
    this duty and what the unbalance costs. ``top_speed`` rad/s: said when over a bearing's
    limiting speed.
    """
    lines = []
    for record in records:
        bearing = record['bearing']
        layout = record['layout']
        hours = _hours(layout)
        lines.append(f"{indent}bearing {record['name']} ({bearing['type']}, C {bearing['C']:.6g} "
                     f"N): {record['revolutions']:.1f} revolutions"
                     + (f' in {hours:.4g} h' if hours is not None else ''))
        limit = bearing['limit_speed']
        if limit is not None and top_speed is not None and top_speed > limit:
            lines.append(f'{indent}  warning: top speed {top_speed:.4g} rad/s is over the '
                         f"bearing's limiting speed {limit:.4g} rad/s")
        lines.append(f"{indent}  layout:   {_use_text(layout, bearing)}")
        if record['measured'] is not None:
            lines.append(f"{indent}  measured: {_use_text(record['measured'], bearing)}")
    return lines


def _hours(use):
    """Return the hours of a use record (rating life x life used), None if not known."""
    if use['l10_hours'] is None:
        return None
    return use['l10_hours'] * use['life_used']


def _use_text(use, bearing):
    """One line of a use record: P_m, life used, rating life, the unbalance's cost."""
    if use['equivalent_load_N'] is None:
        return 'no revolutions: no life used'
    life = 'L10' if bearing['a1'] == 1.0 else f"L (a1 {bearing['a1']:g})"
    text = (f"P_m {use['equivalent_load_N']:.6g} N, life used {use['life_used']:.4g}"
            + (f", {life} {use['l10_hours']:.4g} h at this duty"
               if use['l10_hours'] is not None else ''))
    share = use['unbalance_share']
    if share is not None:
        text += (f'; this unbalance uses {100.0 * share:.3g} % more of its life than the '
                 'rotor balanced')
    return text
