"""
``cvc-balance solve LAYOUT --omega W``: the loads for one motion sample and the verdict.

A table for people or, with ``--json``, one object for programs.
"""

import math

from cvc_balance.cli.arguments import finite, print_json, tolerance
from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.frames import degrees, radians, ROTOR_FRAME, STATOR_FRAME
from cvc_balance.physics.layout_file import load_layout
from cvc_balance.physics.model_choice import choose_model, Envelope, Tolerance
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance


def register(commands):
    """Add the solve command."""
    solve = commands.add_parser('solve', help='loads and unbalance for one motion sample',
                                description='Loads on the stator, per support, drive torque '
                                'and unbalance for one motion sample of a layout.')
    solve.add_argument('layout', metavar='LAYOUT', help='layout file (YAML or JSON)')
    solve.add_argument('--omega', type=finite, required=True, metavar='W',
                       help='rotor speed, rad/s (about +Z)')
    solve.add_argument('--alpha', type=finite, default=0.0, metavar='A',
                       help='rotor angular acceleration, rad/s^2 (default 0)')
    solve.add_argument('--angle-deg', type=finite, default=0.0, metavar='Q',
                       help='rotor angle q from stator X to rotor X, degrees (default 0)')
    solve.add_argument('--gravity', type=finite, nargs=3, metavar=('GX', 'GY', 'GZ'),
                       help="gravity in the stator frame, m/s^2 (default: the layout's)")
    solve.add_argument('--tolerance', type=tolerance, nargs=3, metavar=('N', 'NM', 'TNM'),
                       help='largest change accepted in the forces (N), moments (N m) and '
                       'drive torque (N m), inf for an output not asked: take the smallest '
                       'model within it for speeds up to |W| and accelerations up to |A|, '
                       'and say which')
    solve.add_argument('--json', action='store_true', help='print one JSON object')
    solve.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance solve``."""
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
        print_json(summary)
    else:
        print(format_table(summary))
        print(model_line)
    return 0


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
            correction = 'none: give balancing.correction_radius' \
                if p['correction_mass_kg'] is None else (
                    f"{p['correction_mass_kg'] * 1e3:.1f} g at r {p['correction_radius']:.3f} m, "
                    f"{p['correction_angle_deg']:.2f} deg")
            lines.append(f"{label:6}{p['z']:8.3f}{p['g_mm']:11.1f}{p['angle_deg']:9.2f}"
                         f"{p['permissible_g_mm']:10.1f}   {correction}")
    finest = balance['finest_grade_met']
    verdict = 'WITHIN' if balance['within_grade'] else 'OUT OF'
    lines.append(f"achieved: G {balance['equivalent_grade']:.3g} mm/s (finest standard grade met: "
                 f"{'G %g' % finest if finest else 'none'}) -> {verdict} G {balance['grade']:g}")
    return '\n'.join(lines)


def _vec(values, spec):
    return '[' + ', '.join(format(v, spec) for v in values) + ']'
