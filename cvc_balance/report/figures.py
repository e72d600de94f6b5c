"""
The field-balancing report's figures (PNG, matplotlib without pyplot's global state).

Each function takes the correction summary (:func:`cvc_balance.cli.field.summarise`'s
JSON-able data: the docs' "JSON outputs") and writes one PNG. Unbalance in g mm, angles
in the rotor frame (from rotor X toward rotor Y, counter-clockwise in the plot), masses g.
"""

import math

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import StrMethodFormatter
import numpy as np

BEFORE, AFTER, MEASURED, WEIGHT = '#c62828', '#2e7d32', '#1565c0', '#ef6c00'
DPI = 100
WIDTH = 5.0
"""in: every figure's width. The page shows two side by side (about 465 CSS pixels each,
0.93 of its 500 pixels) or, on a phone, one across (about 364, 0.73 of them): the text
sizes below are then 11.6 CSS pixels or more, and 9.1 or more on a phone."""
TEXT, SMALL = 10.0, 9.0
"""pt: legends, labels and annotations; tick labels."""


def _save(figure, path):
    """Write the figure as a PNG; return it (drawn, for reading back what it shows)."""
    FigureCanvasAgg(figure)
    figure.savefig(path, dpi=DPI)
    return figure


def _vector(entry):
    return entry['g_mm'] * complex(math.cos(math.radians(entry['angle_deg'])),
                                   math.sin(math.radians(entry['angle_deg'])))


def plane_figure(summary, plane_index, path):
    """
    Write plane ``plane_index``'s polar plot: before, after, weights at their sites.

    With a grade: the identified unbalance before (red), the one predicted after the
    recommended plan (green) and measured after (blue) if a check run was given, the
    permissible circle (dashed); the plan's weights as a chain of vectors from before to
    after, and at their sites on the outer ring (orange, labelled in g), every site a
    grey dot. Without a grade: the plane's continuous correction and the weights.
    """
    plane = summary['planes'][plane_index]
    name = plane['name']
    plan = _recommended(summary)
    figure = Figure(figsize=(WIDTH, 6.0))
    axes = figure.add_subplot(projection='polar')
    grade = summary['grade']
    weights = [w for w in plan['weights'] if w['plane'] == name]
    reach, drawn = [], []
    if grade is not None and name in ('I', 'II'):
        k = ('I', 'II').index(name)
        before = _vector(grade['before']['planes'][k])
        allowed = grade['before']['planes'][k]['permissible_g_mm']
        after = _vector(plan['after']['planes'][k]) if plan['after'] else None
        reach += [abs(before), allowed] + ([abs(after)] if after is not None else [])
        circle = np.linspace(0.0, 2.0 * math.pi, 361)
        axes.plot(circle, np.full_like(circle, allowed), '--', color='0.35', lw=1.2,
                  label=f'allowed ({allowed:,.0f} g mm)')
        _arrow(axes, 0j, before, BEFORE, f'before {abs(before):,.0f} g mm', 2.4, drawn)
        tip = before
        for w in weights:      # the weights added head to tail: before + weights = after
            step = w['mass'] * w['radius'] * 1e6 * complex(math.cos(math.radians(
                w['angle_deg'])), math.sin(math.radians(w['angle_deg'])))
            _arrow(axes, tip, tip + step, WEIGHT, None, 1.2, drawn)
            tip += step
            reach.append(abs(tip))
        if after is not None:
            worse = '' if plan['name'] == summary['recommended'] else ' (worse: not recommended)'
            _arrow(axes, 0j, after, AFTER, f'after {abs(after):,.0f} g mm{worse}', 2.4, drawn)
        measured = summary.get('measured_after')
        if measured is not None:
            value = _vector(measured['planes'][k])
            reach.append(abs(value))
            _arrow(axes, 0j, value, MEASURED, f'measured after {abs(value):,.0f} g mm', 2.0,
                   drawn)
        title = f'plane {name} (z = {grade["before"]["planes"][k]["z"]:+.3f} m): unbalance, g mm'
    else:
        correction = next(c for c in summary['plans'][0]['corrections'] if c['plane'] == name)
        value = correction['unbalance'] * 1e6 * complex(
            math.cos(math.radians(correction['angle_deg'])),
            math.sin(math.radians(correction['angle_deg'])))
        reach.append(abs(value))
        unit = 'g mm' if summary['unit'] == 'kg m' else f'1e-6 {summary["unit"]}'
        _arrow(axes, 0j, value, AFTER, f'correction {abs(value):,.0f} {unit}', 2.4, drawn)
        tip = 0j
        for w in weights:      # the plan's weights head to tail: their sum against it
            step = w['mass'] * w['radius'] * 1e6 * complex(math.cos(math.radians(
                w['angle_deg'])), math.sin(math.radians(w['angle_deg'])))
            _arrow(axes, tip, tip + step, WEIGHT, None, 1.2, drawn)
            tip += step
            reach.append(abs(tip))
        title = f'plane {name}: the correction ({unit})'
    ring = 1.18 * max(reach + [1e-9])
    sites = plane['sites']
    if sites is not None:
        angles = np.radians(sites['angles_deg'])
        axes.plot(angles, np.full(len(angles), ring), 'o', color='0.6', ms=3.5,
                  label=f'{len(angles)} sites at r = {plane["radius"]:.3f} m')
    for w in weights:
        theta = math.radians(w['angle_deg'])
        axes.plot([theta], [ring], 'o', color=WEIGHT, ms=10, mec='black', mew=0.6)
        label = ' + '.join(f'{m * 1000:g}' for m in w['masses']) + ' g'
        axes.annotate(label, (theta, ring), xytext=(theta, ring * 0.84), ha='center',
                      va='center', fontsize=TEXT, weight='bold',
                      bbox={'boxstyle': 'round,pad=0.2', 'fc': 'white', 'ec': WEIGHT})
        drawn.append(theta)
    axes.plot([], [], 'o', color=WEIGHT, mec='black',
              label=f'weights ({_plan_label(summary, plan)})')
    axes.set_ylim(0.0, ring * 1.02)
    # The radial scale where nothing is drawn: the candidate angle farthest from it all.
    candidates = np.radians(np.arange(22.5, 360.0, 45.0))
    clearance = [min([abs(math.remainder(c - d, 2.0 * math.pi)) for d in drawn] or [math.pi])
                 for c in candidates]
    axes.set_rlabel_position(math.degrees(candidates[int(np.argmax(clearance))]))
    axes.tick_params(axis='y', labelsize=SMALL)
    axes.yaxis.set_major_formatter(StrMethodFormatter('{x:,.0f}'))
    axes.tick_params(axis='x', labelsize=TEXT)
    axes.set_title(title, fontsize=TEXT, pad=24)
    figure.legend(loc='lower center', ncol=1, fontsize=TEXT, frameon=False)
    figure.subplots_adjust(bottom=0.33, top=0.88, left=0.1, right=0.9)
    return _save(figure, path)


def _arrow(axes, start, end, colour, label, width, drawn=None):
    if drawn is not None:
        drawn.append(math.atan2(end.imag, end.real))
    axes.annotate('', xy=(math.atan2(end.imag, end.real), abs(end)),
                  xytext=(math.atan2(start.imag, start.real), abs(start)),
                  arrowprops={'arrowstyle': '-|>', 'color': colour, 'lw': width,
                              'shrinkA': 0, 'shrinkB': 0})
    if label:
        axes.plot([], [], color=colour, lw=width, label=label)


def grade_figure(summary, path):
    """Write the equivalent grade before, after each plan and measured after, against G."""
    grade = summary['grade']
    rows = [('before (measured)', grade['before']['equivalent_grade'], BEFORE)]
    for plan in summary['plans']:
        if plan['after'] is not None:
            rows.append((f"after: {plan['name']} plan", plan['after']['equivalent_grade'],
                         AFTER if plan['name'] == summary['recommended'] else '#81c784'))
    measured = summary.get('measured_after')
    if measured is not None:
        rows.append(('measured after', measured['equivalent_grade'], MEASURED))
    figure = Figure(figsize=(WIDTH, 0.55 * len(rows) + 1.5))
    axes = figure.add_subplot()
    labels = [r[0] for r in rows]
    values = [r[1] for r in rows]
    y = np.arange(len(rows))[::-1]
    axes.barh(y, values, color=[r[2] for r in rows], height=0.6)
    for yi, value in zip(y, values):
        axes.text(value, yi, f' G {value:.2f}', va='center', fontsize=TEXT)
    axes.axvline(grade['grade'], color='black', ls='--', lw=1.2)
    axes.text(grade['grade'], len(rows) - 0.4, f" G {grade['grade']:g} allowed", ha='left',
              va='center', fontsize=TEXT)
    axes.set_yticks(y, labels, fontsize=TEXT)
    axes.tick_params(axis='x', labelsize=SMALL)
    axes.set_xlim(0.0, 1.35 * max(values + [grade['grade']]))
    axes.set_ylim(-0.6, len(rows) - 0.05)
    axes.set_xlabel(f"equivalent grade G, mm/s, at {grade['speed']:.4g} rad/s",
                    fontsize=TEXT)
    figure.tight_layout()
    return _save(figure, path)


def readings_figure(summary, path):
    """Write each sensor's 1x amplitude before and predicted after the recommended plan."""
    plan = _recommended(summary)
    before = {r['channel']: r['amplitude'] for r in summary['readings']}
    channels = [c for c in plan['residual']['channels'] if c['name'] in before]
    names = [c['name'] for c in channels]
    after = [c['amplitude'] for c in channels]
    figure = Figure(figsize=(WIDTH, 0.5 * len(names) + 1.9))
    axes = figure.add_subplot()
    y = np.arange(len(names))[::-1]
    axes.barh(y + 0.18, [before[n] for n in names], 0.36, color=BEFORE, label='run (1x)')
    axes.barh(y - 0.18, after, 0.36, color=AFTER,
              label=f"predicted after the {_plan_label(summary, plan)}")
    units = {r['channel']: r['unit'] for r in summary['readings']}
    axes.set_yticks(y, [f'{n} [{units[n]}]' for n in names], fontsize=TEXT)
    axes.tick_params(axis='x', labelsize=SMALL)
    axes.set_xlabel('1x amplitude (each sensor in its unit)', fontsize=TEXT)
    figure.legend(fontsize=TEXT, loc='upper center', ncol=1, frameon=False)
    figure.tight_layout(rect=(0.0, 0.0, 1.0, 0.82))
    return _save(figure, path)


def _recommended(summary):
    """Return the plan drawn: the recommended one, else the continuous (shown as worse)."""
    return next((p for p in summary['plans'] if p['name'] == summary['recommended']),
                summary['plans'][0])


def _plan_label(summary, plan):
    if plan['name'] == summary['recommended']:
        return f"{plan['name']} plan"
    return f"{plan['name']} plan, NOT recommended: worse than now"
