"""
Field balancing commands: calibrate, influence, correct and report (docs: Field balancing).

``calibrate`` makes influence coefficients from recorded baseline and trial runs and saves
them; ``influence`` does the same from readings typed in by hand and gives the
corrections; ``correct`` gives a run's corrections (from coefficients, or from the
unbalance its load cells identify) with the weights at the layout's sites; ``report``
writes that as one HTML page with PNG figures. Warnings go to stderr as
``cvc-balance: warning: ...`` and into the JSON.
"""

import datetime
import math
from pathlib import Path
import sys

from cvc_balance.cli.arguments import (add_keyphasor, count, input_bag, input_file,
                                       positive, print_json, renamed, within)
from cvc_balance.files import check_output, moved_into_when_done, replaced_when_done
from cvc_balance.physics import limits
from cvc_balance.physics.frames import degrees

MAX_RECORD_BYTES = 16 * 2**20
"""Largest coefficient record read, bytes."""
MAX_SEGMENT = 10**6
"""Largest layout segment number taken."""


def register(commands):
    """Add calibrate, influence, correct and report."""
    calibrate = commands.add_parser(
        'calibrate', help='influence coefficients from a baseline run and trial-weight runs',
        description='Read the 1x amplitude and phase of every sensor (load cells, vibration '
        'channels: Float64 topics, Vector3Stamped and Imu axes) against the encoder or a '
        'keyphasor over whole revolutions at steady speed in a baseline run and one run per '
        'trial weight, and save the influence coefficients (least squares over the runs).')
    calibrate.add_argument('runs', nargs='+', type=input_bag, metavar='RUN',
                           help='BASELINE then one bag per trial run')
    calibrate.add_argument('--trial', action='append', default=[],
                           metavar='PLANE:MASS_KG@ANGLE_DEG,R_M',
                           help='the trial weight of each trial run, in order (I:0.2@0,0.68); '
                           'default: the one each run was recorded with (record or simulate '
                           '--run trial --trial ...)')
    calibrate.add_argument('--keep-trial', action='store_true',
                           help='each trial weight stayed on for the runs after it')
    calibrate.add_argument('--layout-file', type=input_file, metavar='FILE',
                           help="layout to check the coefficients against (default: the "
                           "baseline's)")
    calibrate.add_argument('--segment', type=segment_number, nargs='+', metavar='N',
                           help='layout segment to read: one number for every run, or one '
                           'per run (default: each run\'s segment with the longest steady '
                           'stretch; a run is never read across a layout change)')
    _accept_mismatch(calibrate)
    _run_options(calibrate)
    calibrate.add_argument('--speed', type=within(limits.SPEED), metavar='W',
                           help='read the runs at this steady speed, rad/s (default: the '
                           "baseline's)")
    calibrate.add_argument('--sensor', action='append', metavar='NAME',
                           help='channel to use (repeat; default: cell forces x, y and every '
                           'vibration channel: Float64 topics, Vector3Stamped and Imu axes as '
                           'TOPIC/x ...)')
    calibrate.add_argument('-o', '--output', metavar='FILE', help='save the coefficients '
                           '(YAML)')
    calibrate.add_argument('--json', action='store_true', help='print the record as JSON')
    calibrate.set_defaults(run=run_calibrate)

    influence = commands.add_parser(
        'influence', help='influence coefficients and corrections from readings by hand',
        description='Readings typed in as AMPLITUDE@PHASE_DEG per sensor, any unit, any '
        'instrument: the baseline, then per trial run its plane, its weight (MASS@DEG, any '
        'mass unit; corrections come in that unit) and the readings with it on.')
    influence.add_argument('--baseline', nargs='+', required=True, metavar='A',
                           help='baseline readings, one per sensor (170@112 53@78)')
    influence.add_argument('--trial', nargs='+', action='append', required=True,
                           metavar='ARG', help='PLANE MASS@DEG B1 B2 ...: one trial run '
                           '(repeat per run); MASS_KG@DEG,R_M gives the radius (kg m)')
    influence.add_argument('--keep-trial', action='store_true',
                           help='each trial weight stayed on for the runs after it')
    influence.add_argument('--noise', type=positive, metavar='X',
                           help="the readings' standard error (their unit): judge trials by "
                           'signal to noise instead of by relative change')
    influence.add_argument('--sensors', nargs='+', metavar='NAME',
                           help='a name per reading, in order (default sensor 1, 2, ...); '
                           'load cells as <support>/force_x, <support>/force_y')
    influence.add_argument('--unit', default='as read', metavar='TEXT',
                           help="the readings' unit, for the record (default 'as read')")
    influence.add_argument('--speed', type=within(limits.SPEED), metavar='W',
                           help='the runs\' steady speed, rad/s (for the record and the check)')
    influence.add_argument('--layout-file', type=input_file, metavar='FILE',
                           help="check the coefficients against this layout's physics: cells' "
                           'readings in N, trials as MASS_KG@DEG,R_M')
    _accept_mismatch(influence)
    influence.add_argument('-o', '--output', metavar='FILE',
                           help='save the coefficients as calibrate -o does (YAML)')
    influence.add_argument('--json', action='store_true', help='print one JSON object')
    influence.set_defaults(run=run_influence)

    trial = commands.add_parser(
        'trial-weight', help='the trial weight to use per plane, before the trial runs',
        description='Per correction plane, the trial mass at the plane\'s radius that moves '
        'the load cells\' 1x readings by --standard-errors of the baseline run (their change '
        'as the layout\'s physics predicts it), capped so that the trial alone adds no more '
        'unbalance than the grade allows in its plane and no more rotating force than 10 % '
        'of a bearing\'s static load (the common starting rule, used when no baseline is '
        'given), rounded up to the kit.')
    trial.add_argument('bag', nargs='?', type=input_bag, metavar='BASELINE',
                       help='the baseline run (.mcap); '
                       'without it, --layout-file alone')
    trial.add_argument('--layout-file', type=input_file, metavar='FILE',
                       help="the layout (default: the baseline's)")
    trial.add_argument('--standard-errors', type=positive, default=20.0, metavar='N',
                       help='how many standard errors of the baseline the trial should move '
                       'the readings by (default 20)')
    trial.add_argument('--sigma', type=positive, metavar='N',
                       help="without a baseline: the cells' 1x standard error, N")
    trial.add_argument('--speed', type=within(limits.SPEED), metavar='W',
                       help='the steady speed of the runs, rad/s (default: the baseline\'s, '
                       "or the layout's service speed)")
    trial.add_argument('--segment', type=segment_number, metavar='N',
                       help='layout segment of the baseline to read')
    _run_options(trial)
    trial.add_argument('--json', action='store_true', help='print one JSON object')
    trial.set_defaults(run=run_trial_weight)

    for name, helptext in (('correct', 'the corrections of a run, at the layout\'s sites'),
                           ('report', 'an HTML report of a run\'s corrections, with figures')):
        command = commands.add_parser(
            name, help=helptext,
            description='The corrections of a run: from influence coefficients '
            '(--coefficients) or, without, from the unbalance its load cells identify; the '
            'continuous optimum, the vector split between the two nearest sites and a '
            "mixed-integer plan (HiGHS) with the kit's weights at the layout's "
            'balancing.sites, each with the residual it leaves and the grade before and '
            'after.' + (' Writes DIR/report.html and its PNG figures.' if name == 'report'
                        else ''))
        command.add_argument('bag', type=input_bag, metavar='RUN', nargs='?',
                             help='the run to correct (.mcap); or --readings')
        command.add_argument('--coefficients', type=input_file, metavar='FILE',
                             help='influence coefficients (from calibrate or influence -o)')
        command.add_argument('--readings', nargs='+', metavar='A',
                             help='readings by hand instead of a run, AMPLITUDE@PHASE_DEG, one '
                             "per sensor in the coefficients' order (with --coefficients)")
        command.add_argument('--weights-on', nargs='+', metavar='PLANE:SITE:MASS',
                             help='weights bolted on already, kg, at a site angle in degrees '
                             'or #HOLE (I:15:0.2 II:#7:0.05): the plan says what to add and '
                             'what to take off, with the fewest changes')
        command.add_argument('--speed', type=within(limits.SPEED), metavar='W',
                             help="the run's (or readings') steady speed, rad/s (default: the "
                             "coefficients'; load cells' coefficients are scaled as the speed "
                             'squared)')
        command.add_argument('--layout-file', type=input_file, metavar='FILE',
                             dest='layout',
                             help="layout with balancing.sites (default: the bag's)")
        renamed(command, '--layout', '--layout-file FILE')
        command.add_argument('--objective', choices=('fewest', 'residual'),
                             help='fewest weights within the grade (default with a grade '
                             'or --limit), or the smallest residual')
        command.add_argument('--limit', type=positive, metavar='X',
                             help='largest residual reading allowed (the sensors\' unit), '
                             'with --coefficients')
        command.add_argument('--max-weights', type=within(limits.MAX_WEIGHTS), metavar='N',
                             help='most weights in the plan (default for --objective '
                             'residual: two per plane with sites)')
        command.add_argument('--time-limit', type=within(limits.TIME_LIMIT), default=30.0,
                             metavar='S',
                             help='seconds the mixed-integer search may take (default 30)')
        command.add_argument('--segment', type=segment_number, metavar='N',
                             help='layout segment to read (default: the one with the longest '
                             'steady stretch; a run is never read across a layout change)')
        _accept_mismatch(command)
        _run_options(command)
        if name == 'report':
            command.add_argument('--after', type=input_bag, metavar='BAG',
                                 help='a check run after the '
                                 'weights went on: its identified unbalance is shown too')
            command.add_argument('-o', '--output', required=True, metavar='DIR',
                                 help='directory for report.html and its figures')
        command.add_argument('--json', action='store_true', help='print one JSON object')
        command.set_defaults(run=run_correct if name == 'correct' else run_report)


def segment_number(text):
    """Parse a layout segment's number, 1 to 10^6 (argparse type)."""
    import argparse

    value = count(text)
    if value > MAX_SEGMENT:
        raise argparse.ArgumentTypeError(f'must be <= {MAX_SEGMENT}, got {text!r}')
    return value


def _accept_mismatch(command):
    command.add_argument('--accept-mismatch', action='store_true',
                         help="go on when the measured coefficients disagree with the "
                         "layout's physics (beyond a factor 3 or 45 deg), with a warning")


def _run_options(command):
    command.add_argument('--speed-tolerance', type=within(limits.SPEED_TOLERANCE), default=1.0,
                         metavar='PERCENT',
                         help='speeds within this of the steady speed count as steady '
                         '(default 1 %%)')
    command.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    add_keyphasor(command, 'a once-per-revolution tach instead of an encoder, in every run '
                  'read: the rotor angle is 0 at each of its marks and interpolated between '
                  'them (the phases are then against the mark); never read as a vibration '
                  'channel (default: keyphasor, when a run has neither joint_states nor '
                  'speed)')


def run_inputs(args):
    """Return the runs' input topics the options name (the keyphasor, as replay takes it)."""
    from cvc_balance.bag.inputs import InputTopics
    return InputTopics(keyphasor=args.keyphasor, keyphasor_edge=args.keyphasor_edge,
                       keyphasor_threshold=args.keyphasor_threshold)


def warn(lines):
    """Print each warning on stderr, one line each."""
    for line in lines:
        print(f'cvc-balance: warning: {line}', file=sys.stderr)


# -- calibrate ---------------------------------------------------------------------------

def run_calibrate(args):
    """Run ``cvc-balance calibrate``."""
    from cvc_balance.bag.field_run import calibrate_runs, check_calibration
    from cvc_balance.bag.run_label import calibration_trials
    from cvc_balance.field.coefficients import calibration_mapping
    from cvc_balance.field.notation import bag_trial
    from cvc_balance.physics.documents import dump_document

    if len(args.runs) < 2:
        raise ValueError('give the baseline run and one run per trial weight')
    trials = calibration_trials(args.runs, [bag_trial(text) for text in args.trial])
    if args.output:
        check_output(args.output, args.runs)
    calibration, runs, speed_warnings = calibrate_runs(
        args.runs[0], args.runs[1:], trials, args.keep_trial, args.sensor, args.speed,
        args.speed_tolerance / 100.0, args.joint_name, args.layout_file, args.segment,
        run_inputs(args))
    check = check_calibration(calibration, runs, trials, args.keep_trial)
    if check.mismatch and not args.accept_mismatch:
        raise ValueError(check.refusal)
    baseline = runs[0]
    record = calibration_mapping(
        calibration, [baseline.units[n] for n in calibration.sensors], 'kg m',
        baseline.window.speed, args.keep_trial, trials,
        [run_identity(run, 'baseline' if k == 0 else f'trial {k}')
         for k, run in enumerate(runs)], _layout(baseline.layout),
        check_mapping(check))
    record['warnings'] = speed_warnings + ([check.message] if check.mismatch else []) \
        + record['warnings']
    warn(record['warnings'])
    if args.output:
        with replaced_when_done(args.output) as path:
            path.write_text('# Influence coefficients (cvc-balance calibrate; the format: the '
                            'docs\' "Coefficient file")\n' + dump_document(record))
    if args.json:
        print_json(record)
    else:
        print(format_record(record))
        if args.output:
            print(f'written: {args.output}')
    return 0


def check_mapping(check):
    """Return a ModelCheck as plain data: the record's and the JSON's ``model_check``."""
    if not check.checked:
        return {'checked': False, 'note': check.note}
    predicted = [[None if math.isnan(v.real) else _polar(complex(v)) for v in row]
                 for row in check.predicted]
    return {'checked': True, 'agrees': not check.mismatch,
            'sensors': list(check.sensors), 'predicted': predicted,
            'planes': [{'plane': p.plane, 'factor': abs(p.factor),
                        'phase_deg': degrees(math.atan2(p.factor.imag, p.factor.real)),
                        'ci95': p.ci95 if math.isfinite(p.ci95) else None,
                        'pattern': p.pattern if math.isfinite(p.pattern) else None,
                        'agrees': p.agrees} for p in check.planes],
            'cause': check.cause or None, 'message': check.message or None}


def run_identity(run, role):
    """Return a run's identity and steady window as plain data."""
    return {'role': role, 'bag': run.bag, 'date': bag_date(run.first_ns),
            'angle_from': run.angle_from,
            'segment': segment_mapping(run.chosen), 'segments': len(run.segments),
            'speed': run.window.speed, 'revolutions': run.window.revolutions,
            'window': [run.window.start, run.window.end], 'speed_spread': run.window.spread,
            'readings': [{'channel': n, 'unit': run.units[n], **_polar(p.value),
                          'sigma': p.sigma, 'samples': p.samples}
                         for n, p in run.phasors.items()]}


def segment_mapping(segment):
    """Return a layout segment as plain data: number, times (log, s), layout, stretch."""
    window = segment.longest
    return {'number': segment.number, 'from': segment.start, 'to': segment.end,
            'layout': _layout(segment.layout),
            'steady': None if window is None else {
                'window': [window.start, window.end], 'speed': window.speed,
                'revolutions': window.revolutions, 'speed_spread': window.spread},
            'stretches': len(segment.stretches), 'note': segment.note or None}


def segment_line(mapping):
    """Return a segment mapping as people read it (one line)."""
    layout = mapping['layout']
    where = f"layout '{layout['name']}' ({layout['digest']})" if layout else 'no layout'
    text = f"segment {mapping['number']} ({mapping['from']:.3f}-{mapping['to']:.3f} s, {where})"
    steady = mapping['steady']
    if steady is None:
        return f"{text}: no steady stretch ({mapping['note']})"
    return (f"{text}: steady {steady['window'][0]:.3f}-{steady['window'][1]:.3f} s at "
            f"{steady['speed']:.4g} rad/s, {steady['revolutions']} revolutions")


def bag_date(log_ns):
    """Return a log time (ns since 1970, UTC) as ISO 8601 text."""
    moment = datetime.datetime.fromtimestamp(log_ns * 1e-9, datetime.timezone.utc)
    return moment.isoformat(timespec='seconds').replace('+00:00', 'Z')


def _polar(value):
    return {'amplitude': abs(value),
            'phase_deg': degrees(math.atan2(value.imag, value.real)) % 360.0}


def format_record(record):
    """Format a coefficient record for people."""
    lines = []
    for run in record['runs']:
        lines.append(f"{run['role']}: {run['bag']} at {run['speed']:.4g} rad/s, "
                     f"{run['revolutions']} revolutions"
                     + (f"; angle from {angle_text(run['angle_from'])}"
                        if run.get('angle_from') else ''))
        if run.get('segment'):
            lines.append(f"  read in {segment_line(run['segment'])}"
                         + (f" (of {run['segments']}; --segment to choose)"
                            if run.get('segments', 1) > 1 else ''))
    planes = record['planes']
    lines.append(f"influence coefficients ({record['reading_units'][0]} per "
                 f"{record['correction_unit']}), condition number "
                 f"{_number(record['condition_number'])}:")
    lines.append(f"  {'sensor':22}" + ''.join(f'{"plane " + p:>26}' for p in planes))
    for s, name in enumerate(record['sensors']):
        cells = []
        for j in range(len(planes)):
            entry = record['coefficients'][s][j]
            text = f"{entry['amplitude']:.4g} @ {_deg(entry['phase_deg'])}"
            if record['ci95'] is not None:
                text += f" +-{record['ci95'][s][j]:.2g}"
            cells.append(f'{text:>26}')
        lines.append(f'  {name:22}' + ''.join(cells))
    for trial in record['trials']:
        seen = f"{trial['snr']:.3g} standard errors" if trial['snr'] is not None else \
            f"{trial['relative_change']:.0%} of the readings"
        # The weight each trial carried, as calibrate used it (typed, or recorded in its bag).
        weight = (f"{trial['mass']:g} kg at {trial['angle_deg']:g} deg, r {trial['radius']:g} m"
                  if record['correction_unit'] == 'kg m' else
                  f"{trial['mass']:g} at {trial['angle_deg']:g} deg")
        lines.append(f"  trial run {trial['run']} (plane {trial['plane']}, {weight}): largest "
                     f"change {trial['largest_change']:.4g} = {seen}")
    lines.append(check_line(record.get('model_check')))
    return '\n'.join(lines)


def check_line(check):
    """Return the model check as one line for people."""
    if not check:
        return "not checked against the layout's physics"
    if not check['checked']:
        return f"not checked against the layout's physics: {check['note']}"
    said = ', '.join(f"plane {p['plane']} {p['factor']:.3g} times "
                     f"{int(round(p['phase_deg'])):+d} deg" for p in check['planes'])
    if check['agrees']:
        return f"the layout's physics predicts these coefficients: measured/predicted {said}"
    return f"MISMATCH with the layout's physics (accepted): measured/predicted {said}"


def angle_text(angle_from):
    """Return where a run's angle came from, for people (:func:`field_run.angle_text`)."""
    from cvc_balance.bag.field_run import angle_text as text
    return text(angle_from)


def _number(value):
    return 'inf' if value is None else f'{value:.3g}'


def _deg(value):
    """Return an angle in degrees for people, 0.0-359.9 (359.97 reads 0.0)."""
    return f'{round(value, 1) % 360.0:.1f}'


# -- trial-weight ------------------------------------------------------------------------

def run_trial_weight(args):
    """Run ``cvc-balance trial-weight``."""
    from cvc_balance.bag.field_run import trial_advice

    if args.bag is None and args.segment is not None:
        raise ValueError('--segment needs a baseline run')
    if args.bag is not None and args.sigma is not None:
        raise ValueError("--sigma is for the layout alone: a baseline gives its own")
    advice, run, layout, speed = trial_advice(
        args.bag, args.layout_file, args.standard_errors, args.sigma, args.speed, args.segment,
        args.speed_tolerance / 100.0, args.joint_name, run_inputs(args))
    summary = plain({
        'run': None if run is None else run_identity(run, 'baseline'),
        'layout': _layout(layout), 'speed': speed, 'standard_errors': args.standard_errors,
        'planes': [{'plane': a.plane, 'z': a.z, 'radius': a.radius, 'mass': a.mass,
                    'unbalance_g_mm': a.unbalance * 1e6, 'standard_errors': a.standard_errors,
                    'wanted_g_mm': None if a.wanted is None else a.wanted * 1e6,
                    'grade_cap_g_mm': a.grade_cap * 1e6,
                    'bearing_cap_g_mm': a.bearing_cap * 1e6
                    if math.isfinite(a.bearing_cap) else None,
                    'capped_by': a.capped_by,
                    'kit': None if a.kit is None else {
                        'masses': list(a.kit), 'mass': sum(a.kit),
                        'standard_errors': a.kit_errors},
                    'note': a.note or None} for a in advice]})
    if args.json:
        print_json(summary)
        return 0
    source = (f"baseline {run.bag}, {segment_line(segment_mapping(run.chosen))}; angle from "
              f"{angle_text(run.angle_from)}" if run is not None
              else f"layout '{layout.name}' alone")
    lines = [f'trial weights at {speed:.4g} rad/s ({source}):']
    for a in summary['planes']:
        seen = '' if a['standard_errors'] is None else \
            f", moves the readings {a['standard_errors']:.3g} standard errors"
        lines.append(f"  plane {a['plane']} (z {a['z']:+.3f} m): {a['mass'] * 1000:.1f} g at r "
                     f"{a['radius']:.3f} m ({a['unbalance_g_mm']:.0f} g mm){seen}")
        if a['kit'] is not None:
            kit = ' + '.join(f'{m * 1000:g} g' for m in a['kit']['masses'])
            seen = '' if a['kit']['standard_errors'] is None else \
                f" ({a['kit']['standard_errors']:.3g} standard errors)"
            lines.append(f'    from the kit: {kit}{seen}')
        caps = f"grade {a['grade_cap_g_mm']:.0f} g mm"
        if a['bearing_cap_g_mm'] is not None:
            caps += f", 10 % of a bearing's static load {a['bearing_cap_g_mm']:.0f} g mm"
        lines.append(f'    caps: {caps}')
        if a['note']:
            lines.append(f"    {a['note']}")
    print('\n'.join(lines))
    return 0


# -- influence (by hand) -----------------------------------------------------------------

def run_influence(args):
    """Run ``cvc-balance influence``."""
    import numpy as np

    from cvc_balance.bag.field_run import permissible_unbalance
    from cvc_balance.field import calibrate, continuous_correction, problem_from_readings
    from cvc_balance.field.coefficients import calibration_mapping
    from cvc_balance.field.model_check import check_coefficients, ModelCheck
    from cvc_balance.field.notation import hand_trial, reading
    from cvc_balance.physics.documents import dump_document

    baseline = [reading(text, f'baseline reading {k + 1}') for k, text in
                enumerate(args.baseline)]
    names = args.sensors or [f'sensor {k + 1}' for k in range(len(baseline))]
    if len(names) != len(baseline) or len(set(names)) != len(names):
        raise ValueError(f'--sensors: give {len(baseline)} different names, one per baseline '
                         f'reading, got {len(names)}')
    trials, readings = [], []
    for k, values in enumerate(args.trial):
        if len(values) != 2 + len(baseline):
            raise ValueError(f'--trial {k + 1}: give PLANE MASS@DEG and {len(baseline)} '
                             f'readings (one per sensor, as the baseline), got '
                             f'{len(values)} values')
        trials.append(hand_trial(values[0], values[1]))
        readings.append([reading(text, f'trial {k + 1} reading {s + 1}')
                         for s, text in enumerate(values[2:])])
    if args.output:
        check_output(args.output, [args.layout_file])
    in_kg_m = all(',' in values[1] for values in args.trial)
    if not in_kg_m and any(',' in values[1] for values in args.trial):
        raise ValueError('--trial: give every trial weight with its radius (MASS_KG@DEG,R_M) '
                         'or none')
    sigma = None if args.noise is None else np.full(len(baseline), args.noise)
    calibration = calibrate(baseline, trials, readings, names, args.keep_trial, sigma,
                            None if sigma is None else np.tile(sigma, (len(trials), 1)))
    layout, speed = None, args.speed
    check = ModelCheck(False, 'no --layout-file: the coefficients are not checked against '
                       'physics')
    if args.layout_file:
        from cvc_balance.physics.layout_file import load_layout
        layout = load_layout(args.layout_file)
        speed = speed or layout.balancing.service_speed
        if not (in_kg_m and speed):
            raise ValueError('--layout-file checks the coefficients against physics: give '
                             'each trial weight as MASS_KG@DEG,R_M, the readings in N with '
                             '--sensors naming each cell channel (front/force_x ...), and '
                             '--speed (rad/s) unless the layout has a service speed')
        check = check_coefficients(layout, calibration, speed, trials, args.keep_trial,
                                   permissible_unbalance(layout, speed))
        if check.mismatch and not args.accept_mismatch:
            raise ValueError(check.refusal)
    unit = 'kg m' if in_kg_m else 'trial mass unit'
    problem = problem_from_readings(calibration, baseline, unit=unit)
    correction = continuous_correction(problem)
    residual = problem.residual(correction)
    radius = {t.plane: t.radius for t in trials}
    summary = {
        'planes': list(calibration.planes), 'sensors': len(baseline), 'sensor_names': names,
        'unit': unit, 'speed': speed,
        'coefficients': [[_polar(v) for v in row] for row in calibration.matrix],
        'ci95': None if calibration.ci95 is None else calibration.ci95.tolist(),
        'condition_number': calibration.condition if math.isfinite(calibration.condition)
        else None,
        'corrections': [{'plane': p, 'mass': abs(u) / radius[p], 'radius': radius[p]
                         if in_kg_m else None, 'unbalance': abs(u),
                         'angle_deg': degrees(math.atan2(u.imag, u.real)) % 360.0}
                        for p, u in zip(calibration.planes, correction)],
        'residual': [_polar(r) for r in residual],
        'residual_rms': float(np.sqrt(np.mean(np.abs(residual) ** 2))),
        'keep_trial': args.keep_trial,
        'trials': [{'run': c.run + 1, 'plane': c.plane, 'largest_change': c.change,
                    'snr': c.snr, 'relative_change': c.relative, 'too_small': c.too_small,
                    'weak': c.weak} for c in calibration.checks],
        'model_check': check_mapping(check),
        'warnings': ([check.message] if check.mismatch else []) + list(calibration.warnings),
    }
    if args.keep_trial:
        on = {p: 0j for p in calibration.planes}
        for trial in trials:
            on[trial.plane] += trial.unbalance
        summary['add_to_trials'] = [
            {'plane': p, 'mass': abs(u - on[p]) / radius[p],
             'angle_deg': degrees(math.atan2((u - on[p]).imag, (u - on[p]).real)) % 360.0}
            for p, u in zip(calibration.planes, correction)]
    warn(summary['warnings'])
    if args.output:
        runs = [{'role': 'baseline', 'source': 'by hand',
                 'readings': [{'channel': n, **_polar(v)} for n, v in zip(names, baseline)]}]
        runs += [{'role': f'trial {k + 1}', 'source': 'by hand',
                  'readings': [{'channel': n, **_polar(v)} for n, v in zip(names, values)]}
                 for k, values in enumerate(readings)]
        record = calibration_mapping(calibration, [args.unit] * len(names), unit, speed,
                                     args.keep_trial, trials, runs, _layout(layout),
                                     check_mapping(check))
        record['warnings'] = summary['warnings']
        with replaced_when_done(args.output) as path:
            path.write_text('# Influence coefficients (cvc-balance influence, readings by hand; '
                            'the format: the docs\' "Coefficient file")\n'
                            + dump_document(plain(record)))
        summary['written'] = args.output
    if args.json:
        print_json(summary)
        return 0
    lines = [f"influence coefficients (reading per {unit}), condition number "
             f"{_number(summary['condition_number'])}:"]
    for name, row in zip(names, summary['coefficients']):
        lines.append(f'  {name}: ' + '   '.join(
            f"plane {p}: {e['amplitude']:.4g} @ {_deg(e['phase_deg'])}"
            for p, e in zip(summary['planes'], row)))
    if args.layout_file:
        lines.append(check_line(summary['model_check']))
    lines.append('corrections (remove the trial weights; ' + (
        'kg at the trials\' radii):' if in_kg_m else 'same mass unit as the trials):'))
    for c in summary['corrections']:
        at = f" at r {c['radius']:g} m" if c['radius'] else ''
        lines.append(f"  plane {c['plane']}: {c['mass']:.4g}{at} @ {_deg(c['angle_deg'])} deg")
    for c in summary.get('add_to_trials', ()):
        lines.append(f"  with the trials left on, add in plane {c['plane']}: "
                     f"{c['mass']:.4g} @ {_deg(c['angle_deg'])} deg")
    lines.append('residual readings: ' + ', '.join(
        f"{r['amplitude']:.3g} @ {r['phase_deg']:.0f}" for r in summary['residual']))
    if args.output:
        lines.append(f'written: {args.output}')
    print('\n'.join(lines))
    return 0


# -- correct and report ------------------------------------------------------------------

def read_coefficients(path):
    """Return (Calibration, record) of a coefficient file (YAML 1.2 or JSON, regular file)."""
    from cvc_balance.field.coefficients import calibration_from_mapping
    from cvc_balance.physics.documents import read_document

    return calibration_from_mapping(read_document(path, MAX_RECORD_BYTES), str(path))


def correction_summary(args):
    """Compute the corrections the arguments ask for; return (summary, FieldCorrection)."""
    from cvc_balance.bag.field_run import correct_run

    from cvc_balance.bag.field_run import correct_readings
    from cvc_balance.field.notation import reading, weight_on

    weights_on = [weight_on(text) for text in args.weights_on or ()]
    calibration = record = None
    if args.coefficients:
        calibration, record = read_coefficients(args.coefficients)
    if args.readings is not None:
        if args.bag is not None or calibration is None:
            raise ValueError('--readings: give the coefficients (--coefficients FILE) and no '
                             'run')
        if args.segment is not None:
            raise ValueError('--segment is for a run, not --readings')
        readings = [reading(text, f'reading {k + 1}') for k, text in enumerate(args.readings)]
        result = correct_readings(readings, calibration, record, args.layout, args.objective,
                                  args.limit, args.max_weights, args.speed, args.time_limit,
                                  args.accept_mismatch, weights_on)
        return summarise(result, record), result
    if args.bag is None:
        raise ValueError('give the run to correct (RUN), or --readings with --coefficients')
    from cvc_balance.bag.field_run import coefficients_identity
    result = correct_run(args.bag, calibration, record, args.layout, args.objective,
                         args.limit, args.max_weights, args.speed_tolerance / 100.0,
                         args.joint_name, args.time_limit, args.segment, args.accept_mismatch,
                         args.speed, weights_on, run_inputs(args),
                         coefficients_identity(args.coefficients, record)
                         if args.coefficients else None)
    return summarise(result, record), result


def run_correct(args):
    """Run ``cvc-balance correct``."""
    summary, _ = correction_summary(args)
    warn(summary['warnings'])
    if args.json:
        print_json(summary)
    else:
        print(format_summary(summary))
    return 0


def run_report(args):
    """Run ``cvc-balance report``."""
    from cvc_balance.report import write_report

    check_output(args.output, [a for a in (args.bag, args.after, args.coefficients,
                                           args.layout) if a], directory=True)
    summary, result = correction_summary(args)
    if args.after:
        summary['measured_after'] = measured_after(args.after, args, result)
    out = Path(args.output)
    with moved_into_when_done(out) as staging:
        files = [out / f.relative_to(staging) for f in write_report(summary, staging)]
    warn(summary['warnings'])
    if args.json:
        print_json({'report': str(out / 'report.html'), 'files': [str(f) for f in files],
                    'summary': summary})
    else:
        print(format_summary(summary))
        print(f"report: {out / 'report.html'} ({len(files) - 1} figures)")
    return 0


def measured_after(path, args, result):
    """Return the identified unbalance of a check run, per plane, and its grade."""
    from cvc_balance.bag.field_run import grade_view, read_run

    if result.grade is None:
        raise ValueError('--after needs load cells and a layout with two correction planes '
                         'in the run (to compare the identified unbalance)')
    run = read_run(path, None, None, args.speed_tolerance / 100.0, args.joint_name,
                   args.layout, names=run_inputs(args))
    view = grade_view(run, args.joint_name)
    if view is None:
        raise ValueError(f'{path}: no load cells to identify the unbalance after the '
                         'correction from')
    grade = result.grade
    value = grade.equivalent_grade(view.before)
    return plain({'bag': str(path), 'date': bag_date(run.first_ns),
                  'layout': _layout(run.layout), 'speed': run.window.speed,
                  'equivalent_grade': value, 'within_grade': value <= grade.grade,
                  'planes': [_plane_vector(p, z, u, ci) for p, z, u, ci in
                             zip(view.planes, view.z, view.before, view.ci95)]})


def _segment_grade(view):
    """Return a segment's identified grade (null without cells) as plain data."""
    if view is None:
        return None
    value = view.equivalent_grade(view.before)
    return {'grade': view.grade, 'equivalent_grade': value, 'within_grade': value <= view.grade}


def _layout(layout):
    return None if layout is None else {'name': layout.name, 'digest': layout.digest()}


def _plane_vector(plane, z, value, ci95=None, permissible=None):
    out = {'plane': plane, 'z': z, 'g_mm': abs(value) * 1e6,
           'angle_deg': degrees(math.atan2(value.imag, value.real)) % 360.0}
    if ci95 is not None:
        out['ci95_g_mm'] = ci95 * 1e6 if math.isfinite(ci95) else None
    if permissible is not None:
        out['permissible_g_mm'] = permissible * 1e6
    return out


def _run_mapping(run):
    """Return what was corrected: a run's identity and window, or readings by hand."""
    if getattr(run, 'window', None) is None:
        return {'bag': None, 'source': 'readings by hand', 'date': None, 'angle_from': None,
                'layout': _layout(run.layout), 'speed': run.speed, 'revolutions': None,
                'window': None, 'speed_spread': None, 'segment': None}
    return {'bag': run.bag, 'source': 'run', 'date': bag_date(run.first_ns),
            'angle_from': run.angle_from,
            'layout': _layout(run.layout), 'speed': run.window.speed,
            'revolutions': run.window.revolutions, 'window': [run.window.start, run.window.end],
            'speed_spread': run.window.spread, 'segment': run.segment}


def _readings(run):
    if getattr(run, 'window', None) is None:
        return [{'channel': n, 'unit': run.units[n], **_polar(v), 'sigma': None}
                for n, v in run.readings.items()]
    return [{'channel': n, 'unit': run.units[n], **_polar(p.value), 'sigma': p.sigma}
            for n, p in run.phasors.items()]


def layout_expects(layout, grade):
    """
    Return what the layout expects beside the measured grade: the verdict of record's rule.

    {'layout_expects': {level, verdict, equivalent_grade, text} or None, 'disagreement':
    'the rotor is not what its layout says: ...' or None}: the layout's own verdict at the
    grade's speed, and where the measured unbalance differs from the layout's beyond its
    95 % radius and the residual share (:func:`cvc_balance.identify.evidence.disagreeing`).
    """
    if layout is None or layout.correction_planes() is None:
        return {'layout_expects': None, 'disagreement': None}
    from cvc_balance.identify.evidence import disagreeing, disagreement_text, explain
    from cvc_balance.identify.estimate import layout_unbalance, residual, unbalance_from
    from cvc_balance.physics.assessment import judge_balance
    from cvc_balance.physics.engine import RotorModel
    model = RotorModel.from_layout(layout)
    verdict = judge_balance(model, top_speed=grade.speed, grade=grade.grade)
    declared = layout_unbalance(model)
    rows = [(label, z, complex(u) - v.value, ci, allowed) for label, z, u, ci, allowed, (_, v)
            in zip(grade.planes, grade.z, grade.before, grade.ci95, grade.permissible,
                   declared.planes)]
    found = disagreeing(rows)
    # The measured rotor as aggregates (S, P about O) from its two planes' unbalance.
    z_i, z_ii = grade.z
    static = complex(grade.before[0] + grade.before[1])
    products = complex(z_i * grade.before[0] + z_ii * grade.before[1])
    diff = residual(unbalance_from(model, static, products), declared)
    expects = None if verdict.assessment is None else {
        'level': verdict.level, 'verdict': verdict.words,
        'equivalent_grade': verdict.assessment.equivalent_grade,
        'text': f'the layout expects {verdict.level}: {verdict.text}'}
    return {'layout_expects': expects,
            'disagreement': disagreement_text(found, explain(model, diff) if found else None)
            or None}


def summarise(result, record=None):
    """Return a FieldCorrection as JSON-able data (its fields: the docs' "JSON outputs")."""
    import numpy as np

    run, problem, grade = result.run, result.problem, result.grade
    planes = []
    for plane in problem.planes:
        sites = result.sites.get(plane)
        planes.append({'name': plane, 'radius': result.radius.get(plane),
                       'sites': None if sites is None else {
                           'angles_deg': [degrees(a) % 360.0 for a in sites.angles],
                           'masses': list(sites.masses), 'stack': sites.stack}})
    summary = {
        'run': _run_mapping(run),
        'segments': [dict(segment_mapping(s), grade=_segment_grade(g))
                     for s, g in zip(getattr(run, 'segments', ()), result.segment_grades)],
        'model_check': None if result.model_check is None
        else check_mapping(result.model_check),
        'method': result.method, 'unit': problem.unit, 'objective': result.objective,
        'max_weights': result.max_weights, 'planes': planes,
        'readings': _readings(run),
        'weights_on': [_placed(w, result.sites) for w in result.existing],
        'coefficients': None, 'grade': None, 'plans': [], 'warnings': list(result.warnings),
        'verdict': None if getattr(result, 'verdict', None) is None
        else result.verdict.record(),
    }
    if result.method == 'influence coefficients':
        # The sensors' coefficients only: the grade's limits ride along as channels of
        # weight 0 (each plane's unbalance, moved one to one), which no sensor measured.
        sensors = [k for k, weight in enumerate(problem.weights) if weight > 0.0]
        summary['coefficients'] = {
            'sensors': [problem.channels[k] for k in sensors], 'planes': list(problem.planes),
            'values': [[_polar(v) for v in problem.influence[k]] for k in sensors],
            'condition_number': record.get('condition_number') if record else None,
            'reading_units': record.get('reading_units') if record else None,
            'runs': [{k: r.get(k) for k in ('role', 'bag', 'date', 'speed')}
                     for r in (record or {}).get('runs', []) if isinstance(r, dict)]}
    if grade is not None:
        before = grade.equivalent_grade(grade.before)
        summary['grade'] = {
            'grade': grade.grade, 'speed': grade.speed, 'mass': grade.mass,
            'source': grade.source,
            'before': {'equivalent_grade': before, 'within_grade': before <= grade.grade,
                       'planes': [_plane_vector(p, z, u, ci, per) for p, z, u, ci, per in
                                  zip(grade.planes, grade.z, grade.before, grade.ci95,
                                      grade.permissible)]},
            **layout_expects(getattr(run, 'layout', None), grade)}
    unchanged = problem.measure(np.zeros(len(problem.planes), complex))
    summary['before'] = {'residual': _residual(problem, unchanged)}
    for plan in result.plans:
        summary['plans'].append(_plan(plan, problem, result, grade, unchanged))
    usable = [p for p in summary['plans'] if not p['worse']]
    feasible = [p for p in usable if p['name'] == 'optimal'
                and p['status'] in ('optimal', 'time limit')]
    split = [p for p in usable if p['name'] == 'split']
    free = [p for p in usable if p['name'] == 'continuous' and len(summary['plans']) == 1]
    best = (feasible or split or free or [None])[0]
    summary['recommended'] = None if best is None else best['name']
    if best is None:
        worst = summary['plans'][0]
        after = worst['after']
        said = (f"G {after['equivalent_grade']:.3g} predicted after, against G "
                f"{summary['grade']['before']['equivalent_grade']:.3g} now by the load cells"
                if after is not None else
                f"residual rms {worst['residual']['rms']:.3g} against {unchanged.rms:.3g} now")
        summary['warnings'].append(
            'no plan is recommended: each would leave the rotor worse than it is (the '
            f'continuous correction: {said}); check the coefficients and the trial runs')
    elif best['after'] is not None and not best['after']['within_grade']:
        summary['warnings'].append(f"the {best['name']} plan does not bring the rotor within "
                                   f"G {grade.grade:g} (G {best['after']['equivalent_grade']:.3g}"
                                   ' predicted)')
    for plan in result.plans:
        if plan.status == 'infeasible':
            summary['warnings'].append('no plan with this kit meets the limits (even the '
                                       'identification\'s 95 % radius spared): ' + plan.note)
        elif plan.status == 'time limit':
            summary['warnings'].append(
                'the mixed-integer search stopped at its time limit: the plan is the best '
                f'found, and HiGHS\'s bound leaves a gap of {plan.gap:.0%} (for the smallest '
                'residual the bound is the continuous optimum: weak; --time-limit for more, '
                'or --objective fewest with --limit)')
        elif plan.note:
            summary['warnings'].append(plan.note)
    return plain(summary)


def plain(data):
    """Return ``data`` with numpy scalars as Python numbers (for JSON and YAML)."""
    if isinstance(data, dict):
        return {key: plain(value) for key, value in data.items()}
    if isinstance(data, (list, tuple)):
        return [plain(value) for value in data]
    if hasattr(data, 'item') and not isinstance(data, (str, bytes)):
        return data.item()
    return data


def _residual(problem, residual):
    return {'channels': [{'name': n, **_polar(v)}
                         for n, v in zip(problem.channels, residual.values)],
            'rms': residual.rms, 'total': residual.total, 'worst_of_limit': residual.worst}


def _placed(weight, sites):
    """Return a PlacedWeight as plain data, with its hole number where the sites count them."""
    from cvc_balance.field.holes import hole_of, hole_text

    plane_sites = sites.get(weight.plane)
    return {'plane': weight.plane, 'angle_deg': degrees(weight.angle) % 360.0,
            'radius': weight.radius, 'masses': list(weight.masses), 'mass': weight.mass,
            'hole': None if plane_sites is None else hole_of(plane_sites, weight.angle),
            'hole_text': (hole_text(plane_sites, weight.angle) or None) if plane_sites
            else None}


def _plan(plan, problem, result, grade, unchanged):
    from cvc_balance.field.plan import final_loading

    corrections = []
    for plane, u in zip(problem.planes, plan.corrections):
        radius = result.radius.get(plane)
        corrections.append({
            'plane': plane, 'unbalance': abs(u),
            'mass': abs(u) / radius if radius else None, 'radius': radius,
            'angle_deg': degrees(math.atan2(u.imag, u.real)) % 360.0})
    after = None
    worse = plan.residual.rms > unchanged.rms * (1.0 + 1e-9)
    if grade is not None and problem.unit == 'kg m':
        values = grade.after(plan, problem.planes)
        value = grade.equivalent_grade(values)
        after = {'equivalent_grade': value, 'within_grade': value <= grade.grade,
                 'planes': [_plane_vector(p, z, u) for p, z, u in
                            zip(grade.planes, grade.z, values)]}
        # The load cells' own unbalance plus the weights: a judge the coefficients are not.
        worse = worse or value > grade.equivalent_grade(grade.before) * (1.0 + 1e-9)
    return {
        'name': plan.name, 'status': plan.status,
        'gap': plan.gap if math.isfinite(plan.gap) else None, 'note': plan.note,
        'corrections': corrections,
        'weights': [_placed(w, result.sites) for w in plan.weights],
        'removed': [_placed(w, result.sites) for w in plan.removed],
        'final': [_placed(w, result.sites) for w in final_loading(result.existing, plan)],
        'count': plan.count,
        'residual': _residual(problem, plan.residual),
        'after': after, 'worse': worse,
    }


def _site_words(weight):
    """Return 'plane I site  15.0 deg (hole 2, 15 deg from the mark with the rotation)'."""
    text = f"plane {weight['plane']} site {_deg(weight['angle_deg']):>5} deg"
    return text + (f" ({weight['hole_text']})" if weight.get('hole_text') else '')


def format_summary(summary):
    """Format a correction summary for people (g, g mm, degrees)."""
    run = summary['run']
    layout = run['layout']
    speed = 'speed not given' if run['speed'] is None else f"at {run['speed']:.4g} rad/s"
    if run['bag'] is None:
        lines = [f"readings by hand {speed}, layout "
                 + (f"'{layout['name']}' ({layout['digest']})" if layout else 'none')]
    else:
        lines = [f"run {run['bag']} ({run['date']}), layout "
                 + (f"'{layout['name']}' ({layout['digest']})" if layout else 'none')
                 + f": {run['revolutions']} revolutions {speed}, angle from "
                 + angle_text(run.get('angle_from'))]
    segments = summary.get('segments') or []
    for segment in segments:
        used = segment['number'] == run['segment']
        grade = segment['grade']
        lines.append(('* ' if used else '  ') + segment_line(segment) + (
            f"; cells: G {grade['equivalent_grade']:.3g}" if grade else '')
            + (' (read)' if used and len(segments) > 1 else ''))
    if len(segments) > 1:
        lines.append(f"  (read segment {run['segment']} of {len(segments)}: --segment N to "
                     'choose; never across a layout change)')
    lines.append(f"corrections from the {summary['method']}")
    if summary.get('model_check') is not None:
        lines.append(check_line(summary['model_check']))
    verdict = summary.get('verdict')
    if verdict is not None:
        lines.append(f"verdict {verdict['headline']}")
        if verdict['source'] == 'measured':
            lines.append(f"  {verdict['layout_expects']}")
    grade = summary['grade']
    if grade is not None:
        before = grade['before']
        lines.append(f"before: G {before['equivalent_grade']:.3g} "
                     f"({'within' if before['within_grade'] else 'OUT OF'} G {grade['grade']:g}"
                     f" at {grade['speed']:.4g} rad/s); " + ', '.join(
                         f"plane {p['plane']} {p['g_mm']:.0f} g mm at {_deg(p['angle_deg'])} deg "
                         f"(allowed {p['permissible_g_mm']:.0f})" for p in before['planes'])
                     + f"; from {grade['source']}")
    for plan in summary['plans']:
        mark = ' (recommended)' if plan['name'] == summary['recommended'] else ''
        lines.append(f"{plan['name']}{mark}: {plan['status']}"
                     + (f", {plan['count']} weights" if plan['name'] != 'continuous' else ''))
        if plan['name'] == 'continuous':
            for c in plan['corrections']:
                mass = f"{c['mass'] * 1000:.1f} g at r {c['radius']:.3f} m" \
                    if c['mass'] is not None and summary['unit'] == 'kg m' \
                    else f"{c['unbalance']:.4g} {summary['unit']}"
                lines.append(f"  plane {c['plane']}: {mass}, {_deg(c['angle_deg'])} deg")
        trim = bool(summary.get('weights_on'))
        for verb, key in (('add: ' if trim else '', 'weights'), ('take off: ', 'removed')):
            for w in plan[key]:
                lines.append(f"  {verb}{_site_words(w)}: "
                             + ' + '.join(f'{m * 1000:g} g' for m in w['masses']))
        if trim and plan['name'] != 'continuous':
            lines.append('  loading after: ' + ('; '.join(
                f"{_site_words(w)}: " + ' + '.join(f'{m * 1000:g} g' for m in w['masses'])
                for w in plan['final']) or 'none'))
        after = plan['after']
        residual = f"residual rms {plan['residual']['rms']:.3g}"
        if after is not None:
            residual += f"; after: G {after['equivalent_grade']:.3g} (" + ', '.join(
                f"{p['g_mm']:.0f} g mm" for p in after['planes']) + ')'
        lines.append('  ' + residual)
    if summary['recommended'] is None:
        lines.append('no plan recommended: each would leave the rotor worse than it is')
    measured = summary.get('measured_after')
    if measured is not None:
        lines.append(f"measured after ({measured['bag']}): G {measured['equivalent_grade']:.3g}")
    return '\n'.join(lines)
