"""
The field-balancing report: one HTML page (no scripts, no network) beside its PNG figures.

At the top the verdict (the grade before and after, in or out), then what to bolt where,
the figures, the plans compared, the run's identity (bag, date, layout name and digest,
speed, revolutions), the coefficients used and every warning. Every text from the run
(paths, names) is escaped. It reads on a phone too (390 CSS pixels): the verdict boxes and
the figures stack, long words (paths) wrap, and a table wider than the screen scrolls
inside its own box while the page does not.
"""

import datetime
from html import escape

STYLE = '''
body { font-family: sans-serif; margin: 1.5em auto; padding: 0 0.8em; max-width: 62em;
color: #222; line-height: 1.35; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
p, .warning, figcaption { overflow-wrap: anywhere; }
.verdict { display: flex; flex-wrap: wrap; gap: 1em; margin: 1em 0; }
.verdict div { flex: 1 1 11em; padding: 0.8em 1em; border-radius: 6px; color: white; }
.ok { background: #2e7d32; } .out { background: #c62828; } .unknown { background: #616161; }
.verdict b { font-size: 1.6em; display: block; }
.scroll { overflow-x: auto; max-width: 100%; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.92em; }
td, th { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: right; }
th { background: #eee; } td.text, th.text { text-align: left; } td { white-space: nowrap; }
td.text { white-space: normal; overflow-wrap: anywhere; }
.bolt td { font-size: 1.1em; } .warning { background: #fff3e0; border-left: 4px solid #ef6c00;
padding: 0.4em 0.8em; margin: 0.3em 0; }
figure { display: inline-block; margin: 0.5em 1%; width: 47%; vertical-align: top; }
figure img { width: 100%; height: auto; } .small { color: #666; font-size: 0.85em; }
@media (max-width: 40em) { figure { display: block; width: 100%; margin: 0.8em 0; } }
'''


def _deg(value):
    """Return an angle in degrees for people, 0.0-359.9 (359.97 reads 0.0)."""
    return f'{round(value, 1) % 360.0:.1f}'


def _grade_box(label, value, grade):
    if value is None:
        return f'<div class="unknown">{escape(label)}<b>no grade</b>no load cells</div>'
    within = value <= grade
    verdict = f'within G {grade:g}' if within else f'OUT OF G {grade:g}'
    return (f'<div class="{"ok" if within else "out"}">{escape(label)}'
            f'<b>G {value:.2f}</b>{verdict}</div>')


def _table(header, rows, text_columns=1, css=''):
    """
    Return a table (in a box that scrolls sideways when it is wider than the screen).

    ``header`` the column names; the first ``text_columns`` columns are left-aligned.
    """
    head = ''.join(f'<th class="text">{escape(h)}</th>' if i < text_columns
                   else f'<th>{escape(h)}</th>' for i, h in enumerate(header))
    body = ''.join('<tr>' + ''.join(
        f'<td class="text">{escape(str(c))}</td>' if i < text_columns
        else f'<td>{escape(str(c))}</td>' for i, c in enumerate(row)) + '</tr>' for row in rows)
    return f'<div class="scroll"><table class="{css}"><tr>{head}</tr>{body}</table></div>'


def _pairs(rows):
    """Return a table of (what, value) rows: each row headed by its name, no header row."""
    body = ''.join(f'<tr><th class="text" scope="row">{escape(str(k))}</th>'
                   f'<td class="text">{escape(str(v))}</td></tr>' for k, v in rows)
    return f'<div class="scroll"><table class="pairs">{body}</table></div>'


def _hole(weight):
    """Return the hole as people count it ('7: 90 deg from the mark ...'), or '-'."""
    if not weight.get('hole'):
        return '-'
    return weight['hole_text'].removeprefix('hole ').replace(', ', ': ', 1)


def _segment_row(segment, used):
    layout = segment['layout']
    steady = segment['steady']
    grade = segment.get('grade')
    return (segment['number'], f"{segment['from']:.3f}-{segment['to']:.3f}",
            f"{layout['name']} ({layout['digest']})" if layout else 'none',
            f"{steady['window'][0]:.3f}-{steady['window'][1]:.3f}" if steady
            else segment['note'] or '-',
            f"{steady['speed']:.4g}" if steady else '-',
            steady['revolutions'] if steady else '-',
            f"G {grade['equivalent_grade']:.2f}" if grade else '-',
            'yes' if segment['number'] == used else '')


def _check_html(check):
    if not check['checked']:
        return f'<p>Not checked: {escape(check["note"])}</p>'
    rows = [(p['plane'], f"{p['factor']:.3g}", f"{round(p['phase_deg']) + 0:+d}",
             'yes' if p['agrees'] else 'NO') for p in check['planes']]
    said = ('The measured coefficients are what the layout\'s physics predicts for load cells '
            'on a rigid rotor (within a factor 3 and 45 deg).' if check['agrees'] else
            escape(check['message']))
    return (_table(('plane', 'measured / predicted', 'phase [deg]', 'agrees'), rows)
            + f'<p>{said}</p>')


def page(summary, figures, generated=None):
    """
    Return the report's HTML text.

    ``figures``: [(file name, caption)] of the PNGs beside the page; ``generated`` the
    time the report is made (default now, UTC).
    """
    generated = generated or datetime.datetime.now(datetime.timezone.utc)
    run, grade = summary['run'], summary['grade']
    plan = next((p for p in summary['plans'] if p['name'] == summary['recommended']), None)
    layout = run['layout']
    by_hand = run['bag'] is None
    title = f"Field balancing report: {layout['name'] if layout else run['bag'] or 'readings'}"
    source = 'readings by hand' if by_hand else \
        f'run {escape(run["bag"])}, recorded {escape(run["date"])}'
    parts = [f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
             '<meta name="viewport" content="width=device-width, initial-scale=1">'
             f'<title>{escape(title)}</title><style>{STYLE}</style></head><body>',
             f'<h1>{escape(title)}</h1>',
             f'<p class="small">{source}; '
             f'layout {escape(layout["name"]) if layout else "none"} '
             f'(digest {escape(layout["digest"]) if layout else "-"})</p>']
    if grade is not None:
        # The verdict of record: what the machine measures, labelled; the layout's beside.
        boxes = [_grade_box(f"before, measured by {grade.get('source', 'the load cells')}",
                            grade['before']['equivalent_grade'], grade['grade'])]
        if plan is None:
            boxes.append('<div class="out">after<b>no plan</b>every plan would leave the '
                         'rotor worse</div>')
        else:
            after = plan['after']['equivalent_grade'] if plan['after'] else None
            boxes.append(_grade_box(f'after the {plan["name"]} plan (predicted)', after,
                                    grade['grade']))
        measured = summary.get('measured_after')
        if measured is not None:
            boxes.append(_grade_box('measured after', measured['equivalent_grade'],
                                    grade['grade']))
        parts.append('<div class="verdict" id="verdict">' + ''.join(boxes) + '</div>')
        if grade.get('layout_expects'):
            parts.append(f'<p id="layout-expects">{escape(grade["layout_expects"]["text"])}'
                         '</p>')
        if grade.get('disagreement'):
            parts.append(f'<p class="warning" id="disagreement"><b>'
                         f'{escape(grade["disagreement"])}</b></p>')
        parts.append(f'<p>ISO 21940-11 grade G {grade["grade"]:g} at '
                     f'{grade["speed"]:.4g} rad/s ({grade["speed"] * 30 / 3.141592653589793:.0f} '
                     f'rpm), rotor {grade["mass"]:.1f} kg.</p>')
    else:
        parts.append('<div class="verdict" id="verdict">'
                     + _grade_box('grade', None, 0.0) + '</div>')
    parts.append('<h2 id="bolt">What to bolt where</h2>')
    if plan is None:
        parts.append('<p id="no-plan"><b>Nothing: no plan is recommended.</b> Every plan '
                     'would leave the rotor worse than it is now (see the warnings); check '
                     'the coefficients and the trial runs.</p>')
    elif plan['weights'] or plan.get('removed'):
        trim = bool(summary.get('weights_on'))
        rows = [(w['plane'], _deg(w['angle_deg']), _hole(w), f"{w['radius']:.3f}",
                 ' + '.join(f'{m * 1000:g} g' for m in w['masses']), f"{w['mass'] * 1000:g}")
                + ((action,) if trim else ())
                for action, key in (('add', 'weights'), ('take off', 'removed'))
                for w in plan.get(key, ())]
        parts.append(_table(('plane', 'site angle [deg]', 'hole', 'radius [m]', 'weights',
                             'total [g]') + (('do',) if trim else ()), rows, 1, 'bolt'))
        if trim:
            parts.append('<h2 id="loading">Loading after, per site</h2>' + _table(
                ('plane', 'site angle [deg]', 'hole', 'weights', 'total [g]'),
                [(w['plane'], _deg(w['angle_deg']), _hole(w),
                  ' + '.join(f'{m * 1000:g} g' for m in w['masses']), f"{w['mass'] * 1000:g}")
                 for w in plan['final']], 1))
        if plan['name'] == 'split':
            how = 'the vector split of the continuous correction, rounded to the kit'
        elif summary['objective'] == 'fewest':
            how = 'the fewest weights within the limits (mixed-integer plan, HiGHS: ' \
                f'{plan["status"]})'
        else:
            how = f'the smallest residual with at most {summary["max_weights"]} weights ' \
                f'(proven by enumeration or HiGHS: {plan["status"]})'
        parts.append(f'<p>{plan["count"]} weights: {escape(how)}. Angles in the rotor frame, '
                     'from rotor X toward rotor Y; radius of the weights\' centres.</p>')
    else:
        rows = [(c['plane'], _deg(c['angle_deg']),
                 f"{c['radius']:.3f}" if c['radius'] else '-',
                 f"{c['mass'] * 1000:.1f}" if c['mass'] is not None and
                 summary['unit'] == 'kg m' else f"{c['unbalance']:.4g} {summary['unit']}")
                for c in plan['corrections']]
        parts.append(_table(('plane', 'angle [deg]', 'radius [m]', 'mass [g]'), rows, 1,
                            'bolt'))
        parts.append('<p>The layout gives no weight sites: the continuous correction.</p>')
    if summary['warnings']:
        parts.append('<h2>Warnings</h2>' + ''.join(
            f'<div class="warning">{escape(w)}</div>' for w in summary['warnings']))
    parts.append('<h2>Figures</h2>' + ''.join(
        f'<figure><img src="{escape(name)}" alt="{escape(caption)}">'
        f'<figcaption class="small">{escape(caption)}</figcaption></figure>'
        for name, caption in figures))
    parts.append('<h2>Plans compared</h2>')
    rows = []
    for p in summary['plans']:
        after = p['after']
        rows.append((p['name'], p['status'], p['count'] if p['name'] != 'continuous' else '-',
                     f"{p['residual']['rms']:.4g}",
                     f"G {after['equivalent_grade']:.2f}" if after else '-',
                     ', '.join(f"{q['g_mm']:.0f}" for q in after['planes']) if after else '-'))
    parts.append(_table(('plan', 'status', 'weights', 'residual rms', 'grade after',
                         'unbalance after [g mm]'), rows, 2))
    parts.append(f'<p class="small">Corrections from the {escape(summary["method"])}; '
                 f'objective: {escape(summary["objective"])}. The residual rms is taken '
                 'over the channels, each weighted (by its noise, or by its permissible '
                 'unbalance).</p>')
    if grade is not None:
        rows = [(q['plane'], f"{q['z']:+.3f}", f"{q['g_mm']:.0f}", _deg(q['angle_deg']),
                 f"{q['ci95_g_mm']:.0f}" if q.get('ci95_g_mm') is not None else '-',
                 f"{q['permissible_g_mm']:.0f}") for q in grade['before']['planes']]
        origin = escape(grade.get('source', 'the load cells'))
        parts.append(f'<h2>Unbalance before (from {origin})</h2>'
                     + _table(('plane', 'z [m]', 'U [g mm]', 'angle [deg]', '95 % [g mm]',
                               'allowed [g mm]'), rows))
    if by_hand:
        rows = [('readings', 'by hand'),
                ('layout', f"{layout['name']} ({layout['digest']})" if layout else 'none'),
                ('speed', f"{run['speed']:.5g} rad/s" if run['speed'] else 'not given')]
    else:
        rows = [('bag', run['bag']), ('recorded (first message, UTC)', run['date']),
                ('layout', f"{layout['name']} ({layout['digest']})" if layout else 'none'),
                ('steady speed', f"{run['speed']:.5g} rad/s (spread "
                                 f"{run['speed_spread']:.2%})"),
                ('read over', f"{run['revolutions']} whole revolutions, "
                              f"{run['window'][0]:.3f}-{run['window'][1]:.3f} s")]
    measured = summary.get('measured_after')
    if measured is not None:
        rows.append(('check run after', f"{measured['bag']} ({measured['date']}): G "
                     f"{measured['equivalent_grade']:.2f}, " + ', '.join(
                         f"plane {q['plane']} {q['g_mm']:.0f} g mm" for q in
                         measured['planes'])))
    parts.append('<h2>Run</h2>' + _pairs(rows))
    segments = summary.get('segments') or []
    if segments:
        parts.append('<h2 id="segments">Layout segments of the run</h2>' + _table(
            ('segment', 'from-to [s]', 'layout', 'steady stretch [s]', 'speed [rad/s]',
             'revolutions', 'load cells', 'read'),
            [_segment_row(s, run.get('segment')) for s in segments], 3))
        parts.append('<p class="small">A run is read inside one layout segment, never across '
                     'a layout change (--segment N to choose).</p>')
    parts.append('<h2 id="readings">1x readings (order tracking)</h2>')
    parts.append(_table(('channel', 'unit', '1x amplitude', 'phase [deg]', 'std. error'),
                        [(r['channel'], r['unit'], f"{r['amplitude']:.4g}",
                          _deg(r['phase_deg']),
                          '-' if r['sigma'] is None else f"{r['sigma']:.2g}")
                         for r in summary['readings']], 2))
    coefficients = summary['coefficients']
    if coefficients is not None:
        condition = coefficients['condition_number']
        parts.append('<h2>Influence coefficients used</h2>' + _table(
            ['sensor'] + [f'plane {p}' for p in coefficients['planes']],
            [[s] + [f"{e['amplitude']:.4g} @ {_deg(e['phase_deg'])}" for e in row]
             for s, row in zip(coefficients['sensors'], coefficients['values'])]))
        parts.append(f'<p>Reading per {escape(summary["unit"])}; condition number '
                     f'{"inf" if condition is None else f"{condition:.3g}"}; from '
                     + ', '.join(escape(f"{r['role']}: {r['bag']}")
                                 for r in coefficients['runs']) + '.</p>')
        check = summary.get('model_check')
        if check is not None:
            parts.append('<h2 id="physics">Coefficients against the layout\'s physics</h2>'
                         + _check_html(check))
    parts.append(f'<p class="small">cvc-balance report, generated '
                 f'{escape(generated.isoformat(timespec="seconds"))}.</p></body></html>')
    return '\n'.join(parts)
