"""
Field balancing: what the steps cost, and what the mixed-integer plans find on a full kit.

1. Reading a run (bags/field_baseline.mcap: 1x of four cell channels over 22 revolutions)
   and calibrating from the three bundled runs.
2. The plans on the bundled gantry's kit (24 sites x 4 sizes x up to 3 a site, per plane):
   the fewest weights within G 6.3 (identified unbalance; coefficients); the smallest
   residual with at most 2-5 weights by the pruned enumeration (field/search.py, the
   default), against HiGHS at time limits of 3, 10 and 30 s (its continuous relaxation is
   the continuous optimum: the bound stays weak, HiGHS stops at the limit); with --long,
   HiGHS given 1500 s to prove the 4-weight optimum.
3. A small kit, the plan against enumerating every loading (the test's brute force).

Best of a few runs each. Run: ./dev.sh run python benchmarks/field_plan.py [--quick]
"""

import argparse
import itertools
import math
from pathlib import Path
import time

import numpy as np

from cvc_balance.bag.field_run import calibrate_runs, correct_run, read_run
from cvc_balance.field import BalancingProblem, optimal_plan, Trial
from cvc_balance.physics.layout import WeightSites

BAGS = Path(__file__).resolve().parents[1] / 'bags'
RUNS = [BAGS / f'field_{r}.mcap' for r in ('baseline', 'trial_I', 'trial_II')]


def best_of(repeats, call):
    """Return (best seconds, last result) of ``repeats`` calls."""
    best, result = math.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        result = call()
        best = min(best, time.perf_counter() - start)
    return best, result


def main():
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer repeats, no 30 s run')
    parser.add_argument('--long', action='store_true', help='HiGHS until it proves the '
                        '4-weight optimum (about a minute or two)')
    args = parser.parse_args()
    repeats = 1 if args.quick else 3
    seconds, _ = best_of(repeats, lambda: read_run(RUNS[0]))
    print(f'read one run (4 channels, 1x over 22 revolutions): {seconds * 1e3:.0f} ms')
    trials = [Trial('I', 0.2, 0.0, 0.68), Trial('II', 0.2, 0.0, 0.68)]
    seconds, (calibration, _, _) = best_of(
        repeats, lambda: calibrate_runs(RUNS[0], RUNS[1:], trials))
    print(f'calibrate from three runs: {seconds * 1e3:.0f} ms')

    identified = correct_run(RUNS[0], time_limit=60.0)
    print('\nplans on the gantry kit (192 integer variables):')
    seconds, plan = best_of(repeats, lambda: optimal_plan(
        identified.problem, identified.sites, 'fewest', time_limit=60.0))
    print(f'  fewest within G 6.3, identified unbalance: {plan.count} weights, {plan.status}, '
          f'{seconds:.2f} s')
    record = {'speed': None, 'correction_unit': 'kg m'}
    by_coefficients = correct_run(RUNS[0], calibration, record, time_limit=60.0)
    seconds, plan = best_of(repeats, lambda: optimal_plan(
        by_coefficients.problem, by_coefficients.sites, 'fewest', time_limit=60.0))
    print(f'  fewest within G 6.3, coefficients: {plan.count} weights, {plan.status}, '
          f'{seconds:.2f} s')
    continuous = by_coefficients.plans[0].residual.rms
    for most in (2, 3, 4, 5):
        seconds, plan = best_of(repeats, lambda: optimal_plan(
            by_coefficients.problem, by_coefficients.sites, 'residual', most, method='search'))
        print(f'  smallest residual, <= {most} weights, pruned enumeration: rms '
              f'{plan.residual.rms:.3g} (continuous {continuous:.3g}), proven optimal, '
              f'{seconds:.2f} s')
    for limit in ((3.0, 10.0) if args.quick else (3.0, 10.0, 30.0)) + \
            ((1500.0,) if args.long else ()):
        start = time.perf_counter()
        plan = optimal_plan(by_coefficients.problem, by_coefficients.sites, 'residual', 4,
                            time_limit=limit, method='milp')
        print(f'  smallest residual, <= 4 weights, time limit {limit:g} s: rms '
              f'{plan.residual.rms:.3g} (continuous {continuous:.3g}), {plan.status}, gap '
              f'{plan.gap:.0%}, {time.perf_counter() - start:.1f} s')

    rng = np.random.default_rng(1)
    sites = {'I': WeightSites('I', tuple(np.radians([0, 60, 150, 240])), 0.5, (0.1, 0.25), 1),
             'II': WeightSites('II', tuple(np.radians([30, 120, 200, 300])), 0.6,
                               (0.1, 0.25), 1)}
    alpha = rng.normal(size=(3, 2)) + 1j * rng.normal(size=(3, 2))
    problem = BalancingProblem(('I', 'II'), ('a', 'b', 'c'),
                               0.3 * (rng.normal(size=3) + 1j * rng.normal(size=3)), alpha,
                               np.ones(3))
    seconds, plan = best_of(repeats, lambda: optimal_plan(problem, sites, 'residual'))

    def enumerate_all():
        options = []
        for plane in ('I', 'II'):
            s = sites[plane]
            options.append([sum(([0.0] + list(s.masses))[c] * s.radius * np.exp(1j * a)
                                for c, a in zip(choice, s.angles))
                            for choice in itertools.product(range(3), repeat=4)])
        return min(float(np.sum(np.abs(problem.residual(np.array(u)))))
                   for u in itertools.product(*options))
    brute_seconds, best = best_of(repeats, enumerate_all)
    print(f'\nsmall kit (2 planes x 4 sites x 2 sizes, 6561 loadings): plan {seconds:.2f} s '
          f'(sum |r| {plan.residual.total:.6g}), enumeration {brute_seconds:.2f} s '
          f'({best:.6g})')


if __name__ == '__main__':
    main()
