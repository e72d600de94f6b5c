"""
What a reduced model saves: per sample, once per layout, and the cost of deciding.

Prints best-of-N wall times (a shared machine: the best is the least disturbed) for the
gantry-like scene of test_model_choice.py: the vectorised engine per sample with the
planar point-mass model against the full one (2^18 samples), aggregating 20000
components as point masses (choose_model, deciding included) against the full model,
and the ratios. Run: ./dev.sh run python benchmarks/model_choice_cost.py
"""

import argparse
import math
from pathlib import Path
import sys
import time

import numpy as np

from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.model_choice import choose_model, Envelope, Tolerance

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
from reference import random_layout  # noqa: E402  (the tests' random layouts)
from test_model_choice import gantry  # noqa: E402  (the tests' ten-component gantry)


def best_time(call, repeat):
    """Return the best wall time (s) of ``repeat`` calls."""
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - start)
    return best


def main():
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--repeat', type=int, default=9, help='timings per figure (best)')
    args = parser.parse_args()
    envelope = Envelope(omega_max=25.0, alpha_max=4.0)
    layout = gantry()
    choice = choose_model(layout, Tolerance(1.0, 1.0), envelope)
    full = RotorModel.from_layout(layout)
    rng = np.random.default_rng(3)
    n = 1 << 18
    q, omega, alpha = rng.uniform(0, 6, n), rng.uniform(0, 25, n), rng.uniform(-4, 4, n)
    reduced_s = best_time(lambda: loads(choice.model, q, omega, alpha), args.repeat)
    full_s = best_time(lambda: loads(full, q, omega, alpha), args.repeat)
    print(f'per sample ({n} samples): {choice.name} {reduced_s / n * 1e9:.1f} ns, '
          f'full {full_s / n * 1e9:.1f} ns, ratio {reduced_s / full_s:.3f}')
    big = parse_layout(random_layout(np.random.default_rng(4), n=20000, supports=2,
                                     tilt=False))
    chosen_s = best_time(lambda: choose_model(big, Tolerance(1e9, 1e9), envelope),
                         max(3, args.repeat // 2))
    full_once = best_time(lambda: RotorModel.from_layout(big), max(3, args.repeat // 2))
    print(f'once (20000 components): choose + point masses {chosen_s * 1e3:.1f} ms, '
          f'full {full_once * 1e3:.1f} ms, ratio {chosen_s / full_once:.3f}')
    decide_full = best_time(lambda: choose_model(big, Tolerance(0.0, 0.0, 0.0), envelope),
                            max(3, args.repeat // 2))
    print(f'deciding, then the full model: {decide_full * 1e3:.1f} ms, '
          f'ratio to building it directly {decide_full / full_once:.3f}')


if __name__ == '__main__':
    main()
