"""
Identification from load cells: accuracy against window and noise, and its cost.

1. Accuracy: the bundled loose-bracket scenario (bags/loose_bracket.yaml: a hidden 0.3 kg
   bracket, cells at 250 Hz) simulated at steady service speed with cell noise 5, 15, 50
   N, fitted over windows of 2-50 revolutions, 30 seeds each: the rms error of the
   identified static unbalance against the hidden truth, beside the fit's own standard
   error (its 95 % radius / sqrt(chi2_2(0.95)), per component, times sqrt 2 for the
   vector). Chart: docs/identify_accuracy.png.
2. Cost: the live fit's time per reading (SlidingFit.reading, plain Python), its motion
   update, and the offline fit's readings/s (vectorised), best of several runs.

Run: ./dev.sh run python benchmarks/identify.py [--quick] [--no-cost]
(``./dev.sh pictures identify_accuracy`` makes the chart with --no-cost.)
"""

import argparse
import math
from pathlib import Path
import tempfile
import time

import numpy as np
import yaml

from cvc_balance.bag.scenario import load_scenario
from cvc_balance.identify import (CellReadings, fit, identified_unbalance, layout_unbalance,
                                  Motion, residual)
from cvc_balance.identify.fit import CHI2_2DOF_95
from cvc_balance.identify.live import SlidingFit
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.motion import acceleration_series

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / 'bags' / 'loose_bracket.yaml'
OMEGA = 23.27


def simulate(revolutions, noise, seed):
    """Return (declared model, Motion, cells, hidden static kg m) of a steady run."""
    spec = yaml.safe_load(SCENARIO.read_text())
    spec['layout'] = str(ROOT / 'config' / 'ct_gantry.yaml')
    spec['profile'] = [{'type': 'spin_up', 'to': OMEGA, 'alpha': 50.0},
                       {'type': 'steady', 'duration': revolutions * 2 * math.pi / OMEGA}]
    spec['events'], spec['seed'] = [], seed
    spec['hidden'] = spec['hidden'][:1]                   # the bracket only
    spec['load_cells']['noise'] = noise
    with tempfile.NamedTemporaryFile('w', suffix='.yaml', delete=False) as stream:
        yaml.safe_dump(spec, stream)
    scenario = load_scenario(stream.name)
    Path(stream.name).unlink()
    t = scenario.time + scenario.start
    angle, omega = scenario.measured()
    motion = Motion(t, angle, omega, acceleration_series(t, omega, 0.1))
    cells = {name: CellReadings(name, stamps * 1e-9, force, torque)
             for name, (stamps, force, torque) in scenario.cell_readings().items()}
    bracket = spec['hidden'][0]['add']
    truth = bracket['mass'] * bracket['radius'] * complex(
        math.cos(math.radians(bracket['angle_deg'])), math.sin(math.radians(bracket['angle_deg'])))
    declared = RotorModel.from_layout(parse_layout(scenario.layouts[0][1]))
    return declared, motion, cells, truth


def accuracy(windows, noises, seeds):
    """Return {noise: [(window, rms error kg m, mean standard error kg m)]}."""
    table = {}
    for noise in noises:
        rows = []
        for window in windows:
            errors, standard = [], []
            for seed in range(seeds):
                declared, motion, cells, truth = simulate(window + 1, noise, seed)
                # The last `window` revolutions: past the spin-up.
                turned = np.abs(np.unwrap(motion.angle) - np.unwrap(motion.angle)[-1])
                keep = turned <= window * 2 * math.pi
                part = Motion(motion.time[keep], motion.angle[keep], motion.omega[keep],
                              motion.alpha[keep])
                estimate, _ = fit(declared, part, {n: c for n, c in cells.items()})
                found = residual(identified_unbalance(declared, estimate),
                                 layout_unbalance(declared)).static
                errors.append(abs(found.value - truth))
                standard.append(found.ci95 / math.sqrt(CHI2_2DOF_95) * math.sqrt(2))
            rows.append((window, math.sqrt(np.mean(np.square(errors))), float(np.mean(standard))))
            print(f'noise {noise:5.1f} N, window {window:3d} rev: rms error '
                  f'{rows[-1][1] * 1e6:9.1f} g mm, standard error {rows[-1][2] * 1e6:9.1f} g mm '
                  f'(ratio {rows[-1][1] / rows[-1][2]:.2f})')
        table[noise] = rows
    return table


def chart(table, path, seeds):
    """Draw the rms error and the standard error against the window, per noise."""
    import matplotlib
    import matplotlib.ticker
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    for (noise, rows), colour in zip(sorted(table.items()), ('tab:blue', 'tab:orange',
                                                             'tab:red')):
        windows = [r[0] for r in rows]
        ax.loglog(windows, [r[1] * 1e6 for r in rows], 'o-', color=colour,
                  label=f'rms error, cell noise {noise:g} N')
        ax.loglog(windows, [r[2] * 1e6 for r in rows], '--', color=colour,
                  label=f'standard error (fit), {noise:g} N')
    # The windows themselves as ticks, in plain numbers (log axes' minor labels collide).
    ax.set_xticks(windows, [f'{w:g}' for w in windows])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel('window (revolutions at 23.27 rad/s, cells at 250 Hz)')
    ax.set_ylabel('static unbalance error (g mm)')
    ax.set_title('Identified unbalance: error against window and cell noise\n'
                 f'(hidden 150 000 g mm bracket, {seeds} seeded runs per point)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    print(f'wrote {path}')


def live_cost(repeats=5, count=100_000):
    """Return (us per reading, us per motion update) of SlidingFit, best of ``repeats``."""
    declared, motion, cells, _ = simulate(5, 15.0, 0)
    force = (123.0, -4567.0)
    best_reading = best_motion = math.inf
    for _ in range(repeats):
        fitter = SlidingFit(declared.supports, declared.gravity[2], window_revs=10)
        fitter.motion(motion.time[0], motion.angle[0], motion.omega[0], motion.alpha[0])
        start = time.perf_counter()
        for k in range(count):
            fitter.reading('front', motion.time[0] + 1e-4, force)
        best_reading = min(best_reading, (time.perf_counter() - start) / count)
        assert fitter.dropped == 0 and fitter.sums().readings == count
        samples = [(float(t), float(a), float(w), float(al)) for t, a, w, al in
                   zip(motion.time, motion.angle, motion.omega, motion.alpha)]
        start = time.perf_counter()
        for sample in samples:
            fitter.motion(*sample)
        best_motion = min(best_motion, (time.perf_counter() - start) / len(samples))
    return best_reading * 1e6, best_motion * 1e6


def offline_rate(readings=1_000_000, repeats=3):
    """Return readings/s of the vectorised fit over ``readings`` cell readings."""
    declared, motion, cells, _ = simulate(40, 15.0, 1)
    name = declared.supports[0].name
    cell = cells[name]
    reps = readings // len(cell.time) + 1
    span = motion.time[-1] - motion.time[0]
    big_motion = Motion(*(np.concatenate([getattr(motion, f) + (i * span if f == 'time' else 0)
                                          for i in range(reps)])
                          for f in ('time', 'angle', 'omega', 'alpha')))
    big = CellReadings(name, np.concatenate([cell.time + i * span for i in range(reps)]),
                       np.tile(cell.force, (reps, 1)), np.tile(cell.torque, (reps, 1)))
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fit(declared, big_motion, {name: big})
        best = min(best, time.perf_counter() - start)
    return len(big.time) / best, len(big.time)


def main():
    """Print the figures (and write the chart)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer seeds and windows')
    parser.add_argument('--no-cost', action='store_true',
                        help='the accuracy and its chart only (seeded: the same every run)')
    parser.add_argument('--png', default=str(ROOT / 'docs' / 'identify_accuracy.png'))
    args = parser.parse_args()
    if not args.no_cost:
        reading, motion = live_cost()
        print(f'live fit: {reading:.2f} us per cell reading, {motion:.2f} us per motion '
              'sample')
        rate, n = offline_rate()
        print(f'offline fit: {rate / 1e6:.2f} M readings/s ({n} readings)')
    windows = [2, 5, 20] if args.quick else [2, 5, 10, 20, 50]
    seeds = 8 if args.quick else 30
    table = accuracy(windows, [5.0, 15.0, 50.0], seeds)
    chart(table, args.png, seeds)


if __name__ == '__main__':
    main()
