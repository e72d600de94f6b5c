"""
``cvc-balance bench``: every method's error against its cost, scene by scene.

For each scene (planar, axial offsets, tilt, spin-up, near-balance, 10^5 components)
every method of :mod:`cvc_balance.study.methods` computes the loads over motion samples; its
cost is the best wall time per sample of three runs or more (:data:`TIMED`), its error the
largest relative deviation from the 40-digit reference (:mod:`cvc_balance.study.exact`)
over the samples (each output scaled by the reference's largest value of it). Writes a CSV
and a log-log chart (error against time per sample, one mark per method per scene) and
prints the table.

Two runs: the full one (every scene's samples; costly methods on fewer, WORK_LIMIT) and the
quick one (the same methods and scenes; costly methods on fewer still,
:data:`QUICK_SAMPLES`; the best of three runs, or of fewer that took over a second). A
scene's reference depends on its layout only (five unit-motion wrenches,
:func:`~cvc_balance.study.exact.basis_wrenches`): the full run computes them and stores
them (:data:`REFERENCES`, keyed by a digest of the layout), and the quick run reads them
from there (the 10^5-component scene's take 1.5 minutes). :func:`compare` says whether a
quick run draws the full run's conclusions.
"""

import csv
import hashlib
import json
import math
from pathlib import Path
import time

import mpmath as mp
import numpy as np

from cvc_balance.physics.frames import STANDARD_GRAVITY
from cvc_balance.physics.layout import parse_layout
from cvc_balance.study.exact import basis_wrenches, BASIS, DIGITS, loads_from_basis
from cvc_balance.study.methods import METHODS

WORK_LIMIT = 3e7      # body- or particle-samples a method may be given per run
QUICK_SHARE = 8
QUICK_SAMPLES = 32
"""
The quick run gives a method WORK_LIMIT / QUICK_SHARE body-samples, but at least
QUICK_SAMPLES samples (or the full run's, if fewer): a time per sample over fewer samples
counts the fixed costs of a call (per particle, per call) more, and would rank methods
otherwise. Cheap methods keep every sample; only the costly ones run on fewer.
"""
TIMED = 0.05
"""
Seconds a method is run for at least (three runs at least): the best run of a cheap method
(80 us) out of hundreds, as one whose caches another process emptied or that was
descheduled is not its cost (best of three moved such a method 5x on this shared machine).
"""
REFERENCES = Path(__file__).with_name('bench_references.json')
"""The scenes' 40-digit unit-motion wrenches, by layout digest (written by the full run)."""
SPEED_GAP = 2.0
"""Two methods whose full-run times differ by more than this are ranked by speed."""
ACCURACY_GAP = 10.0
"""Two methods whose full-run errors differ by more than this are ranked by accuracy."""


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


def scenes(rng, large=True):
    """
    Return {name: (layout, q, omega, alpha, gravity)} of the bench's scenes.

    ``large``: with the 10^5-component scene (drawn last: the others do not depend on it).
    """
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
    every = {
        'planar': (planar, q, steady, np.zeros(n), g),
        'axial offsets': (offsets, q, steady, np.zeros(n), g),
        'tilt': (layout(12, (-0.3, 0.3), ('box', 'cylinder', 'point'), tilted), q, steady,
                 np.zeros(n), tilted),
        'spin-up': (offsets, q, np.linspace(0.0, 23.27, n), np.full(n, 6.0), g),
        'near-balance': (near, q, steady, np.zeros(n), (0.0, 0.0, 0.0)),
    }
    if large:
        every['1e5 components'] = (layout(100_000, (-0.3, 0.3), ('box', 'cylinder', 'point')),
                                   q[:64], steady[:64], np.zeros(64), g)
    return every


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


def layout_digest(layout):
    """Return a digest (sha256, hex) of what a reference depends on: the components."""
    return hashlib.sha256(repr(tuple(layout.components)).encode()).hexdigest()


def stored_references(path=REFERENCES):
    """Return {layout digest: basis (as basis_wrenches returns it)} stored at ``path``."""
    try:
        stored = json.loads(Path(path).read_text(encoding='utf-8'))
    except FileNotFoundError:
        return {}
    with mp.workdps(DIGITS):
        return {digest: [([mp.mpf(v) for v in wrench['force']],
                          [mp.mpf(v) for v in wrench['moment']], mp.mpf(wrench['torque']))
                         for wrench in (entry['basis'][name] for name in BASIS)]
                for digest, entry in stored['layouts'].items()}


def store_references(references, path=REFERENCES):
    """Write {digest: ([scenes], basis)} to ``path`` (50 significant digits: exact at 40)."""
    def text(value):
        return mp.nstr(value, 50, strip_zeros=False)
    layouts = {digest: {'scenes': scenes_, 'basis': {
        name: {'force': [text(v) for v in force], 'moment': [text(v) for v in moment],
               'torque': text(torque)}
        for name, (force, moment, torque) in zip(BASIS, basis)}}
        for digest, (scenes_, basis) in references.items()}
    Path(path).write_text(json.dumps({'digits': DIGITS, 'layouts': layouts}, indent=1) + '\n',
                          encoding='utf-8')


def run(csv_path, png_path, seed=0, print_table=print, full=False, only=None,
        references=REFERENCES):
    """
    Run every method on every scene; write the CSV and the chart; return the rows.

    ``full``: the full run (the references computed, and stored in ``references`` when
    they are not there yet); else the quick run (:data:`QUICK_SAMPLES`), the references
    read from ``references`` (computed when missing). ``only``: names of the scenes to run
    (default all); ``png_path`` None: no chart.
    """
    rng = np.random.default_rng(seed)
    rows = []
    stored = stored_references(references)
    computed = {}
    large = only is None or '1e5 components' in only
    for scene, (layout, q, omega, alpha, gravity) in scenes(rng, large).items():
        if only is not None and scene not in only:
            continue
        digest = layout_digest(layout)
        basis = None if full else stored.get(digest)
        if basis is None:
            if not full:
                print_table(f'{scene}: no stored reference for its layout, computing it '
                            '(cvc-balance bench --full stores it)')
            basis = computed[digest][1] if digest in computed else basis_wrenches(layout)
            computed.setdefault(digest, ([], basis))[0].append(scene)
        reference = loads_from_basis(basis, q, omega, alpha, gravity)
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
            if not full:
                samples = min(samples, max(QUICK_SAMPLES,
                                           int(WORK_LIMIT / QUICK_SHARE // bodies)))
            part = slice(0, samples)
            state = prepare(layout)
            best, spent, runs = math.inf, 0.0, 0
            while runs < 3 or spent < TIMED:
                start = time.perf_counter()
                result = compute(state, q[part], omega[part], alpha[part], gravity)
                best = min(best, time.perf_counter() - start)
                spent += time.perf_counter() - start
                runs += 1
                if not full and spent > 1.0:     # long enough to time once
                    break
            error = max(_relative(got, ref[part]) for got, ref in zip(result, reference))
            rows.append({'scene': scene, 'method': name, 'samples': samples,
                         'seconds_per_sample': best / samples, 'max_relative_error': error,
                         'note': ''})
            print_table(f'{scene:16} {name:18} {best / samples:10.3e} s/sample   '
                        f'error {error:9.2e}')
    with open(csv_path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    if png_path is not None:
        _chart(rows, png_path, run_title(full))
    if full and only is None and any(stored.get(d) != b for d, (_, b) in computed.items()):
        store_references(computed, references)
        print_table(f'references of the {len(computed)} layouts stored in {references}')
    return rows


def run_title(full):
    """Return what the chart's title says of the run."""
    if full:
        return 'full run (cvc-balance bench --full): every sample, costly methods on fewer'
    return (f'quick run: costly methods on 1/{QUICK_SHARE} of the full run\'s work, at least '
            f'{QUICK_SAMPLES} samples (cvc-balance bench --full for the full run)')


def read_rows(path):
    """Return the rows of a bench CSV (numbers as numbers)."""
    rows = []
    with open(path, newline='') as stream:
        for row in csv.DictReader(stream):
            row['samples'] = int(row['samples'])
            if row['samples']:
                row['seconds_per_sample'] = float(row['seconds_per_sample'])
                row['max_relative_error'] = float(row['max_relative_error'])
            rows.append(row)
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


def clearly_beaten(rows, scene):
    """
    Methods of a scene another method nearly beats: better in one beyond the noise.

    Another is more than :data:`SPEED_GAP` times faster and at most :data:`ACCURACY_GAP`
    times less accurate, or more than ACCURACY_GAP times more accurate and at most
    SPEED_GAP times slower.
    """
    done = [r for r in rows if r['scene'] == scene and r['samples']]

    def beats(o, r):
        time, error = o['seconds_per_sample'], o['max_relative_error']
        return (time * SPEED_GAP < r['seconds_per_sample'] and
                error <= r['max_relative_error'] * ACCURACY_GAP) or \
            (error * ACCURACY_GAP < r['max_relative_error'] and
             time <= r['seconds_per_sample'] * SPEED_GAP)
    return {r['method'] for r in done if any(beats(o, r) for o in done)}


def dominated(rows, scene):
    """Methods of a scene another method beats in both time and error, clearly in one."""
    done = [r for r in rows if r['scene'] == scene and r['samples']]

    def beats(o, r):
        time, error = o['seconds_per_sample'], o['max_relative_error']
        return time <= r['seconds_per_sample'] and error <= r['max_relative_error'] and (
            time * SPEED_GAP < r['seconds_per_sample'] or
            error * ACCURACY_GAP < r['max_relative_error'])
    return {r['method'] for r in done if any(beats(o, r) for o in done)}


def ranked_pairs(rows, scene, column, gap):
    """Pairs (a, b) of a scene's methods where ``column`` of b exceeds a's ``gap`` times."""
    done = [r for r in rows if r['scene'] == scene and r['samples']]
    return {(a['method'], b['method']) for a in done for b in done
            if b[column] > gap * a[column]}


def compare(quick, full):
    """
    Return the ways the ``quick`` rows' conclusions differ from the ``full`` rows' ([] if none).

    Per scene: the methods run (and skipped); the Pareto front: no method on one run's front
    and not even nearly beaten there (:func:`clearly_beaten`) is dominated in the other's
    (:func:`dominated`); and the order of every two
    methods the full run sets more than :data:`SPEED_GAP` apart in time or
    :data:`ACCURACY_GAP` apart in error (closer ones are ties, whose order timing noise
    or rounding may swap), the fastest and the most accurate among them.
    """
    differences = []
    for scene in dict.fromkeys(r['scene'] for r in full):
        run = {kind: sorted(r['method'] for r in rows if r['scene'] == scene and r['samples'])
               for kind, rows in (('quick', quick), ('full', full))}
        if run['quick'] != run['full']:
            differences.append(f'{scene}: methods run {run["quick"]}, the full run '
                               f'{run["full"]}')
            continue
        for on, off, rows, other in (('quick', 'full', quick, full),
                                     ('full', 'quick', full, quick)):
            # Fronts to the noise: a method on one, not even nearly beaten there, is not
            # dominated in the other.
            front = set(pareto_front(rows, scene)) - clearly_beaten(rows, scene)
            for method in sorted(front & dominated(other, scene)):
                differences.append(f'{scene}: {method} on the Pareto front of the {on} run, '
                                   f'dominated in the {off} run')
        for column, gap, how in (('seconds_per_sample', SPEED_GAP, 'faster'),
                                 ('max_relative_error', ACCURACY_GAP, 'more accurate')):
            wanted = ranked_pairs(full, scene, column, gap)
            for a, b in sorted(wanted - ranked_pairs(quick, scene, column, 1.0)):
                differences.append(f'{scene}: {a} not {how} than {b}, as the full run has it')
    return differences


def _chart(rows, png_path, title=''):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    scenes_ = list(dict.fromkeys(r['scene'] for r in rows))
    methods = list(dict.fromkeys(r['method'] for r in rows))
    markers = 'osD^v<>phX*+'
    figure, axes = plt.subplots(2, 3, figsize=(15, 9), sharex=True, sharey=True,
                                squeeze=False)
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
                    f'(errors below 1e-17 drawn at 1e-17)\n{title}')
    figure.subplots_adjust(left=0.06, right=0.98, bottom=0.14, top=0.9, wspace=0.08,
                           hspace=0.15)
    figure.savefig(png_path, dpi=80)
