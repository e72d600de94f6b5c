"""
A recorded run as one plain record: what ``cvc-balance replay BAG --json`` prints.

:func:`analyse_bag` replays a bag (no output written) and, when it has load cells
(``supports/<name>/measured_load``), identifies each layout segment's real unbalance
(:func:`cvc_balance.bag.identify_run.identify_bag`); :func:`replay_record` turns that into
JSON-able data (its fields: the docs' "JSON outputs"). The fleet tool (:mod:`cvc_balance.fleet`)
flattens the same record into its table, so a fleet row and ``replay --json`` of the same
bag cannot disagree. SI units; g mm and degrees where people read them, named in the key.
"""

from datetime import datetime, timezone
import math

from cvc_balance.bag.identify_run import identify_bag
from cvc_balance.bag.life_run import life_lines, support_records
from cvc_balance.bag.machine import bag_custom_data, MACHINE_ID
from cvc_balance.bag.replay import InputCheck, replay
from cvc_balance.bag.rosbag2 import open_bag
from cvc_balance.identify.evidence import verdict_of_record
from cvc_balance.identify.mistakes import (cell_mistakes, measured_static_loads,
                                           MOTION_WINDOW, static_loads)
from cvc_balance.messages import topics
from cvc_balance.physics.assessment import verdict_record
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.frames import degrees_360, g_mm
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


def replay_record(summary, identified=None, machine_id=None, coefficients=None):
    """
    Return a :class:`~cvc_balance.bag.replay.ReplaySummary` as JSON-able data.

    ``identified``: [IdentifiedSegment] of the same bag (matched to the replay's
    segments by layout digest and start), or None; ``machine_id``: the bag's own;
    ``coefficients``: [CoefficientReading] of the same bag
    (:func:`cvc_balance.bag.field_run.coefficient_readings`: vibration readings through
    stored coefficients), matched by layout digest and time, or None.
    """
    by_start = {(s.layout.digest(), s.start_ns): s for s in identified or ()}
    matched = [by_start.get((s.layout.digest(), max(s.start_ns, 0))) for s in summary.segments]
    read = [_coefficient_match(s, coefficients) for s in summary.segments]
    segments = [segment_record(s, found, c) for s, found, c
                in zip(summary.segments, matched, read)]
    checks = list(summary.input_checks) + [
        InputCheck('load cells', number, finding)
        for number, found in enumerate(matched, start=1) if found is not None
        for finding in cell_findings(found)]
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
        'input_checks': [{'input': c.input, 'segment': c.segment, 'cause': c.finding.cause,
                          'message': c.finding.message, 'figure': c.finding.figure,
                          'windows': [c.seen, c.judged]} for c in checks],
        'seconds': summary.seconds, 'output': summary.output or None,
        'segments': segments,
    }


def _coefficient_match(segment, readings):
    """Return the CoefficientReading of a replay segment (same layout, its samples), or None."""
    if not readings or segment.first_ns is None:
        return None
    digest = segment.layout.digest()
    for reading in readings:
        layout = reading.segment.layout
        if layout is not None and layout.digest() == digest \
                and segment.first_ns <= reading.segment.first_ns <= segment.last_ns:
            return reading
    return None


def cell_findings(identified):
    """
    Return the mistakes an identified segment's cells show: [Finding] (none if not fitted).

    Each cell's fitted static load against its support's weight share
    (:func:`cvc_balance.identify.mistakes.cell_mistakes`), as the node checks it live.
    """
    if not identified.estimate.identifiable:
        return []
    read = {name: len(cell.time) for name, cell in (identified.cells or {}).items()}
    measured = measured_static_loads(identified.model, identified.estimate, read)
    return cell_mistakes(static_loads(identified.model), measured)


def segment_record(segment, identified=None, coefficients=None):
    """
    Return one layout segment of a replay as JSON-able data (see :func:`replay_record`).

    ``verdict`` is the verdict of record (:mod:`cvc_balance.identify.evidence`): the
    measured rotor's when the segment's load cells can tell, or without cells its
    vibration readings through stored coefficients (``coefficients``, a
    CoefficientReading: also in the record's ``coefficients``), else the layout's,
    labelled; ``balance`` the layout's assessment in detail (what the layout expects).
    """
    layout = segment.layout
    model = segment.model or RotorModel.from_layout(layout)     # aggregated once
    estimate, unfit = None if identified is None else identified.estimate, {}
    if estimate is None and coefficients is not None:
        estimate = coefficients.estimate
        if estimate is None:
            unfit = {'no_measurement': coefficients.reason,
                     'coefficients': coefficients.identity}
    of_record = verdict_of_record(model, estimate, top_speed=segment.max_speed, **unfit)
    verdict = of_record.layout
    balance = verdict_record(verdict)
    if balance is not None:          # replay's record also says where the static unbalance is
        balance['static_g_mm'] = g_mm(verdict.assessment.static_amount)
        balance['static_angle_deg'] = degrees_360(verdict.assessment.static_angle)
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
        'verdict': of_record.record(),
        'balance': balance,
        'model': choice.name if choice is not None else 'rigid bodies',
        'model_choice': choice.describe() if choice is not None else None,
        'model_deviation': None if choice is None else {
            'force_N': choice.deviation.force, 'moment_Nm': choice.deviation.moment,
            'torque_Nm': choice.deviation.torque},
        'identified': None,
        'coefficients': coefficient_record(coefficients, of_record)
        if identified is None else None,
        'life': support_records(segment, identified, of_record),
    }
    if identified is not None:
        record['identified'] = identified_record(identified, of_record)
    return record


def coefficient_record(reading, of_record):
    """
    Return what a segment's vibration readings gave through coefficients, or None.

    The coefficients' record named (file, sha256, made, layout, speed); the stretch read
    (log times s, speed rad/s, revolutions, where the angle came from); each sensor's 1x
    reading; each plane's unbalance (g mm, degrees, 95 % radius) and its fraction of the
    permissible share (from the verdict of record's measured rotor); or ``reason`` why the
    coefficients do not fit (then no readings or planes).
    """
    if reading is None:
        return None
    record = {**reading.identity, 'reason': reading.reason, 'window': None, 'speed': None,
              'revolutions': None, 'angle_from': None, 'readings': [], 'planes': []}
    run = reading.run
    if run is not None:
        record.update(window=[run.log_window.start, run.log_window.end],
                      speed=run.window.speed, revolutions=run.window.revolutions,
                      angle_from=run.angle_from,
                      readings=[{'channel': n, 'unit': run.units[n],
                                 'amplitude': abs(p.value),
                                 'phase_deg': degrees_360(math.atan2(p.value.imag,
                                                                     p.value.real)),
                                 'sigma': p.sigma} for n, p in run.phasors.items()])
    estimate, measured = reading.estimate, of_record.measured
    if estimate is None:
        return record
    judged = None if measured is None else measured.assessment
    fractions = list(judged.fractions) if judged is not None and judged.planes \
        else [None, None]
    from cvc_balance.bag.field_run import plane_weights
    for label, z, u, weights, fraction in zip(('I', 'II'), estimate.z, estimate.values,
                                              plane_weights(estimate.z), fractions):
        record['planes'].append({'plane': label, 'z': z, 'g_mm': g_mm(abs(u)),
                                 'angle_deg': degrees_360(math.atan2(u.imag, u.real)),
                                 'ci95_g_mm': g_mm(estimate.ci95(weights)),
                                 'fraction': fraction})
    return record


def _vector(vector, unit_scale, unit, known=True):
    """Return a vector's amount, angle (deg, 0..360) and 95 % radius; null if not known."""
    if not known:
        return {unit: None, 'angle_deg': None, f'ci95_{unit}': None}
    ci = vector.ci95 * unit_scale if math.isfinite(vector.ci95) else None
    return {unit: vector.amount * unit_scale, 'angle_deg': degrees_360(vector.angle),
            f'ci95_{unit}': ci}


def unbalance_summary(unbalance, known=True):
    """
    Return a RotorUnbalance as JSON-able data: kg m, kg m^2, g mm; degrees.

    ``known`` False (the readings could not tell): every amount, angle and radius null,
    never 0, which would read as perfectly balanced.
    """
    return {'static_unbalance': _vector(unbalance.static, 1.0, 'kg_m', known),
            'couple_unbalance': _vector(unbalance.couple, 1.0, 'kg_m2', known),
            'planes': [{'z': z, **_vector(v, 1e6, 'g_mm', known)} for z, v in unbalance.planes]}


def identified_summary(segment):
    """Return an IdentifiedSegment as JSON-able data (``identify --json``'s segment)."""
    estimate = segment.estimate
    known = estimate.identifiable
    return {
        'layout': {'name': segment.layout.name, 'digest': segment.layout.digest()},
        'from': segment.start_ns * 1e-9, 'to': segment.end_ns * 1e-9,
        'samples': segment.samples, 'readings': segment.readings, 'dropped': segment.dropped,
        'revolutions': segment.revolutions, 'identifiable': known,
        'identified': unbalance_summary(segment.identified, known),
        'layout_prediction': unbalance_summary(segment.declared),
        'residual': unbalance_summary(segment.residual, known),
        'fit': {'rms_N': estimate.sigma * math.sqrt(2) if known else None,
                'sigma_N': estimate.sigma if known else None,
                'biases_N': [[b.real, b.imag] for b in estimate.biases] if known else None},
    }


def identified_record(segment, of_record):
    """
    Return ``identify``'s segment record plus the measured rotor against the grade.

    ``grade``: each plane's identified unbalance over its permissible share, the
    equivalent grade and its level, from the measured rotor's verdict of ``of_record``
    (the one definition, :func:`cvc_balance.physics.assessment.judge_balance`); None when
    not identifiable or not judged.
    """
    record = identified_summary(segment)
    record.pop('layout')
    measured = of_record.measured
    record['grade'] = None
    if measured is None or measured.assessment is None:
        return record
    judged = measured.assessment
    record['grade'] = {'fractions': list(judged.fractions),
                       'equivalent_grade': judged.equivalent_grade,
                       'within_grade': judged.within_grade, 'level': measured.level}
    return record


def format_replay(record):
    """
    Describe a replay record (:func:`replay_record`) for people: ``replay``'s text.

    Per layout segment the verdict of record comes first, with its source; what the
    layout expects and how the rotor differs from it follow; then the measured and the
    layout's planes, the peak loads and the layout's warnings. Rendered from the record,
    so the text and ``replay --json`` cannot say different things.
    """
    lines = [f"bag {record['bag']}: {record['samples']} motion samples, {record['accepted']} "
             f"used, {record['rejected']} rejected, {record['dropped']} before any layout"
             + (f", {record['skipped']} skipped" if record['skipped'] else '')]
    lines += [f'  rejected: {r}' for r in record['rejected_reasons']]
    lines += [f'  problem: {p}' for p in record['problems']]
    lines += [f"  input check: {check_where(c)}: {c['message']}" for c in record['input_checks']]
    for segment in record['segments']:
        lines += _segment_lines(segment)
    rate = record['accepted'] / record['seconds'] if record['seconds'] else 0.0
    output = record['output']
    lines.append(f"{record['accepted']} samples in {record['seconds']:.3f} s "
                 f'({rate / 1e6:.3f} M samples/s, read + compute{" + write" if output else ""})'
                 + (f'; wrote {output}' if output else ''))
    return '\n'.join(lines)


def check_where(check):
    """Say where an input check of a record looked: the topic, or a segment's cells."""
    if check['segment'] is not None:
        return f"{check['input']} of segment {check['segment']}"
    seen, judged = check['windows']
    return f"{check['input']} ({seen} of {judged} windows of {MOTION_WINDOW} samples)"


def coefficient_lines(record):
    """Return the text lines of a segment's readings through coefficients (none: [])."""
    if record is None:
        return []
    layout = record['layout']
    made = ', '.join(part for part in (
        f"made {record['made']}" if record['made'] else '',
        f"at {record['speed']:.4g} rad/s" if record['speed'] else '',
        f"on layout '{layout['name']}' ({layout['digest']})" if layout else '') if part)
    lines = [f"  coefficients {record['file']} (sha256 {record['sha256']}"
             + (f'; {made}' if made else '') + ')']
    if record['reason'] is not None:
        return lines
    from cvc_balance.bag.field_run import angle_text
    lines.append(f"  read {record['window'][0]:.3f}-{record['window'][1]:.3f} s at "
                 f"{record['speed']:.4g} rad/s, {record['revolutions']} revolutions, angle "
                 f"from {angle_text(record['angle_from'])}: " + ', '.join(
                     f"{r['channel']} {r['amplitude']:.4g} {r['unit']} at "
                     f"{r['phase_deg']:.1f} deg" for r in record['readings']))
    for p in record['planes']:
        share = '' if p['fraction'] is None else f" = {p['fraction']:.2f} of its permissible"
        lines.append(f"  measured plane {p['plane']:2} (z {p['z']:.3f} m): {p['g_mm']:.1f} g mm "
                     f"at {p['angle_deg']:.1f} deg +- {p['ci95_g_mm']:.1f} g mm (95 %){share}, "
                     'through the coefficients')
    return lines


def _segment_lines(segment):
    layout, verdict = segment['layout'], segment['verdict']
    start = segment['from'] if segment['from'] is not None else 0.0
    lines = [f"layout '{layout['name']}' ({layout['digest']}) from {start:.3f} s: "
             f"{segment['samples']} samples, top speed {segment['top_speed']:.4g} rad/s",
             f"  verdict {verdict['headline']}"]
    if verdict['source'] == 'measured':
        lines.append(f"  {verdict['layout_expects']}")
    if verdict['disagreement']:
        lines.append(f"  {verdict['disagreement']}")
    lines += coefficient_lines(segment.get('coefficients'))
    identified = segment['identified']
    if identified is not None and identified['identifiable']:
        fractions = (identified['grade'] or {}).get('fractions') or [None, None]
        for label, p, fraction in zip(('I', 'II'), identified['identified']['planes'],
                                      fractions):
            share = '' if fraction is None else f' = {fraction:.2f} of its permissible'
            lines.append(f"  measured plane {label:2} (z {p['z']:.3f} m): {p['g_mm']:.1f} g mm at "
                         f"{p['angle_deg']:.1f} deg +- {p['ci95_g_mm']:.1f} g mm (95 %){share}")
    balance = segment['balance']
    if balance is not None:
        for label, p in zip(('I', 'II'), balance['planes']):
            lines.append(f"  layout plane {label:2} (z {p['z']:.3f} m): unbalance {p['g_mm']:.1f} "
                         f"g mm at {p['angle_deg']:.1f} deg = {p['fraction']:.2f} of its "
                         f"permissible {p['permissible_g_mm']:.1f} g mm")
        if not balance['planes']:
            lines.append(f"  layout static unbalance {balance['static_g_mm']:.1f} g mm = "
                         f"{balance['static_g_mm'] / balance['permissible_g_mm']:.2f} of the "
                         f"permissible {balance['permissible_g_mm']:.1f} g mm")
    peaks = ', '.join(f'{name} {peak:.1f} N'
                      for name, peak in segment['peak_support_load_N'].items())
    lines.append(f"  peak load on the stator {segment['peak_load_N']:.1f} N; per support: "
                 + peaks)
    lines += [f'  warning: {warning}' for warning in segment['warnings']]
    if segment.get('life'):
        lines += life_lines(segment['life'], segment['top_speed'])
    if segment['model_deviation'] is not None:
        lines.append(f"  {segment['model_choice']}")
    return lines
