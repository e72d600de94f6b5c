"""
``cvc-balance bench``: every method's error against its cost, scene by scene.

For each scene (planar, axial offsets, tilt, spin-up, near-balance, 10^5 components)
every method of :mod:`cvc_balance.study.methods` computes the loads over motion samples; its
cost is the best wall time per sample of three runs, its error the largest relative
deviation from the 40-digit reference (:mod:`cvc_balance.study.exact`) over the samples (each
output scaled by the reference's largest value of it). Writes a CSV and a log-log chart
(error against time per sample, one mark per method per scene) and prints the table.
"""

import csv
import math
import time

import numpy as np

from cvc_balance.physics.frames import STANDARD_GRAVITY
from cvc_balance.physics.layout import parse_layout
from cvc_balance.study.exact import exact_loads
from cvc_balance.study.methods import METHODS

WORK_LIMIT = 3e7      # body- or particle-samples a method may be given per run


def _component(rng, i, z_range, kinds):
    kind = kinds[i % len(kinds)]
    item = {'name': f'c{i}', 'mass': float(rng.uniform(1.0, 60.0)),
            'radius': float(rng.uniform(0.2, 0.7)), 'angle': float(rng.uniform(0, 2 * math.pi)),
            'z': float(rng.uniform(*z_range))}
    if kind == 'box':
        item['shape'] = {'type': 'box', 'size': [float(v) for v in rng.uniform(0.05, 0.4, 3)]}
    elif kind == 'cylinder':
        item['shape'] = {'type': 'cylinder', 'radius': float(rng.uniform(0.03, 0.15)),
                         'length': float(rng.uniform(0.05, 0.4)),
                         'axis': ('radial', 'tangential', 'axial')[i % 3]}
    return item


def scenes(rng):
    """Return {name: (layout, q, omega, alpha, gravity)} of the bench's scenes."""
    supports = [{'name': 'front', 'z': -0.25}, {'name': 'rear', 'z': 0.25, 'axial': True}]
    g = (0.0, -STANDARD_GRAVITY, 0.0)
    tilt = math.radians(20.0)
    tilted = (0.0, -STANDARD_GRAVITY * math.cos(tilt), STANDARD_GRAVITY * math.sin(tilt))
    n = 512
    q = rng.uniform(0.0, 2 * math.pi, n)
    steady = np.full(n, 23.27)

    def layout(count, z_range=(0.0, 0.0), kinds=('point', 'cylinder_axial'), gravity=g):
        components = []
        for i in range(count):
            item = _component(rng, i, z_range, ('box', 'cylinder', 'point'))
            if kinds == ('point', 'cylinder_axial'):
                item.pop('shape', None)
                if i % 2:
                    item['shape'] = {'type': 'cylinder', 'radius': 0.08, 'length': 0.3}
            components.append(item)
        return parse_layout({'name': 'bench', 'components': components, 'supports': supports,
                             'gravity': list(gravity)})

    planar = layout(12)
    offsets = layout(12, (-0.3, 0.3), kinds=('box', 'cylinder', 'point'))
    near = _near_balance(layout(12, (-0.3, 0.3), kinds=('box', 'cylinder', 'point')))
    return {
        'planar': (planar, q, steady, np.zeros(n), g),
        'axial offsets': (offsets, q, steady, np.zeros(n), g),
        'tilt': (layout(12, (-0.3, 0.3), ('box', 'cylinder', 'point'), tilted), q, steady,
                 np.zeros(n), tilted),
        'spin-up': (offsets, q, np.linspace(0.0, 23.27, n), np.full(n, 6.0), g),
        'near-balance': (near, q, steady, np.zeros(n), (0.0, 0.0, 0.0)),
        '1e5 components': (layout(100_000, (-0.3, 0.3), ('box', 'cylinder', 'point')), q[:64],
                           steady[:64], np.zeros(64), g),
    }


def _near_balance(layout):
    """Two point masses that cancel static and couple unbalance, off by 1e-9."""
    from cvc_balance.physics.layout import Component
    from cvc_balance.study.exact import unbalance_about_o
    from dataclasses import replace
    (sx, sy), (pxz, pyz) = ((float(v) for v in pair) for pair in unbalance_about_o(layout))
    z1, z2, radius = -0.25, 0.25, 0.6
    # Plane unbalances to cancel (two-plane split), then 1e-9 of the mass moment left over.
    u1 = ((z2 * sx - pxz) / (z2 - z1), (z2 * sy - pyz) / (z2 - z1))
    u2 = ((pxz - z1 * sx) / (z2 - z1), (pyz - z1 * sy) / (z2 - z1))
    extra = []
    for name, (ux, uy), z in (('balance_front', u1, z1), ('balance_rear', u2, z2)):
        amount = math.hypot(ux, uy) * (1 + 1e-9)
        extra.append(Component(name, amount / radius, radius, math.atan2(-uy, -ux), z))
    return replace(layout, components=layout.components + tuple(extra))


def run(csv_path, png_path, seed=0, print_table=print):
    """Run every method on every scene; write the CSV and the chart; return the rows."""
    rng = np.random.default_rng(seed)
    rows = []
    for scene, (layout, q, omega, alpha, gravity) in scenes(rng).items():
        reference = exact_loads(layout, q, omega, alpha, gravity)
        for name, (prepare, compute) in METHODS.items():
            # Bodies (or particles) each sample visits; checked before preparing (10^4
            # particles for each of 10^5 components would not fit in memory).
            per_body = int(name.split('_')[1]) if name.startswith('particles_') else 1
            bodies = 1 if name.startswith('aggregated') else \
                len(layout.components) * per_body
            samples = min(len(q), int(WORK_LIMIT // bodies))   # costly methods: fewer
            if samples < 4:
                rows.append({'scene': scene, 'method': name, 'samples': 0,
                             'seconds_per_sample': '', 'max_relative_error': '',
                             'note': f'skipped: {bodies} bodies a sample'})
                continue
            state = prepare(layout)
            best = math.inf
            part = slice(0, samples)
            for _ in range(3):
                start = time.perf_counter()
                result = compute(state, q[part], omega[part], alpha[part], gravity)
                best = min(best, time.perf_counter() - start)
            error = max(_relative(got, ref[part]) for got, ref in zip(result, reference))
            rows.append({'scene': scene, 'method': name, 'samples': samples,
                         'seconds_per_sample': best / samples, 'max_relative_error': error,
                         'note': ''})
            print_table(f'{scene:16} {name:18} {best / len(q):10.3e} s/sample   '
                        f'error {error:9.2e}')
    with open(csv_path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    _chart(rows, png_path)
    return rows


def _relative(got, reference):
    scale = float(np.abs(reference).max())
    if scale == 0.0:
        return float(np.abs(got).max())
    return float(np.abs(np.asarray(got, float) - reference).max() / scale)


def pareto_front(rows, scene):
    """Methods of a scene that no other method beats in both time and error."""
    done = [r for r in rows if r['scene'] == scene and r['samples']]
    return [r['method'] for r in done if not any(
        o['seconds_per_sample'] < r['seconds_per_sample'] and
        o['max_relative_error'] < r['max_relative_error'] for o in done)]


def _chart(rows, png_path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    scenes_ = list(dict.fromkeys(r['scene'] for r in rows))
    methods = list(dict.fromkeys(r['method'] for r in rows))
    markers = 'osD^v<>phX*+'
    figure, axes = plt.subplots(2, 3, figsize=(15, 9), sharex=True, sharey=True)
    for ax, scene in zip(axes.flat, scenes_):
        for i, method in enumerate(methods):
            for r in rows:
                if r['scene'] == scene and r['method'] == method and r['samples']:
                    ax.loglog(r['seconds_per_sample'], max(r['max_relative_error'], 1e-17),
                              markers[i % len(markers)], color=f'C{i % 10}', label=method,
                              markersize=8)
        ax.set_title(scene)
        ax.grid(True, which='both', alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel('time per sample (s)')
    for ax in axes[:, 0]:
        ax.set_ylabel('largest relative error vs 40-digit reference')
    handles, labels = axes.flat[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='lower center', ncol=6)
    figure.suptitle('Loads of a layout: error against cost, per method and scene '
                    '(errors below 1e-17 drawn at 1e-17)')
    figure.tight_layout(rect=(0, 0.07, 1, 0.96))
    figure.savefig(png_path, dpi=80)
