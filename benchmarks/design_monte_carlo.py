"""
Monte Carlo of tolerances: 10^6 draws of a 100-component layout (issue 16: about a second).

Every component's mass, radius, angle and z toleranced (400 random deviations a draw),
normal and uniform; the exact (not linearised) first moment and products per draw, as
``cvc-balance tolerance`` computes them. Prints the wall-clock and CPU time of each run
(best and worst of REPEATS), the draws per second, and the load average before the runs:
this machine is shared, so the wall-clock time depends on what else runs.

    ./dev.sh run python benchmarks/design_monte_carlo.py
"""

import os
import time

import numpy as np

from cvc_balance.design.monte_carlo import simulate
from cvc_balance.design.stack import analyse
from cvc_balance.design.tolerances import Tolerances
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout

COMPONENTS = 100
SAMPLES = 1_000_000
REPEATS = 5


def layout_of(count, seed=0):
    """Return a random layout of ``count`` point masses around a rotor, two supports."""
    rng = np.random.default_rng(seed)
    return parse_layout({
        'name': f'benchmark_{count}',
        'components': [{'name': f'c{i}', 'mass': float(rng.uniform(1.0, 50.0)),
                        'radius': float(rng.uniform(0.1, 0.7)),
                        'angle': float(rng.uniform(-np.pi, np.pi)),
                        'z': float(rng.uniform(-0.2, 0.2))} for i in range(count)],
        'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.3, 'axial': True}],
        'balancing': {'grade': 6.3, 'service_speed': 23.27}})


def tolerances_of(layout, normal):
    """Return mass 0.5 %, radius and z 0.5 mm, angle 0.1 deg on every component."""
    mass = layout.placement[0]
    n = len(mass)
    values = np.column_stack([0.005 * mass, np.full(n, 5e-4), np.full(n, np.radians(0.1)),
                              np.full(n, 5e-4)])
    return Tolerances(values, np.full(n, normal))


def timed(function):
    """Return (wall s, CPU s) of one call."""
    wall, cpu = time.perf_counter(), time.process_time()
    function()
    return time.perf_counter() - wall, time.process_time() - cpu


def main():
    """Run the benchmark and print its figures."""
    layout = layout_of(COMPONENTS)
    model = RotorModel.from_layout(layout)
    print(f'{COMPONENTS} components, every mass, radius, angle and z toleranced; '
          f'{SAMPLES} draws; {os.cpu_count()} cores; load average before: '
          f'{", ".join(f"{v:.2f}" for v in os.getloadavg())}')
    for normal in (True, False):
        tolerances = tolerances_of(layout, normal)
        simulate(model, tolerances, 20_000, seed=1)                     # warm up
        runs = [timed(lambda: simulate(model, tolerances, SAMPLES, seed=1))
                for _ in range(REPEATS)]
        walls = sorted(wall for wall, _ in runs)
        cpus = sorted(cpu for _, cpu in runs)
        name = 'normal (3 sigma, truncated)' if normal else 'uniform'
        rate = SAMPLES / walls[0]
        print(f'{name:28} draws: wall {walls[0]:.3f} s best, {walls[-1]:.3f} s worst '
              f'({rate / 1e6:.2f} M draws/s, {rate * COMPONENTS / 1e6:.0f} M component-draws/s);'
              f' CPU {cpus[0]:.3f}-{cpus[-1]:.3f} s')
    tolerances = tolerances_of(layout, True)
    wall, cpu = timed(lambda: analyse(model, tolerances, SAMPLES, seed=1))
    print(f'whole analysis (draws, RSS, worst case, percentiles, probability): wall {wall:.3f} s,'
          f' CPU {cpu:.3f} s')
    print(f'load average after: {", ".join(f"{v:.2f}" for v in os.getloadavg())}')


if __name__ == '__main__':
    main()
