"""
Bearing life's cost: per sample in the node, and per sample offline.

1. Node: :meth:`LifeCounters.add_sample` for the two bearings of
   config/ct_gantry_bearings.yaml (a plain ball row and one with ISO 281's e switch), on
   the support forces the node's ``sample_loads`` gives, us per sample; beside it
   ``sample_loads`` itself (what the node already spends on a sample). Target: < 1 us.
2. Offline: :meth:`LifeCounters.add` over blocks of 16384 samples (replay's) of the same
   two bearings, the loads already computed; and with the balanced rotor's loads as
   replay computes them (a second ``loads`` call and a second count). Target: >= 1 M
   samples/s.

Best of ``--repeats`` runs (the machine is shared: the best is the cost, the rest is
other work). Run: ./dev.sh run python benchmarks/bearing_life.py [--samples N]
"""

import argparse
import math
from pathlib import Path
import time

import numpy as np

from cvc_balance.physics.bearing_life import balanced, LifeCounters
from cvc_balance.physics.engine import loads, RotorModel, sample_loads
from cvc_balance.physics.layout_file import load_layout

ROOT = Path(__file__).resolve().parents[1]
BLOCK = 1 << 14
"""Samples per block, as replay computes them."""


def best(function, repeats):
    """Return the least time (s) of ``repeats`` calls of ``function``."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    """Print the costs."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--samples', type=int, default=1_000_000,
                        help='samples offline (the node: a fifth of them)')
    parser.add_argument('--repeats', type=int, default=7)
    args = parser.parse_args()
    model = RotorModel.from_layout(load_layout(ROOT / 'config' / 'ct_gantry_bearings.yaml'))
    omega = 23.27
    n = args.samples
    time_s = np.arange(n) * 1e-3
    angle = np.remainder(omega * time_s, 2 * math.pi)
    speed = np.full(n, omega)

    # 1. The node: one sample at a time, plain floats.
    live = n // 5
    samples = [(float(t), float(q), sample_loads(model, float(q), omega).supports)
               for t, q in zip(time_s[:live], angle[:live])]

    def count_live():
        counters = LifeCounters(model.supports)
        add = counters.add_sample
        for t, q, supports in samples:
            add(t, q, omega, supports)

    def engine_live():
        for t, q, _ in samples:
            sample_loads(model, q, omega)

    per_sample = best(count_live, args.repeats) / live
    engine = best(engine_live, max(args.repeats // 2, 1)) / live
    print(f'node: life of 2 bearings {per_sample * 1e6:.3f} us per sample (target < 1 us); '
          f'sample_loads {engine * 1e6:.2f} us per sample (life / sample_loads '
          f'{per_sample / engine:.2f}: the same on a faster or quieter machine)')

    # 2. Offline: blocks of loads already computed, as replay counts them.
    blocks = [(slice(a, min(a + BLOCK, n)),) for a in range(0, n, BLOCK)]
    results = [loads(model, angle[part], speed[part]).support_force for part, in blocks]
    quiet = balanced(model)

    def count_blocks():
        counters = LifeCounters(model.supports)
        for (part,), forces in zip(blocks, results):
            counters.add(time_s[part], angle[part], speed[part], forces)

    def count_with_balanced():
        counters, balanced_counters = LifeCounters(model.supports), LifeCounters(model.supports)
        for (part,), forces in zip(blocks, results):
            counters.add(time_s[part], angle[part], speed[part], forces)
            balanced_counters.add(time_s[part], angle[part], speed[part],
                                  loads(quiet, angle[part], speed[part]).support_force)

    offline = best(count_blocks, args.repeats)
    both = best(count_with_balanced, max(args.repeats // 2, 1))
    print(f'offline: life of 2 bearings {n / offline / 1e6:.2f} M samples/s (target >= 1); '
          f'with the balanced rotor (its loads and count, as replay) {n / both / 1e6:.2f} M '
          'samples/s')


if __name__ == '__main__':
    main()
