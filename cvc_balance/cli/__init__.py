"""
The ``cvc-balance`` command line: an adapter around the engine.

``cvc-balance solve LAYOUT --omega W`` prints the loads for one motion sample
and the balance verdict, as a table for people or, with ``--json``, one
object for programs. SI units; degrees only where people read or type angles.
Exit codes: 0 done, 2 bad input (one line on stderr naming what is wrong).
"""

import argparse
import json
import math
import sys

from cvc_balance.assessment import assess_balance
from cvc_balance.engine import RotorModel, sample_loads
from cvc_balance.frames import ROTOR_FRAME, STATOR_FRAME, degrees, radians
from cvc_balance.layout import LayoutError
from cvc_balance.layout_file import load_layout
from cvc_balance.model_choice import choose_model, Envelope, Tolerance
from cvc_balance.unbalance import couple_unbalance, static_unbalance

EXIT_BAD_INPUT = 2


def main(argv=None):
    """Run the command line; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (LayoutError, ValueError, OSError) as error:
        print(f'cvc-balance: error: {error}', file=sys.stderr)
        return EXIT_BAD_INPUT


def _parser():
    parser = argparse.ArgumentParser(
        prog='cvc-balance', description='Bearing loads, drive torque and unbalance of a '
        'rotor from its component layout (cylindrical vector components).')
    commands = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    solve = commands.add_parser('solve', help='loads and unbalance for one motion sample',
                                description='Loads on the stator, per support, drive torque '
                                'and unbalance for one motion sample of a layout.')
    solve.add_argument('layout', metavar='LAYOUT', help='layout file (YAML or JSON)')
    solve.add_argument('--omega', type=_finite, required=True, metavar='W',
                       help='rotor speed, rad/s (about +Z)')
    solve.add_argument('--alpha', type=_finite, default=0.0, metavar='A',
                       help='rotor angular acceleration, rad/s^2 (default 0)')
    solve.add_argument('--angle-deg', type=_finite, default=0.0, metavar='Q',
                       help='rotor angle q from stator X to rotor X, degrees (default 0)')
    solve.add_argument('--gravity', type=_finite, nargs=3, metavar=('GX', 'GY', 'GZ'),
                       help="gravity in the stator frame, m/s^2 (default: the layout's)")
    solve.add_argument('--tolerance', type=_tolerance, nargs=3, metavar=('N', 'NM', 'TNM'),
                       help='largest change accepted in the forces (N), moments (N m) and '
                       'drive torque (N m), inf for an output not asked: take the smallest '
                       'model within it for speeds up to |W| and accelerations up to |A|, '
                       'and say which')
    solve.add_argument('--json', action='store_true', help='print one JSON object')
    solve.set_defaults(run=_solve)

    simulate = commands.add_parser('simulate', help='make an input bag from a scenario',
                                   description='Write a bag of /layout and /joint_states '
                                   'from a scenario file (speed profile, noise, layout changes).')
    simulate.add_argument('scenario', metavar='SCENARIO', help='scenario file (YAML)')
    simulate.add_argument('-o', '--output', required=True, metavar='BAG', help='bag to write')
    simulate.set_defaults(run=_simulate)

    replay = commands.add_parser('replay', help='compute a bag\'s outputs offline',
                                 description='Read a bag\'s motion and layouts, compute every '
                                 'output with the vectorised engine, write them as a bag and '
                                 'print a summary. No ROS graph needed.')
    replay.add_argument('bag', metavar='BAG', help='input bag (.mcap)')
    replay.add_argument('-o', '--output', metavar='OUT', help='bag of outputs to write')
    replay.add_argument('--layout', metavar='FILE', help='use this layout for the whole run '
                        '("what if") instead of the bag\'s')
    replay.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    replay.add_argument('--alpha-time-constant', type=_finite, default=0.1, metavar='S',
                        help='as the node\'s parameter (s)')
    replay.add_argument('--max-speed', type=_finite, default=1000.0, metavar='W',
                        help='as the node\'s parameter (rad/s)')
    replay.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    replay.add_argument('--progress', action=argparse.BooleanOptionalAction, default=None,
                        help='progress bar (default: on a terminal)')
    replay.add_argument('--rrd', metavar='RUN.rrd', help='also log the run for rerun')
    replay.add_argument('--tolerance', type=_tolerance, nargs=3, metavar=('N', 'NM', 'TNM'),
                        help='largest change accepted in the forces (N), moments (N m) and '
                        'drive torque (N m), inf for an output not asked: each layout takes '
                        "the smallest model within it over its samples' speeds and "
                        'accelerations, and the summary says which')
    replay.set_defaults(run=_replay)

    view = commands.add_parser('view', help='log every sample of a bag to a rerun .rrd',
                               description='Compute a bag\'s run (as replay does) and log it '
                               'for the rerun viewer: the turning gantry, loads, unbalance.')
    view.add_argument('bag', metavar='BAG')
    view.add_argument('-o', '--output', required=True, metavar='RUN.rrd')
    view.add_argument('--every', type=int, default=10, metavar='N',
                      help='draw load arrows for every N-th sample (plots get all)')
    view.add_argument('--joint-name', default='gantry_joint')
    view.set_defaults(run=_view)

    bench = commands.add_parser('bench', help='error against cost of every method, per scene',
                                description='Compute the loads of six scenes with every '
                                'method; write the table (CSV) and the chart (PNG).')
    bench.add_argument('--csv', default='docs/bench.csv', metavar='FILE')
    bench.add_argument('--png', default='docs/bench.png', metavar='FILE')
    bench.set_defaults(run=_bench)

    play = commands.add_parser('play', help='publish a bag\'s inputs live, record the outputs',
                               description='Publish the bag\'s layout and motion messages with '
                               'their timing (to drive a running balance_monitor) and record '
                               'the node\'s outputs.')
    play.add_argument('bag', metavar='BAG')
    play.add_argument('--rate', type=_finite, default=1.0, metavar='X',
                      help='playback speed factor (default 1)')
    play.add_argument('-o', '--output', metavar='OUT', help='record the outputs to this bag')
    play.set_defaults(run=_play)

    record = commands.add_parser('record', help='record topics to a bag until Ctrl-C',
                                 description='Record the run\'s inputs and outputs (raw CDR) '
                                 'to a rosbag2 MCAP file; SIGINT or SIGTERM finalises it.')
    record.add_argument('-o', '--output', required=True, metavar='BAG')
    record.add_argument('topics', nargs='*', metavar='TOPIC',
                        help='topics (patterns with *); default: inputs, outputs, diagnostics')
    record.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    record.add_argument('--chunk-kib', type=int, default=1024, metavar='K',
                        help='chunk size; a killed recorder loses at most one chunk')
    record.add_argument('--ready-when', action='append', default=[], metavar='TOPIC',
                        help='print "ready" once this topic\'s publisher is matched')
    record.add_argument('--ros-args', nargs=argparse.REMAINDER, default=[],
                        help='ROS arguments (remapping, namespace)')
    record.set_defaults(run=_record)
    return parser


def _number(text):
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None


def _finite(text):
    value = _number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'must be finite, got {text!r}')
    return value


def _tolerance(text):
    value = _number(text)
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f'must be >= 0 (or inf), got {text!r}')
    return value


def _solve(args):
    layout = load_layout(args.layout)
    gravity = tuple(args.gravity) if args.gravity else layout.gravity
    if args.tolerance:
        choice = choose_model(layout, Tolerance(*args.tolerance),
                              Envelope(abs(args.omega), abs(args.alpha)), gravity)
        model, model_name, model_line = choice.model, choice.name, choice.describe()
    else:
        model = RotorModel.from_layout(layout)
        model_name, model_line = 'rigid bodies', 'model: rigid bodies (full)'
    q = radians(args.angle_deg)
    result = sample_loads(model, q, args.omega, args.alpha, gravity)
    speed = layout.balancing.service_speed or abs(args.omega)
    assessment = assess_balance(model, speed) if speed > 0.0 else None
    summary = solve_summary(model, result, assessment, args.omega, args.alpha, q, gravity)
    summary['model'] = model_name
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_table(summary))
        print(model_line)
    return 0


def _simulate(args):
    from cvc_balance.scenario import load_scenario, write_bag
    scenario = load_scenario(args.scenario)
    count = write_bag(scenario, args.output)
    print(f'{args.output}: {count} samples over {scenario.time[-1]:.3f} s, '
          f'{len(scenario.layouts)} layouts')
    return 0


def _replay(args):
    from cvc_balance.replay import format_summary, progress_bar, replay
    show = args.progress if args.progress is not None else sys.stderr.isatty()
    logger = _rerun_logger(args.rrd, args.bag) if args.rrd else None
    summary = replay(args.bag, args.output, args.layout, args.joint_name,
                     args.alpha_time_constant, args.max_speed,
                     '' if args.compression == 'none' else args.compression,
                     progress_bar() if show else None, observer=logger,
                     tolerance=Tolerance(*args.tolerance) if args.tolerance else None)
    if logger:
        logger.finish()
    print(format_summary(summary))
    return 0


def _rerun_logger(path, bag, every=10):
    from cvc_balance.rerun_log import open_recording, RunLogger
    return RunLogger(open_recording('save', path, name=bag), every)


def _view(args):
    from cvc_balance.replay import replay
    logger = _rerun_logger(args.output, args.bag, args.every)
    summary = replay(args.bag, joint_name=args.joint_name, observer=logger)
    logger.finish()
    print(f'{args.output}: {summary.accepted} samples of {args.bag}, '
          f'{len(summary.segments)} layouts')
    for problem in summary.problems:
        print(f'  problem: {problem}')
    return 0


def _bench(args):
    from cvc_balance.bench import pareto_front, run
    rows = run(args.csv, args.png)
    for scene in dict.fromkeys(r['scene'] for r in rows):
        print(f'Pareto front, {scene}: {", ".join(pareto_front(rows, scene))}')
    print(f'wrote {args.csv} and {args.png}')
    return 0


def _play(args):
    from cvc_balance.player import play_main
    return play_main(args)


def _record(args):
    from cvc_balance.recorder import record_main
    return record_main(args)


def solve_summary(model, result, assessment, omega, alpha, q, gravity):
    """Collect the solve result as plain JSON-able data (SI; angles in degrees for people)."""
    static = static_unbalance(model)
    couple = couple_unbalance(model)
    layout = model.layout
    summary = {
        'layout': {'name': layout.name, 'digest': layout.digest(),
                   'components': len(layout.components)},
        'frames': {'stator': STATOR_FRAME, 'rotor': ROTOR_FRAME},
        'sample': {'omega': omega, 'alpha': alpha, 'angle_deg': degrees(q),
                   'gravity': list(gravity)},
        'mass': model.mass,
        'com': [model.s_x / model.mass, model.s_y / model.mass, model.s_z / model.mass],
        'force_stator': list(result.force_stator),
        'moment_stator': list(result.moment_stator),
        'force_rotor': list(result.force_rotor),
        'moment_rotor': list(result.moment_rotor),
        'drive_torque': result.drive_torque,
        'supports': {
            s.name: {'z': s.z, 'axial': s.axial, 'force': list(result.supports[s.name][0]),
                     'moment': list(result.supports[s.name][1])}
            for s in model.supports},
        'static_unbalance': {'kg_m': math.hypot(*static),
                             'angle_deg': degrees(math.atan2(static[1], static[0]))},
        'couple_unbalance': {'kg_m2': math.hypot(*couple),
                             'angle_deg': degrees(math.atan2(couple[1], couple[0]))},
        'balance': None,
    }
    if assessment is not None:
        summary['balance'] = {
            'grade': assessment.grade, 'service_speed': assessment.omega,
            'permissible_g_mm': assessment.permissible * 1e6,
            'planes': [{'z': p.z, 'g_mm': p.amount * 1e6, 'angle_deg': degrees(p.angle),
                        'permissible_g_mm': allowed * 1e6,
                        'correction_mass_kg': p.correction_mass,
                        'correction_radius': p.correction_radius,
                        'correction_angle_deg': degrees(p.correction_angle)}
                       for p, allowed in zip(assessment.planes,
                                             assessment.plane_permissible)],
            'equivalent_grade': assessment.equivalent_grade,
            'finest_grade_met': assessment.finest_grade_met,
            'within_grade': assessment.within_grade,
        }
    return summary


def format_table(s):
    """Format the solve result as a table for people."""
    sample = s['sample']
    lines = [
        f"layout {s['layout']['name']} ({s['layout']['components']} components, "
        f"digest {s['layout']['digest']}): mass {s['mass']:.3f} kg, "
        f"centre of mass {_vec(s['com'], '.4f')} m (rotor frame)",
        f"sample: omega {sample['omega']:.4g} rad/s ({sample['omega'] * 30 / math.pi:.4g} rpm), "
        f"alpha {sample['alpha']:.4g} rad/s^2, rotor angle {sample['angle_deg']:.4g} deg, "
        f"gravity {_vec(sample['gravity'], '.4g')} m/s^2 (stator)",
        '',
        'Load on the stator through the supports (moment about O)',
        f"{'':24}{'x':>12}{'y':>12}{'z':>12}",
    ]
    for label, key, unit in (('force, stator frame', 'force_stator', 'N'),
                             ('moment, stator frame', 'moment_stator', 'N m'),
                             ('force, rotor frame', 'force_rotor', 'N'),
                             ('moment, rotor frame', 'moment_rotor', 'N m')):
        lines.append(f'{label:20}{unit:>4}' + ''.join(f'{v:12.2f}' for v in s[key]))
    lines.append(f"drive torque about +Z {s['drive_torque']:.3f} N m")
    lines += ['', 'Per support, stator frame (force N; tilting moment N m about the support)',
              f"{'support':12}{'z [m]':>8}{'Fx':>11}{'Fy':>11}{'Fz':>11}{'|F_xy|':>11}"
              f"{'Mx':>11}{'My':>11}"]
    for name, sup in s['supports'].items():
        f, m = sup['force'], sup['moment']
        label = name + (' (axial)' if sup['axial'] else '')
        lines.append(f'{label:12}{sup["z"]:8.3f}' + ''.join(f'{v:11.2f}' for v in f)
                     + f'{math.hypot(f[0], f[1]):11.2f}{m[0]:11.2f}{m[1]:11.2f}')
    st, cp = s['static_unbalance'], s['couple_unbalance']
    lines += ['', 'Unbalance (rotor frame)',
              f"static  {st['kg_m'] * 1e6:12.1f} g mm    at {st['angle_deg']:7.2f} deg",
              f"couple  {cp['kg_m2'] * 1e6:12.1f} g mm^2  at {cp['angle_deg']:7.2f} deg"]
    balance = s['balance']
    if balance is None:
        lines.append('balance grade: not judged (no service speed and omega = 0)')
        return '\n'.join(lines)
    lines += ['', f"ISO 21940-11 G {balance['grade']:g} at {balance['service_speed']:.4g} rad/s: "
              f"U_per {balance['permissible_g_mm']:.1f} g mm"]
    if balance['planes']:
        lines.append(f"{'plane':6}{'z [m]':>8}{'U [g mm]':>11}{'angle':>9}{'allowed':>10}"
                     '   correction mass')
        for label, p in zip(('I', 'II'), balance['planes']):
            grams = p['correction_mass_kg'] * 1e3
            lines.append(f"{label:6}{p['z']:8.3f}{p['g_mm']:11.1f}{p['angle_deg']:9.2f}"
                         f"{p['permissible_g_mm']:10.1f}   {grams:.1f} g at r "
                         f"{p['correction_radius']:.3f} m, {p['correction_angle_deg']:.2f} deg")
    finest = balance['finest_grade_met']
    verdict = 'WITHIN' if balance['within_grade'] else 'OUT OF'
    lines.append(f"achieved: G {balance['equivalent_grade']:.3g} mm/s (finest standard grade met: "
                 f"{'G %g' % finest if finest else 'none'}) -> {verdict} G {balance['grade']:g}")
    return '\n'.join(lines)


def _vec(values, spec):
    return '[' + ', '.join(format(v, spec) for v in values) + ']'


if __name__ == '__main__':
    sys.exit(main())
