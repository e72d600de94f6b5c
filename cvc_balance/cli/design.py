"""
Design for balance: ``sensitivity``, ``tolerance``, ``sweep`` and ``balance``.

Thin adapters around :mod:`cvc_balance.design`: read the layout (and tolerance
file), call the design tools, print a table for people or one JSON object for
programs. SI in JSON (g mm for plane unbalances, as the balance verdict
prints them); angles in degrees where people type or read them.
"""

import math

import numpy as np

from cvc_balance.cli.arguments import (add_bounded, finite, input_file, print_json,
                                       staged_outputs)
from cvc_balance.design.parameters import design_parameter, parse_parameter, PARAMETERS, UNITS
from cvc_balance.design.tolerances import describe, load_tolerances, typical_tolerances
from cvc_balance.physics import limits
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.frames import degrees, radians
from cvc_balance.physics.layout_file import load_layout

G_MM = 1e6
"""g mm per kg m."""
DEFAULT_SAMPLES = 200_000


def register(commands):
    """Add the design commands."""
    sensitivity = commands.add_parser(
        'sensitivity', help='exact derivatives of the balance for every design parameter',
        description='For every component and parameter (mass kg, radius m, angle rad, z m): '
        'the derivative of each correction plane\'s unbalance vector, of the static and the '
        'couple unbalance (and, with a speed, of each support\'s unbalance load and, where '
        'the layout describes the supports\' bearings, of each bearing\'s ISO 281 rating '
        'life at that speed, in hours), ranked by how far a typical tolerance moves the '
        'worse plane.')
    _layout_argument(sensitivity)
    add_bounded(sensitivity, '--omega', limit=limits.SPEED, metavar='W',
                help="speed for the loads and the grade, rad/s (default: the layout's service "
                'speed)')
    sensitivity.add_argument('--tolerances', type=input_file, metavar='TOL',
                             help='tolerance file to rank by (default: typical ones: mass '
                             '0.5 %%, radius and z 0.5 mm, angle 0.1 deg)')
    sensitivity.add_argument('--norms', action='store_true',
                             help="also the norms' one-sided slopes (they jump at balance)")
    sensitivity.add_argument('--json', action='store_true', help='print one JSON object')
    sensitivity.set_defaults(run=run_sensitivity)

    tolerance = commands.add_parser(
        'tolerance', help='residual unbalance under tolerances: Monte Carlo, RSS, worst case',
        description='The residual unbalance per correction plane under the tolerances of '
        'TOL: its Monte-Carlo distribution, the linearised RSS sigma, the worst case, the '
        'probability of meeting the grade and the tolerances that contribute most; with '
        'a speed and bearings described (supports[].bearing), each bearing\'s rating life '
        'and its linearised spread; with '
        '--target-probability, which tolerances to tighten to reach it at least cost.')
    _layout_argument(tolerance)
    tolerance.add_argument('--tolerances', type=input_file, required=True, metavar='TOL',
                           help='tolerance file (YAML or JSON; the docs\' "Tolerance file")')
    add_bounded(tolerance, '--samples', limit=limits.DRAWS, default=DEFAULT_SAMPLES,
                metavar='N', help=f'Monte-Carlo draws (default {DEFAULT_SAMPLES})')
    add_bounded(tolerance, '--seed', limit=limits.SEED, default=0, metavar='S',
                help='random seed (default 0): the same seed, the same draws')
    add_bounded(tolerance, '--omega', limit=limits.SPEED, metavar='W',
                help="speed to judge the grade at, rad/s (default: the layout's service "
                'speed)')
    tolerance.add_argument('--target-probability', type=finite, metavar='P',
                           help='propose the least-cost tightening (cost ~ 1 / tolerance) '
                           'that meets the grade with probability P')
    tolerance.add_argument('--json', action='store_true', help='print one JSON object')
    tolerance.set_defaults(run=run_tolerance)

    sweep = commands.add_parser(
        'sweep', help="the thesis's charts: balance over one or two parameters",
        description='Plot each correction plane\'s unbalance and the supports\' unbalance '
        'loads over one parameter (two: contour maps), marking the balance points and the '
        "grade's band. Angles in degrees, other parameters SI.")
    _layout_argument(sweep)
    sweep.add_argument('--component', action='append', required=True, metavar='C',
                       help='component to move (once for both parameters, or once each)')
    sweep.add_argument('--parameter', action='append', required=True, choices=PARAMETERS,
                       help='parameter to sweep (give twice for a map)')
    sweep.add_argument('--range', action='append', nargs=2, type=finite, required=True,
                       metavar=('A', 'B'), help='from A to B (deg for angles, else SI), '
                       'once per parameter')
    add_bounded(sweep, '--points', limit=limits.POINTS, metavar='N',
                help='grid points per parameter (default 401; 121 for a map)')
    add_bounded(sweep, '--omega', limit=limits.SPEED, metavar='W',
                help="speed for the loads and the grade, rad/s (default: the layout's service "
                'speed)')
    sweep.add_argument('--derivative', action='store_true',
                       help="one parameter: add the resultant's derivative (the norm's jump, "
                       "the vector's smooth components)")
    sweep.add_argument('-o', '--output', default='sweep.png', metavar='PNG',
                       help='chart file (default sweep.png)')
    sweep.add_argument('--json', action='store_true', help='print the swept values as JSON')
    sweep.set_defaults(run=run_sweep)

    balance = commands.add_parser(
        'balance', help='solve free parameters for balance, and how sensitive that is',
        description='Solve for the free parameters (COMPONENT.PARAMETER) that zero the '
        'unbalance vector in each correction plane (or minimise it), and report how '
        'sensitive the solution is.')
    _layout_argument(balance)
    balance.add_argument('--free', nargs='+', required=True, metavar='C.P',
                         help='free parameters, e.g. counterweight_rear.angle')
    add_bounded(balance, '--omega', limit=limits.SPEED, metavar='W',
                help="speed to judge the grade at, rad/s (default: the layout's service "
                'speed)')
    balance.add_argument('--json', action='store_true', help='print one JSON object')
    balance.set_defaults(run=run_balance)


def _layout_argument(parser):
    """Add the LAYOUT argument."""
    parser.add_argument('layout', type=input_file, metavar='LAYOUT',
                        help='layout file (YAML or JSON)')


def _speed(args, layout):
    """Return the speed asked (rad/s), else the layout's service speed, else None."""
    return args.omega if args.omega is not None else layout.balancing.service_speed


# --- sensitivity ---------------------------------------------------------------------


def run_sensitivity(args):
    """Run ``cvc-balance sensitivity``."""
    from cvc_balance.design.sensitivity import norm_slopes, sensitivities
    from cvc_balance.physics.assessment import assess_balance
    layout = load_layout(args.layout)
    omega = _speed(args, layout)
    tolerances = (load_tolerances(args.tolerances, layout) if args.tolerances
                  else typical_tolerances(layout))
    model = RotorModel.from_layout(layout)
    sens = sensitivities(model, omega)
    life = _life(model, omega)
    nominal = sens.nominal
    judged = nominal.planes if nominal.planes is not None else nominal.static[None, :]
    d_judged = sens.planes if sens.planes is not None else sens.static[:, None, :]
    amounts = [math.hypot(*v) for v in judged]
    allowed = None
    if omega is not None and omega > 0.0:
        assessment = assess_balance(model, omega)
        allowed = (assessment.plane_permissible if assessment.planes
                   else (assessment.permissible,))
        worse = max(range(len(amounts)), key=lambda i: amounts[i] / allowed[i])
    else:
        worse = max(range(len(amounts)), key=lambda i: amounts[i])
    flat_tolerance = tolerances.values.reshape(-1)
    rows = []
    for i, parameter in enumerate(sens.parameters):
        moved = math.hypot(*d_judged[i, worse]) * flat_tolerance[i]
        row = {'component': parameter.component, 'parameter': parameter.name,
               'unit': UNITS[parameter.name],
               'd_planes_g_mm': None if sens.planes is None else _listed(sens.planes[i] * G_MM),
               'd_static_kg_m': _listed(sens.static[i]),
               'd_couple_kg_m2': _listed(sens.couple[i]),
               'tolerance': float(flat_tolerance[i]),
               'moves_worse_plane_g_mm': moved * G_MM}
        if sens.supports is not None:
            row['d_supports_N'] = {s.name: _listed(sens.supports[i, k])
                                   for k, s in enumerate(layout.supports)}
        if life is not None:
            row['d_l10_hours'] = {name: float(life.d_hours[i, k])
                                  for k, name in enumerate(life.supports)}
            row['moves_l10_hours'] = {name: abs(float(life.d_hours[i, k])) * flat_tolerance[i]
                                      for k, name in enumerate(life.supports)}
        if args.norms:
            slopes = {}
            if sens.planes is not None:
                slopes['planes_g_mm'] = [_listed(norm_slopes(nominal.planes[k] * G_MM,
                                                             sens.planes[i, k] * G_MM,
                                                             sens.size * G_MM))
                                         for k in range(2)]
            slopes['static_kg_m'] = _listed(norm_slopes(nominal.static, sens.static[i],
                                                        sens.size))
            slopes['couple_kg_m2'] = _listed(norm_slopes(nominal.couple, sens.couple[i],
                                                         sens.size))
            row['norm_slopes'] = slopes
        rows.append(row)
    rows.sort(key=lambda r: -r['moves_worse_plane_g_mm'])
    summary = {
        'layout': {'name': layout.name, 'digest': layout.digest()},
        'omega': omega,
        'worse_plane': _plane_label(layout, worse),
        'nominal': {'planes_g_mm': None if nominal.planes is None
                    else _listed(nominal.planes * G_MM),
                    'static_kg_m': _listed(nominal.static),
                    'couple_kg_m2': _listed(nominal.couple),
                    'permissible_g_mm': None if allowed is None
                    else [a * G_MM for a in allowed]},
        'tolerances': args.tolerances or 'typical',
        'bearings': None if life is None else {
            'omega': omega, 'l10_hours': dict(zip(life.supports, life.hours))},
        'parameters': rows,
    }
    if args.json:
        print_json(summary)
        return 0
    print(_sensitivity_table(summary, tolerances, layout))
    if life is not None:
        print(_life_lines(summary, tolerances, layout))
    return 0


def _life(model, omega):
    """Return the bearings' LifeSensitivity at ``omega``, or None (no speed, no bearing)."""
    from cvc_balance.design.life import life_sensitivity
    if omega is None or not omega > 0.0:
        return None
    return life_sensitivity(model, omega)


def _life_lines(summary, tolerances, layout, shown=5):
    """Return the bearings' block of sensitivity's text: their life, what moves it most."""
    bearings = summary['bearings']
    hours = bearings['l10_hours']
    lines = ['', f"bearing rating life at {bearings['omega']:.4g} rad/s (ISO 281, the layout "
             'as designed): ' + ', '.join(f'{name} {h:.4g} h' if h is not None else
                                          f'{name} no load' for name, h in hours.items())]
    for name in hours:
        rows = sorted(summary['parameters'], key=lambda r: -r['moves_l10_hours'][name])
        lines.append(f'what moves the {name} bearing\'s life most (by its tolerance; per '
                     'unit):')
        for row in rows[:shown]:
            p = design_parameter(layout, row['component'], row['parameter'])
            tolerance = describe(tolerances, p.index, p.column) if row['tolerance'] > 0 \
                else 'exact'
            slope = row['d_l10_hours'][name]
            unit = row['unit']
            step = ''
            if row['parameter'] == 'mass':
                step = f'; 0.1 kg more: {0.1 * slope:+.4g} h'
            lines.append(f"  {row['component'] + '.' + row['parameter']:32}{tolerance:24}"
                         f"{row['moves_l10_hours'][name]:>10.4g} h   ({slope:+.4g} h/{unit}"
                         f'{step})')
    return '\n'.join(lines)


def _sensitivity_table(summary, tolerances, layout):
    allowed = summary['nominal']['permissible_g_mm']
    worse = summary['worse_plane']
    judged = ('static unbalance', 'plane I', 'plane II').index(worse)
    lines = [f"layout {summary['layout']['name']}: {len(summary['parameters'])} parameters, "
             f'ranked by how far their tolerance moves the worse plane ({worse}'
             + (f', allowed {allowed[max(judged - 1, 0)]:.4g} g mm' if allowed else '') + ')',
             f"tolerances: {summary['tolerances']}", '',
             f"{'parameter':32}{'tolerance':24}{'moves':>15}   derivative per unit "
             '(rotor frame x, y)']
    for row in summary['parameters']:
        label = f"{row['component']}.{row['parameter']}"
        p = design_parameter(layout, row['component'], row['parameter'])
        tolerance = describe(tolerances, p.index, p.column) if row['tolerance'] > 0 else 'exact'
        unit = row['unit']
        planes = row['d_planes_g_mm']
        if planes is not None:
            text = (f"I ({planes[0][0]:.4g}, {planes[0][1]:.4g}) "
                    f"II ({planes[1][0]:.4g}, {planes[1][1]:.4g}) g mm/{unit}")
        else:
            text = f"static ({row['d_static_kg_m'][0]:.4g}, {row['d_static_kg_m'][1]:.4g}) " \
                f'kg m/{unit}'
        lines.append(f"{label:32}{tolerance:24}{row['moves_worse_plane_g_mm']:>10.4g} g mm"
                     f'   {text}')
    lines += ['', 'moves: |d U_worse / dp| x tolerance; derivatives of the vectors (smooth '
              'through balance); --json adds static, couple, supports, and --norms the '
              "norms' one-sided slopes"]
    return '\n'.join(lines)


# --- tolerance -----------------------------------------------------------------------


def run_tolerance(args):
    """Run ``cvc-balance tolerance``."""
    from cvc_balance.design.stack import analyse
    target = args.target_probability
    if target is not None and not 0.0 < target < 1.0:
        raise ValueError(f'--target-probability must be between 0 and 1, got {target:g}')
    layout = load_layout(args.layout)
    omega = _speed(args, layout)
    tolerances = load_tolerances(args.tolerances, layout)
    model = RotorModel.from_layout(layout)
    allocation = None
    if target is not None:
        from cvc_balance.design.allocation import allocate
        allocation = allocate(model, tolerances, target, args.samples, args.seed, omega)
    result = analyse(model, tolerances, args.samples, args.seed, omega)
    summary = _tolerance_summary(layout, result, allocation)
    summary['bearings'] = _life_stack(model, result.omega, tolerances)
    if args.json:
        print_json(summary)
    else:
        print(_tolerance_table(summary, result))
    return 0


def _tolerance_summary(layout, result, allocation):
    planes = []
    for plane in result.planes:
        planes.append({
            'z': plane.z, 'nominal_g_mm': plane.nominal * G_MM, 'mean_g_mm': plane.mean * G_MM,
            'p50_g_mm': plane.p50 * G_MM, 'p95_g_mm': plane.p95 * G_MM,
            'p99_g_mm': plane.p99 * G_MM, 'rss_sigma_g_mm': plane.rss_sigma * G_MM,
            'rms_change_g_mm': plane.rms_change * G_MM,
            'worst_case_g_mm': plane.worst_case * G_MM,
            'worst_case_linear_g_mm': plane.worst_case_linear * G_MM,
            'max_drawn_g_mm': plane.max_drawn * G_MM,
            'permissible_g_mm': None if plane.permissible is None
            else plane.permissible * G_MM,
            'probability_within': plane.probability_within})
    summary = {
        'layout': {'name': layout.name, 'digest': layout.digest()},
        'samples': result.samples, 'seed': result.seed, 'omega': result.omega,
        'grade': result.grade,
        'planes': planes,
        'probability_within_grade': result.probability_within_grade,
        'probability_stderr': result.probability_stderr,
        'judging_plane': _plane_label(layout, result.judging_plane),
        'contributions': [{'component': c.parameter.component,
                           'parameter': c.parameter.name, 'share': c.share,
                           'share_planes': list(c.share_planes)}
                          for c in result.contributions],
    }
    if allocation is not None:
        summary['allocation'] = {
            'target_probability': allocation.target,
            'cost_model': 'sum over toleranced parameters of given / proposed tolerance',
            'cost_given': allocation.cost_given, 'cost_proposed': allocation.cost_proposed,
            'probability_given': allocation.probability_given,
            'probability_proposed': allocation.probability_proposed,
            'probability_proposed_stderr': allocation.stderr_proposed,
            'tolerances': [{'component': c.parameter.component,
                            'parameter': c.parameter.name, 'unit': UNITS[c.parameter.name],
                            'given': c.given, 'proposed': c.proposed, 'factor': c.factor}
                           for c in allocation.changes],
        }
    return summary


def _life_stack(model, omega, tolerances):
    """Return the bearings' rating life under the tolerances, linearised (or None)."""
    from cvc_balance.design.life import life_stack
    life = _life(model, omega)
    if life is None:
        return None
    out = []
    for name, hours, sigma, worst, shares in life_stack(life, tolerances):
        order = np.argsort(-shares, kind='stable')
        out.append({'support': name, 'omega': omega, 'l10_hours': hours,
                    'rss_sigma_hours': sigma, 'worst_case_linear_hours': worst,
                    'contributions': [{'component': life.parameters[k].component,
                                       'parameter': life.parameters[k].name,
                                       'share': float(shares[k])}
                                      for k in order[:10] if shares[k] > 0.0]})
    return out


def _tolerance_table(summary, result):
    lines = [f"layout {summary['layout']['name']}: {summary['samples']} draws (seed "
             f"{summary['seed']})" + ('' if summary['omega'] is None else
                                      f", judged at {summary['omega']:.4g} rad/s against "
                                      f"G {summary['grade']:g}"), '',
             f"{'g mm':10}{'nominal':>10}{'mean':>10}{'p50':>10}{'p95':>10}{'p99':>10}"
             f"{'RSS sigma':>11}{'worst':>10}{'allowed':>10}{'P within':>10}"]
    for label, plane in zip(_labels(summary), summary['planes']):
        allowed = plane['permissible_g_mm']
        within = plane['probability_within']
        lines.append(f"{label:10}" + ''.join(f'{plane[k]:10.4g}' for k in (
            'nominal_g_mm', 'mean_g_mm', 'p50_g_mm', 'p95_g_mm', 'p99_g_mm'))
            + f"{plane['rss_sigma_g_mm']:11.4g}{plane['worst_case_g_mm']:10.4g}"
            + (f'{allowed:10.4g}{within:10.4f}' if allowed is not None else f"{'-':>10}"))
    probability = summary['probability_within_grade']
    if probability is not None:
        lines.append(f"probability of meeting G {summary['grade']:g}: {probability:.4f} "
                     f"(+- {summary['probability_stderr']:.4f})")
    lines += ['', f"largest contributions (share of the mean squared change, "
              f"{summary['judging_plane']}):"]
    for c in summary['contributions'][:10]:
        lines.append(f"  {c['component'] + '.' + c['parameter']:34}{c['share'] * 100:6.1f} %")
    for bearing in summary.get('bearings') or ():
        most = bearing['contributions'][0] if bearing['contributions'] else None
        lines.append(f"bearing {bearing['support']}: rating life {bearing['l10_hours']:.4g} h at "
                     f"{bearing['omega']:.4g} rad/s, +- {bearing['rss_sigma_hours']:.3g} h (RSS "
                     f"sigma), worst case +- {bearing['worst_case_linear_hours']:.3g} h"
                     + (f"; most from {most['component']}.{most['parameter']} "
                        f"({most['share'] * 100:.0f} %)" if most else ''))
    allocation = summary.get('allocation')
    if allocation:
        lines += ['', f"to meet G {summary['grade']:g} with probability "
                  f"{allocation['target_probability']:g} at least cost (cost ~ 1/tolerance: "
                  f"{allocation['cost_given']:.4g} -> {allocation['cost_proposed']:.4g}): "
                  f"P {allocation['probability_given']:.4f} -> "
                  f"{allocation['probability_proposed']:.4f}"]
        changed = [t for t in allocation['tolerances'] if t['factor'] > 1.0 + 1e-9]
        if not changed:
            lines.append('  nothing to tighten: the given tolerances meet it')
        for t in changed:
            given = _shown(t['given'], t['parameter'])
            proposed = _shown(t['proposed'], t['parameter'])
            lines.append(f"  {t['component'] + '.' + t['parameter']:34}{given:>14} -> "
                         f"{proposed:>14}  ({t['factor']:.3g} x tighter)")
    return '\n'.join(lines)


def _shown(value, parameter):
    if parameter == 'angle':
        return f'+-{degrees(value):.4g} deg'
    if parameter == 'mass':
        return f'+-{value:.4g} kg'
    return f'+-{value * 1e3:.4g} mm'


def _labels(summary):
    if len(summary['planes']) == 1 and summary['planes'][0]['z'] is None:
        return ('static',)
    return ('plane I', 'plane II')


def _plane_label(layout, index):
    if layout.correction_planes() is None:
        return 'static unbalance'
    return ('plane I', 'plane II')[index]


# --- sweep ---------------------------------------------------------------------------


def run_sweep(args):
    """Run ``cvc-balance sweep``."""
    from cvc_balance.design.charts import draw_sweep
    from cvc_balance.design.sweep import sweep
    layout = load_layout(args.layout)
    count = len(args.parameter)
    if count > 2:
        raise ValueError(f'sweep one or two parameters, got {count} --parameter')
    if len(args.component) not in (1, count):
        raise ValueError('give --component once (for every parameter) or once per --parameter')
    if len(args.range) != count:
        raise ValueError(f'give one --range per --parameter ({count}), got {len(args.range)}')
    components = args.component * count if len(args.component) == 1 else args.component
    parameters = [design_parameter(layout, c, p) for c, p in zip(components, args.parameter)]
    ranges = [tuple(radians(v) for v in r) if p.name == 'angle' else tuple(r)
              for p, r in zip(parameters, args.range)]
    points = args.points if args.points is not None else (401 if count == 1 else 121)
    if args.derivative and count != 1:
        raise ValueError('--derivative is for one parameter')
    omega = _speed(args, layout)
    with staged_outputs([args.layout], png=args.output) as out:   # checked before the work
        result = sweep(layout, parameters, ranges, points, omega)
        draw_sweep(result, out['png'], derivative=args.derivative)
    summary = _sweep_summary(result)
    if args.json:
        print_json(summary)
        return 0
    for point in summary['balance_points']:
        where = ', '.join(f'{k} = {v:.9g}' for k, v in point['values'].items())
        kind = 'balance point' if point['balanced'] else 'least unbalance'
        planes = ', '.join(f'{a:.4g}' for a in point['planes_g_mm'])
        lines = f'{kind}: {where} (planes {planes} g mm)'
        print(lines)
    if not summary['balance_points']:
        print('no minimum of the unbalance inside the range')
    print(f'wrote {args.output}')
    return 0


def _sweep_summary(result):
    def people(parameter, value):
        return degrees(value) if parameter.name == 'angle' else float(value)

    names = [p.label + ('_deg' if p.name == 'angle' else '') for p in result.parameters]
    amounts = (result.planes[..., 0] ** 2 + result.planes[..., 1] ** 2) ** 0.5 * G_MM
    summary = {
        'layout': {'name': result.layout.name, 'digest': result.layout.digest()},
        'parameters': names, 'omega': result.omega, 'grade': result.grade,
        'permissible_g_mm': None if result.permissible is None
        else [a * G_MM for a in result.permissible],
        'axes': {name: [people(p, v) for v in axis]
                 for name, p, axis in zip(names, result.parameters, result.axes)},
        'planes_g_mm': amounts.tolist(),
        'resultant_N': None if result.resultant is None else result.resultant.tolist(),
        'balance_points': [{'values': {name: people(p, v) for name, p, v in
                                       zip(names, result.parameters, point.values)},
                            'planes_g_mm': [math.hypot(*v) * G_MM for v in point.planes],
                            'balanced': point.balanced}
                           for point in result.balance_points],
    }
    if result.supports is not None:
        summary['supports_N'] = {
            s.name: ((result.supports[..., k, 0] ** 2 + result.supports[..., k, 1] ** 2)
                     ** 0.5).tolist() for k, s in enumerate(result.layout.supports)}
    if result.resultant_slopes is not None:
        minus, plus = result.resultant_slopes
        summary['d_resultant_N'] = result.d_resultant.tolist()
        summary['resultant_slopes_N'] = {'minus': minus.tolist(), 'plus': plus.tolist()}
    return summary


# --- balance -------------------------------------------------------------------------


def run_balance(args):
    """Run ``cvc-balance balance``."""
    from cvc_balance.design.balance_point import solve_balance
    layout = load_layout(args.layout)
    omega = _speed(args, layout)
    free = [parse_parameter(layout, text) for text in args.free]
    solution = solve_balance(layout, free, omega)
    tolerances = typical_tolerances(layout).values
    rows = []
    for k, parameter in enumerate(solution.free):
        steep = [math.hypot(*v) for v in solution.jacobian[k]]
        alone = None
        if solution.permissible is not None:
            alone = min((a / s if s > 0.0 else math.inf)
                        for a, s in zip(solution.permissible, steep))
        effects = sorted(((abs(solution.moves_with[k, j]) * tolerances[o.index, o.column], j)
                          for j, o in enumerate(solution.others)), reverse=True)
        largest = effects[0][0] if effects else 0.0
        rows.append({
            'component': parameter.component, 'parameter': parameter.name,
            'unit': UNITS[parameter.name],
            'start': float(solution.start[k]), 'value': float(solution.values[k]),
            'd_planes_g_mm': _listed(solution.jacobian[k] * G_MM),
            'miss_within_grade': None if alone is None or math.isinf(alone) else alone,
            'moves_with': [{'component': solution.others[j].component,
                            'parameter': solution.others[j].name,
                            'derivative': float(solution.moves_with[k, j]),
                            'typical_tolerance': float(
                                tolerances[solution.others[j].index, solution.others[j].column]),
                            'moves_by': effect}
                           for effect, j in effects if effect > 1e-9 * largest],
        })
    summary = {
        'layout': {'name': layout.name, 'digest': layout.digest()},
        'omega': omega,
        'balanced': solution.balanced,
        'within_grade': solution.within_grade,
        'planes_g_mm': [math.hypot(*v) * G_MM for v in solution.planes],
        'permissible_g_mm': None if solution.permissible is None
        else [a * G_MM for a in solution.permissible],
        'singular_values_g_mm': (solution.singular_values * G_MM).tolist(),
        'evaluations': solution.evaluations,
        'free': rows,
    }
    if args.json:
        print_json(summary)
        return 0
    print(_balance_table(summary))
    return 0


def _balance_table(summary):
    verdict = 'balanced' if summary['balanced'] else 'least unbalance (no exact balance)'
    planes = ', '.join(f'{v:.4g}' for v in summary['planes_g_mm'])
    lines = [f"layout {summary['layout']['name']}: {verdict}; residual {planes} g mm"
             + ('' if summary['within_grade'] is None else
                f" ({'within' if summary['within_grade'] else 'OUT OF'} the grade's "
                f"{', '.join(f'{a:.4g}' for a in summary['permissible_g_mm'])} g mm)")]
    lines.append(f"{'free parameter':34}{'start':>14}{'solution':>16}   a miss of one unit "
                 'moves the planes by; alone within the grade')
    for row in summary['free']:
        label = f"{row['component']}.{row['parameter']}"
        start, value = row['start'], row['value']
        if row['parameter'] == 'angle':
            start_text, value_text = f'{degrees(start):.6g} deg', f'{degrees(value):.9g} deg'
        else:
            start_text, value_text = f"{start:.6g} {row['unit']}", f"{value:.9g} {row['unit']}"
        steep = ', '.join(f'{math.hypot(*v):.4g}' for v in row['d_planes_g_mm'])
        miss = row['miss_within_grade']
        miss_text = '' if miss is None else f'; +-{_shown(miss, row["parameter"])[2:]}'
        lines.append(f"{label:34}{start_text:>14}{value_text:>16}   {steep} g mm/"
                     f"{row['unit']}{miss_text}")
    lines += ['', 'the solution moves most with (typical tolerance x derivative):']
    for row in summary['free']:
        label = f"{row['component']}.{row['parameter']}"
        for other in row['moves_with'][:3]:
            moved = _shown(other['moves_by'], row['parameter'])[2:]
            lines.append(f"  {label:32} {other['component'] + '.' + other['parameter']:32} "
                         f"{other['derivative']:+.4g} {row['unit']}/{UNITS[other['parameter']]}"
                         f" (+-{moved})")
    values = summary['singular_values_g_mm']
    lines.append('singular values of d(planes)/d(free) x typical tolerance: '
                 f"{', '.join(f'{v:.4g}' for v in values)} g mm (a small one: "
                 'the planes barely fix the solution)')
    return '\n'.join(lines)


def _listed(array):
    """Nested lists of floats from arrays and tuples of them (JSON)."""
    if isinstance(array, (tuple, list)) or getattr(array, 'ndim', 0):
        return [_listed(v) for v in array]
    return float(array)
