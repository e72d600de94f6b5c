"""
Exact aggregation of a layout: time per layout size, before and after, and cos/sin error.

Prints, for 10, 10^3, 10^5 and 10^6 components (point masses; bodies of the parametric
shapes; bodies of given inertia tensors with products of inertia), the
time of :func:`cvc_balance.physics.inertia.place` (the layout reduced to its exact
aggregates, double-double), best of several runs, wall-clock and CPU time of all
threads; the same for the code at a git revision ("before", in a child process on the
same arrays); the largest error of :func:`cvc_balance.physics.compensated.cos_sin`
against 60-digit mpmath over random and hard angles, before and after; and with
``--instructions``, the instructions per component counted by valgrind's callgrind,
which do not change with the machine's load.

    ./dev.sh run python benchmarks/aggregation.py [--before REV] [--instructions]
"""

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

SIZES = (10, 1_000, 100_000, 1_000_000)
KINDS = ('points', 'shapes', 'tensors')
HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DEFAULT_BEFORE = '49574c3'           # the last commit with the Taylor-series double-double


def layout_arrays(n, kind, seed=0):
    """
    Masses, own tensors (or None), radii, angles and z of n random components.

    ``kind``: 'points'; 'shapes', the parametric shapes in turn (box, solid cylinder
    along each axis, tube, sphere, point: own tensors diagonal in the own frame);
    'tensors', given inertia tensors with products of inertia (a box turned in its
    own frame), the most work.
    """
    rng = np.random.default_rng(seed)
    mass = rng.uniform(0.1, 60.0, n)
    radius = rng.uniform(0.0, 0.8, n)
    angle = rng.uniform(0.0, 2 * math.pi, n)
    z = rng.uniform(-0.3, 0.3, n)
    if kind == 'points':
        return mass, None, radius, angle, z
    a, b, c = (rng.uniform(0.02, 0.4, n) for _ in range(3))
    own = np.zeros((n, 3, 3))
    if kind == 'tensors':
        size = np.stack([a, b, c], 1)
        box = mass[:, None] * (size.sum(1, keepdims=True) ** 2 - size ** 2) / 12
        turn = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
        return mass, np.einsum('nij,nj,nkj->nik', turn, box, turn), radius, angle, z
    kind_of = np.arange(n) % 6
    along, across = 0.5 * mass * a ** 2, mass * (3 * a ** 2 + b ** 2) / 12
    for k in range(3):                               # cylinders along x, y, z
        take = kind_of == k
        own[take] = np.eye(3) * across[take, None, None]
        own[take, k, k] = along[take]
    take = kind_of == 3                              # boxes
    own[take, 0, 0] = mass[take] * (b[take] ** 2 + c[take] ** 2) / 12
    own[take, 1, 1] = mass[take] * (a[take] ** 2 + c[take] ** 2) / 12
    own[take, 2, 2] = mass[take] * (a[take] ** 2 + b[take] ** 2) / 12
    take = kind_of == 4                              # tubes along z
    own[take] = np.eye(3) * (mass[take] * (3 * (a[take] ** 2 + b[take] ** 2) + c[take] ** 2)
                             / 12)[:, None, None]
    own[take, 2, 2] = 0.5 * mass[take] * (a[take] ** 2 + b[take] ** 2)
    take = kind_of == 5                              # spheres
    own[take] = np.eye(3) * (0.4 * mass[take] * a[take] ** 2)[:, None, None]
    return mass, own, radius, angle, z


def hard_and_random_angles(count):
    """Angles for the cos/sin error: random at every scale, and the hard cases."""
    rng = np.random.default_rng(1)
    step = math.pi / 8192
    k, j = np.arange(-40, 41), np.arange(-200, 201)
    hard = np.concatenate([k * math.pi / 2, j * step, (j + 0.5) * step,
                           [0.0, 5e-324, 1e-300, 402.1, 2.0 ** 31, 1e9, 1e12, 1e18, 1e300,
                            6381956970095103 * 2.0 ** 797]])
    hard = np.concatenate([hard, np.nextafter(hard, np.inf), np.nextafter(hard, -np.inf)])
    quarter = count // 4
    return np.concatenate([hard, rng.uniform(-7, 7, quarter), rng.uniform(-402, 402, quarter),
                           rng.uniform(-1e9, 1e9, quarter),
                           10.0 ** rng.uniform(-12, 9, quarter) * rng.choice([-1, 1], quarter)])


def cos_sin_error(angles):
    """
    Largest |error| of cos_sin (cos and sin, hi + lo) against mpmath at 60 digits.

    Returns (over |angle| <= 1e9, over all angles): the layouts' bound, and beyond.
    """
    import mpmath as mp
    from cvc_balance.physics.compensated import cos_sin
    (c, c_lo), (s, s_lo) = cos_sin(angles)
    worst = [0.0, 0.0]
    with mp.workdps(60):
        for k, angle in enumerate(angles):
            x = mp.mpf(float(angle))
            error = max(abs(mp.mpf(float(c[k])) + mp.mpf(float(c_lo[k])) - mp.cos(x)),
                        abs(mp.mpf(float(s[k])) + mp.mpf(float(s_lo[k])) - mp.sin(x)))
            worst[1] = max(worst[1], float(error))
            if abs(angle) <= 1e9:
                worst[0] = max(worst[0], float(error))
    return worst


def best_times(call, repeats):
    """Best wall-clock and best CPU time (all threads) of ``repeats`` calls, s."""
    wall = cpu = math.inf
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        call()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return wall, cpu


def repeats_for(n, slow):
    """More repeats for the short runs: the machine's noise is in milliseconds."""
    if n >= 1_000_000:
        return 3 if slow else 7
    return 5 if slow and n >= 100_000 else 9


def measure(sizes, kinds, angles, slow):
    """Measure this process's place() timings and cos/sin error: a dict."""
    from cvc_balance.physics import inertia
    place = inertia.place
    result = {'times': {}, 'cos_sin_error': cos_sin_error(angles), 'source': inertia.__file__}
    place(*layout_arrays(100, 'shapes'))             # tables, threads: made once
    for kind in kinds:
        for n in sizes:
            arrays = layout_arrays(n, kind)
            result['times'][f'{kind} {n}'] = best_times(lambda: place(*arrays),
                                                        repeats_for(n, slow))
    return result


def block_time(kind, repeats=300):
    """
    Best time of one block of the kernel (single thread), s per component.

    On a shared machine the best of many ~2 ms runs is one that nobody interrupted:
    times 10^6, what one idle core takes for 10^6 components.
    """
    from cvc_balance.physics import compensated, inertia
    n = compensated.BLOCK
    mass, own, radius, angle, z = layout_arrays(64 * n, kind)
    arrays = [mass, radius, angle, z]
    bounds = inertia._bounds(mass.max(), radius.max(), np.abs(z).max())
    best = math.inf
    for k in range(repeats):
        block = [((k % 64) * n, (k % 64 + 1) * n)]
        start = time.perf_counter()
        inertia._place_blocks(block, arrays, own, bounds, True)
        best = min(best, time.perf_counter() - start)
    return best / n


def measure_before(revision, sizes, kinds, angles):
    """Measure the same on the code at ``revision``, in a child process."""
    with tempfile.TemporaryDirectory() as folder:
        archive = subprocess.run(['git', '-C', ROOT, 'archive', revision, 'cvc_balance'],
                                 check=True, capture_output=True).stdout
        subprocess.run(['tar', '-x', '-C', folder], input=archive, check=True)
        np.save(os.path.join(folder, 'angles.npy'), angles)
        env = dict(os.environ, PYTHONPATH=folder)
        out = subprocess.run([sys.executable, __file__, '--worker', folder,
                              '--sizes', *map(str, sizes), '--kinds', *kinds],
                             check=True, capture_output=True, text=True, env=env).stdout
    return json.loads(out)


def instructions(source, n, kind):
    """Instructions of place() on n components, by callgrind (setup run subtracted)."""
    python = os.path.realpath(sys.executable)    # valgrind fails on the venv's symlink
    site = [p for p in sys.path if p.endswith('site-packages')]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([source, *site]),
               OPENBLAS_NUM_THREADS='1')
    counts = []
    for run in ('0', '1'):
        with tempfile.NamedTemporaryFile() as out:
            log = subprocess.run(
                ['valgrind', '--tool=callgrind', f'--callgrind-out-file={out.name}', python,
                 __file__, '--count', str(n), kind, run], env=env, capture_output=True,
                text=True).stderr
        refs = [line for line in log.splitlines() if 'refs:' in line]
        if not refs:
            return None
        counts.append(int(refs[-1].split()[-1].replace(',', '')))
    return (counts[1] - counts[0]) / n


def count_run(n, kind, run):
    """Run the child under callgrind: make the arrays, aggregate 100 (and n if ``run``)."""
    from cvc_balance.physics.inertia import place
    arrays = layout_arrays(n, kind)
    place(*layout_arrays(100, kind))
    if run == '1':
        place(*arrays)


def milliseconds(times):
    wall, cpu = times
    return f'{wall * 1e3:9.2f} ms ({cpu * 1e3:8.2f})'


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--before', default=DEFAULT_BEFORE,
                        help='git revision to compare with (default %(default)s); '
                             "'none' to skip")
    parser.add_argument('--sizes', type=int, nargs='+', default=list(SIZES))
    parser.add_argument('--kinds', nargs='+', default=list(KINDS), choices=KINDS)
    parser.add_argument('--angles', type=int, default=20_000,
                        help='random angles for the cos/sin error (plus ~1900 hard ones)')
    parser.add_argument('--instructions', action='store_true',
                        help='also count instructions with callgrind (10^5 components; '
                             'a few minutes)')
    parser.add_argument('--worker', help=argparse.SUPPRESS)
    parser.add_argument('--count', nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.count:
        count_run(int(args.count[0]), args.count[1], args.count[2])
        return
    if args.worker:
        angles = np.load(os.path.join(args.worker, 'angles.npy'))
        print(json.dumps(measure(args.sizes, args.kinds, angles, slow=True)))
        return
    angles = hard_and_random_angles(args.angles)
    load = os.getloadavg()[0]
    after = measure(args.sizes, args.kinds, angles, slow=False)
    before = None
    if args.before != 'none':
        before = measure_before(args.before, args.sizes, args.kinds, angles)
    print(f'Exact aggregation, place(): best wall-clock time (best CPU time of all threads); '
          f'{os.cpu_count()} cores, load average {load:.1f} at the start, '
          f'{os.getloadavg()[0]:.1f} at the end')
    print(f'{"components":>10}  {"kind":6}  {"before " + args.before:>24}  {"after":>24}  '
          f'{"wall ratio":>10}')
    for kind in args.kinds:
        for n in args.sizes:
            key = f'{kind} {n}'
            now = after['times'][key]
            then = before['times'][key] if before else None
            ratio = f'{then[0] / now[0]:9.1f}x' if then else ''
            print(f'{n:>10}  {kind:6}  {milliseconds(then) if then else "":>24}  '
                  f'{milliseconds(now):>24}  {ratio:>10}')
    print('one core, uncontended (best of 300 blocks of the kernel, times 10^6): '
          + ', '.join(f'{kind} {block_time(kind) * 1e9:.0f} ms' for kind in args.kinds)
          + ' for 10^6 components')
    for k, span in enumerate(('|angle| <= 1e9', 'all, to 1.8e308')):
        line = (f'cos/sin against 60-digit mpmath, {angles.size} angles (random at every '
                f'scale and hard cases), {span}: largest |error| after '
                f'{after["cos_sin_error"][k]:.2e}')
        print(line + (f', before {before["cos_sin_error"][k]:.2e}' if before else ''))
    if before:
        print(f'(before: {before["source"]})')
    if args.instructions:
        if not shutil.which('valgrind'):
            print('instructions: valgrind not found')
            return
        for kind in args.kinds:
            now = instructions(ROOT, 100_000, kind)
            line = f'instructions per component (callgrind, 10^5 {kind}): after {now:.0f}'
            if before:
                with tempfile.TemporaryDirectory() as folder:
                    archive = subprocess.run(['git', '-C', ROOT, 'archive', args.before,
                                              'cvc_balance'], check=True,
                                             capture_output=True).stdout
                    subprocess.run(['tar', '-x', '-C', folder], input=archive, check=True)
                    then = instructions(folder, 100_000, kind)
                line += f', before {then:.0f} ({then / now:.1f}x)'
            print(line)


if __name__ == '__main__':
    main()
