"""
``identify`` of a recorded run: per layout segment, the rotor's unbalance from its load cells.

Reads the motion and the layouts as replay does (:func:`cvc_balance.bag.replay.read_inputs`,
the node's input checks and alpha estimate), each support's cell
(``supports/<name>/measured_load``, WrenchStamped, stator frame), and fits each layout's
segment (:mod:`cvc_balance.identify`): the identified unbalance, the layout's, the
residual (what the layout does not know), their 95 % radii and the fit's rms.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from cvc_balance.bag.mcap_reader import wrench_samples
from cvc_balance.bag.replay import layout_events, read_inputs
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.identify import (CellReadings, fit, identified_unbalance, layout_unbalance,
                                  Motion, residual)
from cvc_balance.identify.evidence import verdict_of_record
from cvc_balance.messages import topics
from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.motion import accepted_motion


@dataclass
class IdentifiedSegment:
    """One layout's samples and what the fit found (SI; see :mod:`cvc_balance.identify`)."""

    layout: object
    start_ns: int
    end_ns: int
    samples: int
    readings: int
    dropped: int
    revolutions: float
    top_speed: float        # rad/s, the top |omega| of the segment's accepted samples
    estimate: object
    identified: object
    declared: object
    residual: object
    model: object = field(default=None, repr=False)     # the layout's RotorModel
    motion: object = field(default=None, repr=False)    # the fitted Motion and cells, kept
    cells: dict = field(default=None, repr=False)       # for :func:`observe`


def cell_readings(bag, supports):
    """Return {support name: CellReadings} of the bag's load cells for these supports."""
    cells = {}
    for support in supports:
        channel = bag.channel(topics.measured_load(support.name), topics.WRENCH_TYPE)
        if channel is None:
            continue
        stamp, force, torque = wrench_samples(bag, channel)
        cells[support.name] = CellReadings(support.name, stamp * 1e-9, force, torque)
    return cells


def identify_bag(bag_path, layout_file=None, joint_name='gantry_joint', window_revs=None,
                 time_constant=0.1, max_speed=1000.0, names=None, observer=None):
    """
    Identify each layout segment of ``bag_path``; return ([IdentifiedSegment], problems).

    ``bag_path``: a bag file or rosbag2 directory; ``names`` its input topics if not the
    node's (:class:`cvc_balance.bag.inputs.InputTopics`); ``window_revs``: fit only the
    last that many revolutions of each segment (the state at its end, as the live node
    reports it); default the whole segment. ``observer``: see :func:`observe` (or call it
    later with the segments returned).
    """
    bag = open_bag(bag_path)
    motion, layout_messages = read_inputs(bag, joint_name, names)
    events, problems = layout_events(bag, layout_messages, layout_file)
    t = motion.stamp * 1e-9
    accepted, alpha = accepted_motion(t, motion.log_time * 1e-9, motion.angle, motion.omega,
                                      max_speed, time_constant)
    t, angle, omega = t[accepted], motion.angle[accepted], motion.omega[accepted]
    log_time = motion.log_time[accepted]
    segments = []
    bounds = [e[0] for e in events[1:]] + [np.iinfo(np.int64).max]
    for (start_ns, layout), end_ns in zip(events, bounds):
        lo, hi = np.searchsorted(log_time, [start_ns, end_ns])
        model = RotorModel.from_layout(layout)
        if hi - lo < 2:
            continue
        part = slice(lo, hi)
        seg = Motion(t[part], angle[part], omega[part], alpha[part])
        if window_revs is not None:
            turned = np.abs(np.unwrap(seg.angle) - np.unwrap(seg.angle)[-1]) / (2 * math.pi)
            keep = turned <= window_revs
            seg = Motion(seg.time[keep], seg.angle[keep], seg.omega[keep], seg.alpha[keep])
        cells = {name: _during(c, seg.time[0], seg.time[-1])
                 for name, c in cell_readings(bag, model.supports).items()}
        estimate, dropped = fit(model, seg, cells)
        identified = identified_unbalance(model, estimate)
        declared = layout_unbalance(model)
        segments.append(IdentifiedSegment(
            layout, int(max(start_ns, 0)), int(min(end_ns, log_time[hi - 1])), int(hi - lo),
            int(estimate.readings), int(dropped), seg.revolutions(),
            float(np.abs(omega[part]).max()), estimate, identified,
            declared, residual(identified, declared), model, seg, cells))
        if observer is not None:
            observe(observer, segments[-1])
    return segments, bag.problems + motion.problems + problems


def observe(observer, segment):
    """
    Hand ``observer`` (a rerun RunLogger) a segment's cells and what the fit found.

    Each cell, less its fitted zero, beside the layout's prediction (``cells``), then the
    residual, the identified unbalance and the segment's verdict of record (``measured``).
    The observer must have seen the replay of the same bag. Nothing when not identifiable.
    """
    estimate, model, motion, cells = segment.estimate, segment.model, segment.motion, \
        segment.cells
    if not estimate.identifiable:
        return
    names = [s.name for s in model.supports]
    for name, cell in cells.items():
        if not len(cell.time):
            continue
        angle, omega, alpha = motion.at(cell.time)
        predicted = loads(model, angle, omega, alpha).support_force[name]
        # The fitted bias holds the cell's zero and the static weight: the predicted one's
        # weight goes back in, so the two curves differ by the unbalance only.
        at_rest = loads(model, angle, 0.0, 0.0).support_force[name][:, 0]
        zero = estimate.biases[names.index(name)].real - float(np.mean(at_rest))
        observer.cells(name, np.round(cell.time * 1e9).astype(np.int64),
                       cell.force[:, 0] - zero, predicted[:, 0])
    # Drawn from the segment's start: the fit holds for the whole of it.
    observer.measured(int(round(motion.time[0] * 1e9)), segment.residual, segment.identified,
                      segment_verdict(segment))


def segment_verdict(segment, grade=None):
    """Return the segment's :class:`~cvc_balance.identify.evidence.VerdictOfRecord`."""
    return verdict_of_record(segment.model, segment.estimate, top_speed=segment.top_speed,
                             grade=grade)


def _during(cell, start, end):
    inside = (cell.time >= start) & (cell.time <= end)
    return CellReadings(cell.support, cell.time[inside], cell.force[inside],
                        cell.torque[inside])
