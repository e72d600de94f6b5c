"""
A recorded run as one plain record: what ``cvc-balance replay BAG --json`` prints.

:func:`analyse_bag` replays a bag (no output written) and, when it has load cells
(``supports/<name>/measured_load``), identifies each layout segment's real unbalance
(:func:`cvc_balance.bag.identify_run.identify_bag`); :func:`replay_record` turns that into
JSON-able data (schema in the README, "Bags"). The fleet tool (:mod:`cvc_balance.fleet`)
flattens the same record into its table, so a fleet row and ``replay --json`` of the same
bag cannot disagree. SI units; g mm and degrees where people read them, named in the key.
"""

from datetime import datetime, timezone
import math

from cvc_balance.bag.identify_run import identify_bag
from cvc_balance.bag.machine import bag_custom_data, MACHINE_ID
from cvc_balance.bag.replay import replay
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.messages import topics
from cvc_balance.physics.assessment import (ERROR, judge_balance, OK, verdict_record, WARN,
                                            WARN_FRACTION)
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.frames import degrees, g_mm
from cvc_balance.physics.plausibility import layout_warnings

SCHEMA = 'cvc_balance replay'
VERSION = 1
"""The record's ``kind`` and ``version`` (a reader can refuse what it does not know)."""


def analyse_bag(bag_path, layout_file=None, joint_name='gantry_joint', time_constant=0.1,
                max_speed=1000.0, tolerance=None, names=None, identify=True):
    """
    Replay ``bag_path`` (a file or rosbag2 directory) and return its :func:`replay_record`.

    Nothing is written. With ``identify`` and load-cell topics in the bag, each segment
    also gets the unbalance identified from them. Raises BagError (and LayoutError) as
    :func:`cvc_balance.bag.replay.replay` does.
    """
    summary = replay(bag_path, layout_file=layout_file, joint_name=joint_name,
                     time_constant=time_constant, max_speed=max_speed, tolerance=tolerance,
                     names=names)
    identified = None
    if identify and has_load_cells(bag_path):
        identified, _ = identify_bag(bag_path, layout_file, joint_name,
                                     time_constant=time_constant, max_speed=max_speed,
                                     names=names)
    machine = bag_custom_data(bag_path).get(MACHINE_ID)
    return replay_record(summary, identified, machine)


def has_load_cells(bag_path):
    """Tell whether the bag has a load-cell topic (``.../supports/<name>/measured_load``)."""
    suffix = topics.measured_load('').rsplit('/', 1)[-1]
    return any(topic.endswith('/' + suffix) and msg_type == topics.WRENCH_TYPE
               for topic, msg_type in open_bag(bag_path).topics().items())


def utc(ns):
    """Return a log time (ns since the epoch) as ISO 8601 UTC text, None for None."""
    if ns is None:
        return None
    return datetime.fromtimestamp(ns // 1_000_000_000, timezone.utc).replace(
        microsecond=(ns % 1_000_000_000) // 1000).isoformat().replace('+00:00', 'Z')


def replay_record(summary, identified=None, machine_id=None):
    """
    Return a :class:`~cvc_balance.bag.replay.ReplaySummary` as JSON-able data.

    ``identified``: [IdentifiedSegment] of the same bag (matched to the replay's
    segments by layout digest and start), or None; ``machine_id``: the bag's own.
    """
    by_start = {(s.layout.digest(), s.start_ns): s for s in identified or ()}
    segments = [segment_record(s, by_start.get((s.layout.digest(), max(s.start_ns, 0))))
                for s in summary.segments]
    used = [s for s in summary.segments if s.first_ns is not None]
    first = min((s.first_ns for s in used), default=None)
    last = max((s.last_ns for s in used), default=None)
    return {
        'kind': SCHEMA, 'version': VERSION,
        'bag': summary.bag, 'machine_id': machine_id,
        'start': first * 1e-9 if first is not None else None, 'start_utc': utc(first),
        'end': last * 1e-9 if last is not None else None,
        'samples': summary.samples, 'accepted': summary.accepted,
        'rejected': summary.rejected, 'dropped': summary.dropped, 'skipped': summary.skipped,
        'rejected_reasons': list(summary.reasons)
        + ([summary.skipped_reason] if summary.skipped else []),
        'problems': list(summary.problems),
        'seconds': summary.seconds,
        'segments': segments,
    }


def segment_record(segment, identified=None):
    """Return one layout segment of a replay as JSON-able data (see :func:`replay_record`)."""
    layout = segment.layout
    model = segment.model or RotorModel.from_layout(layout)     # aggregated once
    verdict = judge_balance(model, top_speed=segment.max_speed)
    balance = verdict_record(verdict)
    if balance is not None:          # replay's record also says where the static unbalance is
        balance['static_g_mm'] = g_mm(verdict.assessment.static_amount)
        balance['static_angle_deg'] = degrees(verdict.assessment.static_angle)
    choice = segment.choice
    record = {
        'layout': {'name': layout.name, 'digest': layout.digest()},
        'from': segment.start_ns * 1e-9 if segment.start_ns >= 0 else None,
        'first_sample': segment.first_ns * 1e-9 if segment.first_ns is not None else None,
        'last_sample': segment.last_ns * 1e-9 if segment.last_ns is not None else None,
        'start_utc': utc(segment.first_ns),
        'samples': segment.samples,
        'top_speed': segment.max_speed,
        'peak_load_N': segment.peak_total,
        'peak_support_load_N': dict(segment.peak_support),
        'warnings': list(layout_warnings(layout)),
        'balance': balance,
        'model': choice.name if choice is not None else 'rigid bodies',
        'model_deviation': None if choice is None else {
            'force_N': choice.deviation.force, 'moment_Nm': choice.deviation.moment,
            'torque_Nm': choice.deviation.torque},
        'identified': None,
    }
    if identified is not None:
        record['identified'] = identified_record(identified, balance)
    return record


def _vector(vector, unit_scale, unit):
    ci = vector.ci95 * unit_scale if math.isfinite(vector.ci95) else None
    return {unit: vector.amount * unit_scale, 'angle_deg': degrees(vector.angle),
            f'ci95_{unit}': ci}


def unbalance_summary(unbalance):
    """Return a RotorUnbalance as JSON-able data: kg m, kg m^2, g mm; degrees."""
    return {'static_unbalance': _vector(unbalance.static, 1.0, 'kg_m'),
            'couple_unbalance': _vector(unbalance.couple, 1.0, 'kg_m2'),
            'planes': [{'z': z, **_vector(v, 1e6, 'g_mm')} for z, v in unbalance.planes]}


def identified_summary(segment):
    """Return an IdentifiedSegment as JSON-able data (``identify --json``'s segment)."""
    estimate = segment.estimate
    return {
        'layout': {'name': segment.layout.name, 'digest': segment.layout.digest()},
        'from': segment.start_ns * 1e-9, 'to': segment.end_ns * 1e-9,
        'samples': segment.samples, 'readings': segment.readings, 'dropped': segment.dropped,
        'revolutions': segment.revolutions, 'identifiable': estimate.identifiable,
        'identified': unbalance_summary(segment.identified),
        'layout_prediction': unbalance_summary(segment.declared),
        'residual': unbalance_summary(segment.residual),
        'fit': {'rms_N': estimate.sigma * math.sqrt(2) if estimate.identifiable else None,
                'sigma_N': estimate.sigma if estimate.identifiable else None,
                'biases_N': [[b.real, b.imag] for b in estimate.biases]},
    }


def identified_record(segment, balance):
    """
    Return ``identify``'s segment record plus the identified unbalance against the grade.

    ``grade``: each plane's identified unbalance over the permissible share the layout's
    verdict gives it (``balance``), the equivalent grade (G times the larger fraction: the
    standard's own rule, as :class:`~cvc_balance.physics.assessment.BalanceAssessment`) and
    its level; None when not identifiable or not judged.
    """
    record = identified_summary(segment)
    record.pop('layout')
    record['grade'] = None
    planes = record['identified']['planes']
    if (balance is None or not record['identifiable'] or not planes
            or len(planes) != len(balance['planes'])):
        return record
    fractions = [p['g_mm'] / allowed['permissible_g_mm']
                 for p, allowed in zip(planes, balance['planes'])]
    equivalent = balance['grade'] * max(fractions)
    level = ERROR if equivalent > balance['grade'] else \
        WARN if equivalent > WARN_FRACTION * balance['grade'] else OK
    record['grade'] = {'fractions': fractions, 'equivalent_grade': equivalent,
                       'within_grade': equivalent <= balance['grade'], 'level': level}
    return record
