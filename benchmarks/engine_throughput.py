"""
Samples per second of the vectorised engine, for few and for many components.

Prints, for N = 10 and N = 100000 components, the time to aggregate the
layout (once) and the samples/s of :func:`cvc_balance.physics.engine.loads` over a
block of motion samples (best of several repeats), and the ratio of the
per-sample costs. Run: ./dev.sh run python benchmarks/engine_throughput.py
"""

import argparse
import math
import time

import numpy as np

from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.layout import parse_layout


def layout_with(n, rng):
    """Make a layout of n components: boxes, cylinders and points at random places."""
    shapes = [{'type': 'box', 'size': [0.1, 0.2, 0.1]},
              {'type': 'cylinder', 'radius': 0.05, 'length': 0.2, 'axis': 'radial'},
              {'type': 'point'}]
    components = [{'name': f'c{i}', 'mass': float(rng.uniform(0.1, 50.0)),
                   'radius': float(rng.uniform(0.0, 0.8)),
                   'angle': float(rng.uniform(0.0, 2 * math.pi)),
                   'z': float(rng.uniform(-0.3, 0.3)), 'shape': shapes[i % 3]}
                  for i in range(n)]
    return parse_layout({'name': f'bench_{n}', 'components': components,
                         'supports': [{'name': 'front', 'z': -0.25},
                                      {'name': 'rear', 'z': 0.25, 'axial': True}],
                         'gravity': [0.0, -9.80665 * math.cos(0.3), 9.80665 * math.sin(0.3)]})


def samples_per_second(model, samples, repeats):
    """Best-of-``repeats`` samples/s of the vectorised loads over ``samples`` samples."""
    rng = np.random.default_rng(1)
    q = rng.uniform(0.0, 2 * math.pi, samples)
    omega = rng.uniform(20.0, 25.0, samples)
    alpha = rng.uniform(-2.0, 2.0, samples)
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        loads(model, q, omega, alpha)
        best = min(best, time.perf_counter() - start)
    return samples / best


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=2_000_000)
    parser.add_argument('--repeats', type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rates = {}
    for n in (10, 100_000):
        layout = layout_with(n, rng)
        start = time.perf_counter()
        model = RotorModel.from_layout(layout)
        aggregate = time.perf_counter() - start
        rates[n] = samples_per_second(model, args.samples, args.repeats)
        print(f'N = {n:>6} components: aggregate once {aggregate * 1e3:8.2f} ms; '
              f'{rates[n] / 1e6:6.2f} M samples/s ({1e9 / rates[n]:.1f} ns/sample, '
              f'{args.samples} samples, best of {args.repeats})')
    print(f'per-sample cost ratio N=100000 / N=10: {rates[10] / rates[100_000]:.3f}')


if __name__ == '__main__':
    main()
