"""
What a person reads in the charts: the sweep's grade band, the fleet chart's one unit.

A sweep of the thesis's two particles (docs/design_two_particles_r2.png): the band of
unbalance within G 6.3 is drawn where a person can see it (a fifth of the panel at least,
its top at the plane's permissible unbalance worked out by hand: G m / Omega, half a plane),
not as a hairline under 2e7 g mm. A fleet machine's chart (docs/fleet_machine.png): its
axes, its drift and its step labels in g mm, the permissible line at the trends' values.
"""

from pathlib import Path
import re

import numpy as np

from cvc_balance.design.parameters import design_parameter
from cvc_balance.physics.layout_file import load_layout

ROOT = Path(__file__).resolve().parents[1]


def rgb(figure):
    """Return the figure's pixels, (h, w, 3), row 0 at the top."""
    figure.canvas.draw()
    return np.asarray(figure.canvas.buffer_rgba())[..., :3].astype(int)


def test_the_sweep_shows_the_grade_band():
    from cvc_balance.design.charts import BAND, sweep_figure
    from cvc_balance.design.sweep import sweep
    layout = load_layout(ROOT / 'config' / 'thesis_two_particles.yaml')
    result = sweep(layout, [design_parameter(layout, 'B', 'radius')], [(0.0, 2.0)], 401)
    figure = sweep_figure(result, derivative=True)
    pixels = rgb(figure)
    top = figure.axes[0]
    height = pixels.shape[0]
    box = top.get_window_extent()
    # By hand: U_per = G m / Omega, both planes half of it (the particles at z = 0, the
    # planes at -+0.5 m); the band ends there.
    mass = sum(c.mass for c in layout.components)
    per_plane = 6.3e-3 * mass / 12.0 / 2.0 * 1e6                  # g mm
    assert abs(per_plane - 21000.0) < 1e-6
    # The band's colour over white, in a column away from the balance point (R2 = 0.35 m).
    paint = np.array([255.0 * (1 - BAND[3]) + 255.0 * BAND[3] * c for c in BAND[:3]])
    column = int(round(top.transData.transform((0.35, 1.0))[0]))
    rows = np.arange(int(height - box.y1) + 2, int(height - box.y0) - 2)
    band = rows[np.all(np.abs(pixels[rows, column] - paint) <= 6, axis=1)]
    assert len(band) >= 0.2 * box.height, (len(band), box.height)
    edge = height - top.transData.transform((0.35, per_plane))[1]
    assert abs(band.min() - edge) <= 3.0, (band.min(), edge)     # its dotted edge
    assert band.max() >= int(height - box.y0) - 4          # down to the axis' bottom
    # Its legend names it and the axis says how it is scaled.
    labels = [t.get_text() for t in top.get_legend().get_texts()]
    assert 'within G 6.3' in labels
    assert top.get_ylabel() == 'unbalance [g mm], log scale' and top.get_yscale() == 'log'
    import matplotlib.pyplot as plt
    plt.close(figure)


def test_the_fleet_chart_speaks_g_mm_throughout(tmp_path):
    """Axis, drift (per day) and permissible line in one unit, the trends' g mm."""
    from cvc_balance.cli import main
    from cvc_balance.fleet.charts import machine_chart
    from cvc_balance.fleet.simulate import simulate_fleet
    from cvc_balance.fleet.trends import machine_trends
    simulate_fleet(ROOT / 'config' / 'ct_gantry.yaml', tmp_path / 'runs', machines=1, runs=4,
                   seed=0)
    assert main(['fleet', str(tmp_path / 'runs'), '--out', str(tmp_path / 'fleet.parquet'),
                 '--engine', 'local', '--no-progress']) == 0
    (trend,) = machine_trends(tmp_path / 'fleet.parquet')
    figure = machine_chart(trend, tmp_path / 'machine.png')
    layout = load_layout(ROOT / 'config' / 'ct_gantry.yaml')
    mass = sum(c.mass for c in layout.components)
    z_com = sum(c.mass * c.z for c in layout.components) / mass
    z_i, z_ii = -0.12, 0.12                                  # its balancing.planes
    shares = [min(max((z_ii - z_com) / (z_ii - z_i), 0.3), 0.7),
              min(max((z_com - z_i) / (z_ii - z_i), 0.3), 0.7)]
    u_per = 6.3e-3 * mass / 23.27 * 1e6                       # g mm, G m / Omega
    for ax, plane, share in zip(figure.axes, trend.planes, shares):
        assert ax.get_ylabel() == 'unbalance [g mm]'
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        (drift,) = [t for t in legend if t.startswith('drift ')]
        assert re.fullmatch(r'drift [+-]\d+ \+- \d+ g mm/day', drift), drift
        (line,) = [ln for ln in ax.get_lines() if ln.get_label() == 'permissible (G 6.3)']
        assert np.allclose(line.get_ydata(), u_per * share, rtol=1e-9), \
            (line.get_ydata()[:2], u_per * share)
        # The tick labels people read are in the same g mm, with thousands separators.
        ticks = [t.get_text() for t in ax.get_yticklabels()]
        assert any(t.replace(',', '').isdigit() and int(t.replace(',', '')) >= 10_000
                   for t in ticks), ticks
