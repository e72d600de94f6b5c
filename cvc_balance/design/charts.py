"""
Charts of a sweep (:mod:`cvc_balance.design.sweep`): the design package's only matplotlib.

One parameter: the judged planes' unbalance (g mm) with the grade's band (on a
log axis when the band is under a twentieth of the largest unbalance: on a linear
one it would be a hairline at the bottom) and, beside it, the first balance
point's neighbourhood (the band is narrow there: the thesis's point),
the supports' unbalance loads and the resultant F_res (N), and, asked for,
the derivative of F_res: the norm's one-sided slope (which jumps at balance,
thesis Figs. 4.3, 4.4, 4.7, 4.8) beside the vector's components (smooth).
Two parameters: contour maps of the worse plane's unbalance with the
within-grade region outlined, and of F_res (thesis Figs. 4.2, 4.6). Balance
points are marked. Angles in degrees, other parameters in SI units.
"""

import math

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the file backend)
import numpy as np  # noqa: E402

G_MM = 1e6
"""g mm per kg m."""
BAND = (0.15, 0.85, 0.15, 0.18)
"""The within-grade band: green, light enough for the lines over it."""
LOG_BELOW = 0.05
"""A grade band under this fraction of the largest unbalance is drawn on a log axis."""
PLANE_NAMES = ('plane I', 'plane II')
COLOURS = ('tab:blue', 'tab:orange', 'tab:green', 'tab:red')


def axis_values(parameter, values):
    """Grid values for people: degrees for angles, SI otherwise."""
    values = np.asarray(values, dtype=float)
    return np.degrees(values) if parameter.name == 'angle' else values


def axis_label(parameter):
    """Axis label with the unit people read."""
    unit = {'mass': 'kg', 'radius': 'm', 'angle': 'deg', 'z': 'm'}[parameter.name]
    return f'{parameter.label} [{unit}]'


def draw_sweep(result, path, derivative=False, title=None):
    """Draw ``result`` (a Sweep) to the PNG file ``path``."""
    figure = sweep_figure(result, derivative, title)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def sweep_figure(result, derivative=False, title=None):
    """Return the figure of ``result`` (a Sweep), drawn; the caller closes it."""
    if len(result.parameters) == 1:
        figure = _one_parameter(result, derivative)
    else:
        figure = _two_parameters(result)
    figure.suptitle(title or _title(result), fontsize=11)
    return figure


def _title(result):
    layout = result.layout
    speed = '' if result.omega is None else f', omega {result.omega:g} rad/s'
    grade = '' if result.grade is None else f', G {result.grade:g}'
    return f'{layout.name}: sweep of {" and ".join(p.label for p in result.parameters)}' \
        f'{speed}{grade}'


def _plane_labels(result):
    planes = result.layout.correction_planes()
    if planes is None:
        return ('static unbalance',)
    return tuple(f'{name} (z {z:g} m)' for name, z in zip(PLANE_NAMES, planes))


def _one_parameter(result, derivative):
    parameter = result.parameters[0]
    x = axis_values(parameter, result.axes[0])
    rows = 2 + (derivative and result.d_resultant is not None)
    amounts = np.hypot(result.planes[..., 0], result.planes[..., 1]) * G_MM
    zoom = _zoom_range(result, amounts)
    figure = plt.figure(figsize=(10.5 if zoom else 9, 3.3 * rows + 0.6),
                        constrained_layout=True)
    # With a zoom panel beside the first row, the other rows keep the same width (their
    # legends go beside them), so the parameter axis lines up from top to bottom.
    grid = figure.add_gridspec(rows, 2 if zoom else 1, width_ratios=(3, 1) if zoom else None)
    top = figure.add_subplot(grid[0, 0])
    axes = [top] + [figure.add_subplot(grid[row, 0], sharex=top) for row in range(1, rows)]
    beside = [figure.add_subplot(grid[row, 1]) for row in range(1, rows)] if zoom else []
    for i, label in enumerate(_plane_labels(result)):
        top.plot(x, amounts[:, i], color=COLOURS[i], label=label,
                 linestyle='-' if i == 0 else '--')
    bottom = _unbalance_axis(top, result, amounts)
    _grade_band(top, result, bottom)
    _mark_points(top, result, parameter)
    top.legend(loc='upper right', fontsize=8)
    top.grid(alpha=0.3)
    if zoom:
        _zoom(figure.add_subplot(grid[0, 1]), result, parameter, *zoom)
    loads = axes[1]
    if result.supports is not None:
        for i, support in enumerate(result.layout.supports):
            force = np.hypot(result.supports[:, i, 0], result.supports[:, i, 1])
            loads.plot(x, force, color=COLOURS[i], label=f'support {support.name}',
                       linestyle='-' if i == 0 else '--')
        loads.plot(x, result.resultant, color='black', linewidth=1.0,
                   label='resultant F_res = omega^2 |S|')
        loads.set_ylabel(f'unbalance load at {result.omega:g} rad/s [N]')
        loads.legend(loc='upper right', fontsize=8)
        _mark_points(loads, result, parameter, label=False)
    else:
        loads.text(0.5, 0.5, 'no speed: give --omega or balancing.service_speed',
                   ha='center', va='center', transform=loads.transAxes)
    loads.set_ylim(bottom=0.0)
    loads.grid(alpha=0.3)
    if rows == 3:
        _derivative(axes[2], result, x, parameter)
    for ax, side in zip(axes[1:], beside):
        side.axis('off')
        if ax.get_legend() is not None:
            ax.get_legend().remove()
            side.legend(*ax.get_legend_handles_labels(), loc='center left', fontsize=8)
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel(axis_label(parameter))
    return figure


def _derivative(ax, result, x, parameter):
    per = 'deg' if parameter.name == 'angle' else {'mass': 'kg', 'radius': 'm', 'z': 'm'}[
        parameter.name]
    to_display = math.pi / 180.0 if parameter.name == 'angle' else 1.0
    minus, plus = result.resultant_slopes
    d = result.d_resultant * to_display
    ax.plot(x, plus * to_display, color='black', linewidth=1.6,
            label='d|F_res|/dp (the norm: jumps at balance)')
    kinks = np.flatnonzero(minus != plus)
    if kinks.size:
        ax.plot(x[kinks], minus[kinks] * to_display, 'o', color='black', fillstyle='none',
                label='one-sided slope from below')
    ax.plot(x, d[:, 0], color='tab:purple', linestyle='--', label='dF_x/dp (vector: smooth)')
    ax.plot(x, d[:, 1], color='tab:green', linestyle=':', label='dF_y/dp (vector: smooth)')
    ax.axhline(0.0, color='grey', linewidth=0.6)
    _mark_points(ax, result, parameter, label=False)
    ax.set_ylabel(f'derivative [N/{per}]')
    ax.legend(loc='best', fontsize=8)
    ax.grid(alpha=0.3)


def _unbalance_axis(ax, result, amounts):
    """
    Scale the unbalance axis so the grade's band can be seen; return its bottom (g mm).

    Linear from 0 while the band is a twentieth of the largest unbalance or more; else
    logarithmic from a decade under the band's top (a balance point dips out of sight
    at the bottom: its exact zero has no logarithm).
    """
    largest = float(np.max(amounts))
    if result.permissible is None or largest <= 0.0 or \
            float(np.min(result.permissible)) * G_MM >= LOG_BELOW * largest:
        ax.set_ylabel('unbalance [g mm]')
        ax.set_ylim(bottom=0.0)
        return 0.0
    bottom = 0.1 * float(np.min(result.permissible)) * G_MM
    ax.set_yscale('log')
    ax.set_ylim(bottom, 2.0 * max(largest, float(np.max(result.permissible)) * G_MM))
    ax.set_ylabel('unbalance [g mm], log scale')
    return bottom


def _grade_band(ax, result, bottom=0.0):
    if result.permissible is None:
        return
    allowed = result.permissible * G_MM
    ax.axhspan(bottom, float(np.min(allowed)), color=BAND, label=f'within G {result.grade:g}')
    for i, value in enumerate(allowed):
        ax.axhline(value, color=COLOURS[i], linewidth=0.8, linestyle=':')


def _mark_points(ax, result, parameter, label=True):
    for point in result.balance_points:
        value = axis_values(parameter, point.values[0])
        ax.axvline(value, color='red' if point.balanced else 'grey', linewidth=0.8,
                   linestyle='-.')
        if label:
            kind = 'balance' if point.balanced else 'least unbalance'
            unit = 'deg' if parameter.name == 'angle' else ''
            ax.annotate(f'{kind} at {value:.6g} {unit}'.strip(), (value, 0.0),
                        xycoords=('data', 'axes fraction'), xytext=(4, 6),
                        textcoords='offset points', fontsize=8,
                        color='red' if point.balanced else 'dimgrey')


def _zoom_range(result, amounts):
    """(point, index, half-width) to zoom on when the grade's band is too thin to see."""
    if result.permissible is None or not result.balance_points or result.d_planes is None:
        return None
    allowed = float(np.max(result.permissible)) * G_MM
    if allowed > 0.05 * float(np.max(amounts)):
        return None
    point = result.balance_points[0]
    index = int(np.argmin(np.abs(result.axes[0] - point.values[0])))
    steep = float(np.max(np.hypot(result.d_planes[index, :, 0],
                                  result.d_planes[index, :, 1]))) * G_MM
    if steep <= 0.0:
        return None
    return point, index, 4.0 * allowed / steep


def _zoom(ax, result, parameter, point, index, half):
    """Draw the balance point's neighbourhood, linearised (its derivative), with the band."""
    centre = point.values[0]
    local = np.linspace(centre - half, centre + half, 401)
    allowed = float(np.max(result.permissible)) * G_MM
    for k in range(result.planes.shape[-2]):
        base = np.asarray(point.planes[k]) * G_MM
        slope = result.d_planes[index, k] * G_MM
        values = np.hypot(base[0] + slope[0] * (local - centre),
                          base[1] + slope[1] * (local - centre))
        ax.plot(axis_values(parameter, local), values, color=COLOURS[k],
                linestyle='-' if k == 0 else '--')
    ax.axhspan(0.0, float(np.min(result.permissible)) * G_MM, color=BAND)
    for k, value in enumerate(result.permissible * G_MM):
        ax.axhline(value, color=COLOURS[k], linewidth=0.8, linestyle=':')
    ax.set_ylim(0.0, 3.0 * allowed)
    ax.xaxis.set_major_locator(plt.MaxNLocator(3))
    ax.tick_params(labelsize=8)
    ax.set_title('near the point (linearised):\nthe grade band', fontsize=9)
    ax.set_xlabel(axis_label(parameter), fontsize=8)
    ax.grid(alpha=0.3)


def _two_parameters(result):
    px, py = result.parameters
    x, y = axis_values(px, result.axes[0]), axis_values(py, result.axes[1])
    amounts = np.hypot(result.planes[..., 0], result.planes[..., 1]) * G_MM
    worst = np.max(amounts, axis=-1)
    panels = 1 + (result.resultant is not None)
    figure, axes = plt.subplots(1, panels, figsize=(6.2 * panels, 5.4),
                                constrained_layout=True, squeeze=False)
    ax = axes[0, 0]
    filled = ax.contourf(x, y, worst.T, levels=24, cmap='viridis')
    figure.colorbar(filled, ax=ax, label='worse plane unbalance [g mm]')
    if result.permissible is not None:
        ratio = np.max(amounts / (result.permissible * G_MM), axis=-1)
        inside = int(np.count_nonzero(ratio <= 1.0))
        if inside > 1:
            ax.contour(x, y, ratio.T, levels=[1.0], colors='white', linewidths=1.2)
        note = '' if inside > 1 else ' (narrower than the grid)'
        ax.plot([], [], color='white', label=f'edge of G {result.grade:g}{note}')
    _mark_map(ax, result, px, py)
    ax.set_xlabel(axis_label(px))
    ax.set_ylabel(axis_label(py))
    ax.set_title('unbalance, worse correction plane', fontsize=10)
    ax.legend(loc='upper right', fontsize=8, facecolor='lightgrey')
    if panels == 2:
        ax = axes[0, 1]
        filled = ax.contourf(x, y, result.resultant.T, levels=24, cmap='magma')
        figure.colorbar(filled, ax=ax, label='F_res = omega^2 |S| [N]')
        ax.contour(x, y, result.resultant.T, levels=12, colors='white', linewidths=0.4,
                   alpha=0.5)
        _mark_map(ax, result, px, py)
        ax.set_xlabel(axis_label(px))
        ax.set_ylabel(axis_label(py))
        ax.set_title(f'resultant unbalance force at {result.omega:g} rad/s', fontsize=10)
        ax.legend(loc='upper right', fontsize=8, facecolor='lightgrey')
    return figure


def _mark_map(ax, result, px, py):
    for point in result.balance_points:
        vx, vy = axis_values(px, point.values[0]), axis_values(py, point.values[1])
        kind = 'balance' if point.balanced else 'least unbalance'
        ax.plot(vx, vy, marker='x', color='red', markersize=10, markeredgewidth=2,
                linestyle='none', label=f'{kind} ({vx:.4g}, {vy:.4g})')
