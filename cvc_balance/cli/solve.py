"""
``cvc-balance solve LAYOUT --omega W``: the loads for one motion sample and the verdict.

A table for people or, with ``--json``, one object for programs.
"""

import math
import sys

from cvc_balance.cli.arguments import add_bounded, input_file, print_json, tolerance
from cvc_balance.physics import limits
from cvc_balance.physics.assessment import judge_balance, verdict_record
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.frames import degrees_360, g_mm, g_mm2, radians, ROTOR_FRAME, STATOR_FRAME
from cvc_balance.physics.layout_file import load_layout
from cvc_balance.physics.model_choice import choose_model, Envelope, Tolerance
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance


def register(commands):
    """Add the solve command."""
    solve = commands.add_parser('solve', help='loads and unbalance for one motion sample',
                                description='Loads on the stator, per support, drive torque '
                                'and unbalance for one motion sample of a layout.')
    solve.add_argument('layout', type=input_file, metavar='LAYOUT',
                       help='layout file (YAML or JSON)')
    add_bounded(solve, '--omega', limit=limits.OMEGA, required=True, metavar='W',
                help='rotor speed, rad/s (about +Z)')
    add_bounded(solve, '--alpha', limit=limits.ACCELERATION, default=0.0, metavar='A',
                help='rotor angular acceleration, rad/s^2 (default 0)')
    add_bounded(solve, '--angle-deg', limit=limits.ANGLE_DEG, default=0.0, metavar='Q',
                help='rotor angle q from stator X to rotor X, degrees (default 0)')
    add_bounded(solve, '--gravity', limit=limits.GRAVITY, nargs=3, metavar=('GX', 'GY', 'GZ'),
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
    warnings = layout_warnings(layout)
    for warning in warnings:
        print(f'cvc-balance: warning: {args.layout}: {warning}', file=sys.stderr)
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
    # The verdict at the service speed, or at the speed asked when the layout has none; of
    # the full model (a reduced one may leave out the components' own products).
    full = model if model.own_inertia else RotorModel.from_layout(layout)
    verdict = judge_balance(full, top_speed=abs(args.omega))
    summary = solve_summary(full, result, verdict, args.omega, args.alpha, q, gravity)
    summary['model'] = model_name
    summary['warnings'] = list(warnings)
    if args.json:
        print_json(summary)
    else:
        print(format_table(summary))
        print(model_line)
    return 0


def solve_summary(model, result, verdict, omega, alpha, q, gravity):
    """
    Collect the solve result as plain JSON-able data (SI; angles in degrees for people).

    ``verdict``: :class:`cvc_balance.physics.assessment.Verdict`. Amounts people read in
    balancing units carry them in their key (``g_mm``); the rest is SI.
    """
    static = static_unbalance(model)
    couple = couple_unbalance(model)
    layout = model.layout
    summary = {
        'layout': {'name': layout.name, 'digest': layout.digest(),
                   'components': len(layout.components)},
        'frames': {'stator': STATOR_FRAME, 'rotor': ROTOR_FRAME},
        'sample': {'omega': omega, 'alpha': alpha, 'angle_deg': degrees_360(q),
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
                             'angle_deg': degrees_360(math.atan2(static[1], static[0]))},
        'couple_unbalance': {'kg_m2': math.hypot(*couple),
                             'angle_deg': degrees_360(math.atan2(couple[1], couple[0]))},
        'balance': verdict_record(verdict),
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
    ]
    rows = [['', '', 'x', 'y', 'z']]
    for label, key, unit in (('force, stator frame', 'force_stator', 'N'),
                             ('moment, stator frame', 'moment_stator', 'N m'),
                             ('force, rotor frame', 'force_rotor', 'N'),
                             ('moment, rotor frame', 'moment_rotor', 'N m')):
        rows.append([label, unit] + [f'{v:.2f}' for v in s[key]])
    lines += _columns(rows, left=2)
    lines.append(f"drive torque about +Z {s['drive_torque']:.3f} N m")
    lines += ['', 'Per support, stator frame (force N; tilting moment N m about the support)']
    rows = [['support', 'z [m]', 'Fx', 'Fy', 'Fz', '|F_xy|', 'Mx', 'My']]
    for name, sup in s['supports'].items():
        f, m = sup['force'], sup['moment']
        rows.append([name + (' (axial)' if sup['axial'] else ''), f'{sup["z"]:.3f}']
                    + [f'{v:.2f}' for v in (*f, math.hypot(f[0], f[1]), m[0], m[1])])
    lines += _columns(rows)
    st, cp = s['static_unbalance'], s['couple_unbalance']
    lines += ['', 'Unbalance (rotor frame)']
    lines += _columns([['static', f"{g_mm(st['kg_m']):.1f}", 'g mm', 'at',
                        f"{st['angle_deg']:.2f} deg"],
                       ['couple', f"{g_mm2(cp['kg_m2']):.1f}", 'g mm^2', 'at',
                        f"{cp['angle_deg']:.2f} deg"]], left=1, right_of=(2, 3))
    balance = s['balance']
    if balance is None:
        lines.append('balance grade: NOT JUDGED (the layout names no service speed and '
                     'omega = 0)')
        return '\n'.join(lines)
    lines += ['', f"ISO 21940-11 G {balance['grade']:g} at the {balance['speed_source']} "
              f"{balance['service_speed']:.4g} rad/s: U_per "
              f"{balance['permissible_g_mm']:.1f} g mm"]
    if balance['planes']:
        rows = [['plane', 'z [m]', 'U [g mm]', 'angle [deg]', 'allowed [g mm]', 'U / allowed',
                 'correction mass']]
        for label, p in zip(('I', 'II'), balance['planes']):
            correction = 'none: give balancing.correction_radius' \
                if p['correction_mass_kg'] is None else (
                    f"{p['correction_mass_kg'] * 1e3:.1f} g at r {p['correction_radius']:.3f} m, "
                    f"{p['correction_angle_deg']:.2f} deg")
            rows.append([label, f"{p['z']:.3f}", f"{p['g_mm']:.1f}", f"{p['angle_deg']:.2f}",
                         f"{p['permissible_g_mm']:.1f}", f"{p['fraction']:.2f}", correction])
        lines += _columns(rows, right_of=(6,))
    finest = balance['finest_grade_met']
    lines.append(f"achieved: G {balance['equivalent_grade']:.3g} mm/s (finest standard grade met: "
                 f"{'G %g' % finest if finest else 'none'}) -> {balance['verdict']}")
    return '\n'.join(lines)


def _columns(rows, left=1, right_of=()):
    """
    Lay out ``rows`` of text cells in columns at least two spaces apart.

    The first ``left`` columns and those in ``right_of`` are left-aligned, the
    others (numbers) right-aligned; widths follow the widest cell, so large
    values never run into their neighbours.
    """
    widths = [max(len(row[i]) for row in rows if i < len(row)) for i in range(len(rows[0]))]
    lines = []
    for row in rows:
        cells = [cell.ljust(width) if i < left or i in right_of else cell.rjust(width)
                 for i, (cell, width) in enumerate(zip(row, widths))]
        lines.append('  '.join(cells).rstrip())
    return lines


def _vec(values, spec):
    return '[' + ', '.join(format(v, spec) for v in values) + ']'
