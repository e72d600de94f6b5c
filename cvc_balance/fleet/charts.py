"""
The trends as pictures (PNG, matplotlib without pyplot's global state).

Per machine (:func:`machine_chart`): one panel per correction plane, its unbalance per run
(g mm, as its drift is in g mm a day; identified from the load cells, with their 95 % bars,
or the layout's, hollow), its permissible share of the grade (red, stepping where a layout
change moves it), the fitted drift of each layout epoch and its projection with the 95 %
band up to the projected date of leaving the grade (shaded: its interval), and each layout
change (grey, labelled with its step). For the fleet (:func:`fleet_chart`): the most urgent
machines, each a bar to its projected date with the interval, those out of grade now
in red at the left.
"""

from datetime import timedelta
import re

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter, date2num
from matplotlib.figure import Figure
from matplotlib.ticker import StrMethodFormatter

from cvc_balance.fleet.trends import DAY_NS, LEAVES, OUT

RED, BLUE, GREY = '#c0392b', '#1f5f99', '#7f7f7f'


def chart_name(machine_id):
    """Return a file name for a machine's chart (its id with / and odd characters as _)."""
    return re.sub(r'[^A-Za-z0-9_.@+-]', '_', machine_id) + '.png'


def _dates(ns):
    return np.asarray(ns, dtype='datetime64[ns]').astype('datetime64[us]').astype(object)


def machine_chart(trend, path):
    """Draw one machine's trends (see the module's description) to ``path``; its Figure."""
    planes = trend.planes
    figure = Figure(figsize=(9.0, 2.9 * max(len(planes), 1) + 0.6), dpi=110)
    FigureCanvasAgg(figure)
    title = f'{trend.machine_id}: {trend.status}'
    if trend.status == LEAVES and trend.leaves is not None:
        title += f' {trend.leaves:%Y-%m-%d}'
    figure.suptitle(f'{title}   (layout {trend.layout}, G {trend.grade:g}, {trend.runs} runs)',
                    fontsize=11)
    axes = figure.subplots(max(len(planes), 1), 1, sharex=True, squeeze=False)[:, 0]
    end = max(_end(plane) for plane in planes) if planes else 0
    for ax, plane in zip(axes, planes):
        _plane(ax, plane, trend, end)
    if not planes:                  # every machine gets its chart: this one says why it is empty
        axes[0].set_axis_off()
        axes[0].text(0.5, 0.5, 'no correction plane to chart: its runs gave no plane unbalance',
                     ha='center', va='center', transform=axes[0].transAxes)
    locator = AutoDateLocator()
    axes[-1].xaxis.set_major_locator(locator)
    axes[-1].xaxis.set_major_formatter(ConciseDateFormatter(locator))
    figure.tight_layout()
    figure.savefig(path)
    return figure


def _end(plane):
    """Return the last time (ns) a plane's chart shows: its last run or its projection."""
    if plane.status == LEAVES and plane.leaves_latest is not None:
        return int(plane.leaves_latest.timestamp() * 1e9)
    if plane.status == LEAVES and plane.leaves is not None:
        return int(plane.leaves.timestamp() * 1e9) + 30 * DAY_NS
    return int(plane.times[-1])


def _plane(ax, plane, trend, chart_end):
    """One plane's panel, in g mm throughout: its axis, its drift (per day) and its steps."""
    when = _dates(plane.times)
    ident = plane.identified
    ax.errorbar(when[ident], plane.amount[ident], yerr=np.nan_to_num(plane.ci95[ident]),
                fmt='o', color=BLUE, ms=4, capsize=2, label='identified (load cells), 95 %')
    if (~ident).any():
        ax.plot(when[~ident], plane.amount[~ident], 'o', mfc='none', color=BLUE,
                label="layout's")
    end = _end(plane)
    steps = np.concatenate([plane.times, [max(chart_end, int(plane.times[-1]))]])
    ax.step(_dates(steps), np.concatenate([plane.permissible, plane.permissible[-1:]]),
            where='post', color=RED, lw=1.5, label=f'permissible (G {trend.grade:g})')
    if plane.levels is not None:
        for k in range(len(plane.levels)):
            inside = plane.times[plane.epoch == k]
            span = np.linspace(inside[0], inside[-1], 20)
            ax.plot(_dates(span), plane.line(span, k), color='black', lw=1)
        if plane.status == LEAVES:
            ahead = np.linspace(plane.times[-1], end, 200)
            line, half = plane.line(ahead), plane.band(ahead)
            ax.plot(_dates(ahead), line, '--', color='black', lw=1,
                    label=f'drift {plane.drift:+.0f} +- {plane.drift_ci95:.0f} g mm/day')
            ax.fill_between(_dates(ahead), line - half, line + half,
                            color='black', alpha=0.1, lw=0)
            latest = plane.leaves_latest or (plane.leaves + timedelta(days=30))
            ax.axvspan(date2num(plane.leaves_earliest), date2num(latest), color=RED,
                       alpha=0.12, lw=0)
            ax.axvline(date2num(plane.leaves), color=RED, ls=':', lw=1)
        else:
            ax.plot([], [], color='black', lw=1,
                    label=f'drift {plane.drift:+.0f} +- {plane.drift_ci95:.0f} g mm/day')
    for change in trend.changes:
        step = change.steps.get(plane.plane)
        ax.axvline(date2num(change.when), color=GREY, ls='--', lw=1)
        if step is not None and np.isfinite(step[0]):
            ax.annotate(f'layout change: {step[0]:+,.0f} +- {step[1]:,.0f} g mm',
                        (date2num(change.when), 0.97), xycoords=('data', 'axes fraction'),
                        ha='left', va='top', fontsize=8, color=GREY, rotation=0,
                        xytext=(3, 0), textcoords='offset points')
    status = plane.status + (f' {plane.leaves:%Y-%m-%d}' if plane.leaves else '')
    ax.set_title(f'plane {plane.plane}: {status}', fontsize=10, loc='left')
    ax.set_ylabel('unbalance [g mm]')
    ax.yaxis.set_major_formatter(StrMethodFormatter('{x:,.0f}'))
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='best', framealpha=0.8)


def fleet_chart(trends, path, most=30):
    """Draw the ``most`` most urgent machines (days to leaving the grade) to ``path``."""
    shown = trends[:most]
    figure = Figure(figsize=(8.0, 0.28 * max(len(shown), 1) + 1.4), dpi=110)
    FigureCanvasAgg(figure)
    ax = figure.subplots()
    labels, rows = [], range(len(shown))
    for row, trend in zip(rows, shown):
        labels.append(trend.machine_id)
        worst = next((p for p in trend.planes if p.plane == trend.worst_plane), None)
        if trend.status == OUT:
            ax.barh(row, 0.0, color=RED)
            ax.text(0, row, f' out of grade now (plane {trend.worst_plane}: '
                    f'{worst.now_fraction:.2f} of its share)', va='center', fontsize=7,
                    color=RED)
        elif trend.status == LEAVES and worst is not None:
            now = worst.times[-1]
            days = (worst.leaves.timestamp() * 1e9 - now) / DAY_NS
            early = (worst.leaves_earliest.timestamp() * 1e9 - now) / DAY_NS
            late = (worst.leaves_latest.timestamp() * 1e9 - now) / DAY_NS \
                if worst.leaves_latest else None
            right = late if late is not None else days * 2
            ax.barh(row, days, color=BLUE, alpha=0.8)
            ax.plot([early, right], [row, row], color='black', lw=1)
            ax.text(right, row, f' {worst.leaves:%Y-%m-%d} (plane {worst.plane}'
                    + ('' if late is not None else '; may never leave') + ')', va='center',
                    fontsize=7)
        else:
            ax.text(0, row, f' {trend.status}', va='center', fontsize=7, color=GREY)
    ax.set_yticks(list(rows), labels, fontsize=7)
    ax.set_ylim(max(len(shown), 1) - 0.5, -0.5)     # top down; the last row not on the edge
    ax.set_xlabel('days from the last run to leaving the grade (95 % interval)')
    ax.set_title('machines by urgency', fontsize=10, loc='left')
    ax.grid(axis='x', alpha=0.3)
    figure.tight_layout()
    figure.savefig(path)
