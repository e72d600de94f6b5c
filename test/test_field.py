"""
Field balancing's math against published examples, exact constructions and brute force.

Published worked examples (numbers copied, not code, to their printed precision):

* Brüel & Kjær, J. Vaughan, "Static and dynamic balancing using portable measuring
  equipment" (application note, https://www.bksv.com/media/doc/17-227.pdf), Table 2,
  example 6: two sensors, two planes, a 1.15 g trial weight at 0 deg in each plane. As
  worked in the hsbalance package's walk-through (github.com/MagedMohamedTurk/
  Turbomachinery-Rotors-Balancing, docs/source/walkThroughExample.rst, MIT licence): its
  printed influence coefficients and corrections.
* T. P. Goodman, "A least-squares method for computing balance corrections", Journal of
  Engineering for Industry 86 (1964): three sensors, two planes (least squares); as
  transcribed in hsbalance's test/config.yaml ('Goodman64').
* The Balance-It two-plane example with four sensors and trial weights left on, as
  transcribed in hsbalance's test/config.yaml ('Balanceit_Example_Two_Plane'): the
  forward plane's 6.6 g at 113 deg, and the aft plane's 15.3 g at 3 deg that the example's
  author printed (quoted in that file's comment; hsbalance's test uses another value).
"""

import cmath
import itertools
import math

import numpy as np
import pytest

from cvc_balance.field import (BalancingProblem, calibrate, continuous_correction,
                               optimal_plan, problem_from_readings, problem_from_unbalance,
                               round_to_kit, split_plan, steady_window, track, Trial,
                               vector_split)
from cvc_balance.field.correction import with_unbalance_limits
from cvc_balance.field.notation import bag_trial, hand_trial, reading
from cvc_balance.physics.layout import WeightSites


def polar(amplitude, degrees):
    return cmath.rect(amplitude, math.radians(degrees))


def assert_printed(value, amplitude, degrees, amplitude_digits, degree_digits=1):
    """``value`` printed as amplitude@degrees to the given decimals equals the print."""
    got_degrees = math.degrees(cmath.phase(value)) % 360.0
    assert abs(abs(value) - amplitude) <= 0.5 * 10 ** -amplitude_digits + 1e-12, \
        (abs(value), amplitude)
    difference = abs(math.remainder(got_degrees - degrees, 360.0))
    assert difference <= 0.5 * 10 ** -degree_digits + 1e-9, (got_degrees, degrees)


# -- published examples ------------------------------------------------------------------

BK_BASELINE = ['170@112', '53@78']
BK_TRIALS = [('I', '1.15@0', ['235@94', '58@68']), ('II', '1.15@0', ['185@115', '77@104'])]


def test_bk_two_plane_example_coefficients_and_corrections():
    calibration = calibrate([reading(a) for a in BK_BASELINE],
                            [hand_trial(p, m) for p, m, _ in BK_TRIALS],
                            [[reading(b) for b in bs] for _, _, bs in BK_TRIALS])
    # Printed: sensor 1: 78.433 @ 58.4, 15.34 @ 145.3; sensor 2: 9.462 @ 10.2, 32.56 @ 142.4.
    assert_printed(calibration.matrix[0, 0], 78.433, 58.4, 3)
    assert_printed(calibration.matrix[0, 1], 15.34, 145.3, 2)
    assert_printed(calibration.matrix[1, 0], 9.462, 10.2, 3)
    assert_printed(calibration.matrix[1, 1], 32.56, 142.4, 2)
    problem = problem_from_readings(calibration, [reading(a) for a in BK_BASELINE])
    correction = continuous_correction(problem)
    # Printed corrections: plane 1 1.979 @ 236.2, plane 2 1.071 @ 121.8 (g); RMSE 0.0.
    assert_printed(correction[0], 1.979, 236.2, 3)
    assert_printed(correction[1], 1.071, 121.8, 3)
    assert problem.measure(correction).rms < 1e-12        # measured: 4.6e-14
    assert calibration.warnings == ()                       # changes of 11-69 % of the readings


def test_goodman_1964_least_squares_with_more_sensors_than_planes():
    alpha = np.array([[polar(3, 0), polar(2, 180)], [polar(5, 0), polar(2, 180)],
                      [polar(5, 0), polar(3, 180)]])
    baseline = np.array([polar(1, 0), polar(1, 180), polar(0, 0)])
    problem = BalancingProblem(('1', '2'), ('a', 'b', 'c'), baseline, alpha, np.ones(3))
    correction = continuous_correction(problem)
    # Printed: 0.81 @ 0 and 1.48 @ 0.
    assert_printed(correction[0], 0.81, 0.0, 2, 0)
    assert_printed(correction[1], 1.48, 0.0, 2, 0)
    # Least squares: the residual is orthogonal to every plane's column (normal equations).
    residual = problem.residual(correction)
    assert np.max(np.abs(alpha.conj().T @ residual)) < 1e-12
    assert np.linalg.norm(residual) > 0.5                   # no exact solution: 0.617


def test_balance_it_four_sensors_trials_kept_on():
    baseline = [polar(.68, 32), polar(.56, 86), polar(1.94, 231), polar(2.07, 335)]
    runs = [[polar(1.31, 1), polar(1.25, 75), polar(.93, 251), polar(1, 342)],
            [polar(.54, 9), polar(.52, 75), polar(.81, 196), polar(.9, 296)]]
    trials = [hand_trial('aft', '11.1@35'), hand_trial('fwd', '3.7@135')]
    calibration = calibrate(baseline, trials, runs, keep_trial=True)
    # With the trials kept on, run 2's change from run 1 is the second trial's alone.
    expected_fwd = (np.array(runs[1]) - np.array(runs[0])) / trials[1].unbalance
    assert np.allclose(calibration.matrix[:, 1], expected_fwd, rtol=1e-13)
    correction = continuous_correction(problem_from_readings(calibration, baseline))
    assert_printed(correction[0], 15.3, 3.0, 1, 0)       # the author's aft plane
    assert_printed(correction[1], 6.6, 113.0, 1, 0)      # the forward plane


def test_influence_command_gives_the_published_example(tmp_path):
    import json
    import subprocess
    import sys
    argv = [sys.executable, '-m', 'cvc_balance.cli', 'influence', '--json',
            '--baseline', *BK_BASELINE]
    for plane, mass, values in BK_TRIALS:
        argv += ['--trial', plane, mass, *values]
    done = subprocess.run(argv, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout, parse_constant=lambda c: pytest.fail(f'non-JSON {c}'))
    assert [c['plane'] for c in data['corrections']] == ['I', 'II']
    first, second = data['corrections']
    assert (round(first['mass'], 3), round(first['angle_deg'], 1)) == (1.979, 236.2)
    assert (round(second['mass'], 3), round(second['angle_deg'], 1)) == (1.071, 121.8)
    entry = data['coefficients'][0][0]
    assert (round(entry['amplitude'], 3), round(entry['phase_deg'], 1)) == (78.433, 58.4)
    assert data['condition_number'] > 1.0 and len(data['residual']) == 2
    assert max(r['amplitude'] for r in data['residual']) < 1e-9


# -- influence coefficients: exact constructions, noise, too small ------------------------

def synthetic(rng, sensors=4, planes=2):
    alpha = rng.normal(size=(sensors, planes)) + 1j * rng.normal(size=(sensors, planes))
    baseline = rng.normal(size=sensors) + 1j * rng.normal(size=sensors)
    return alpha, baseline


@pytest.mark.parametrize('keep_trial', [False, True])
def test_coefficients_exact_with_more_runs_than_planes(keep_trial):
    rng = np.random.default_rng(4)
    alpha, baseline = synthetic(rng, 5, 2)
    trials = [Trial('I', 0.3, 0.2, 0.5), Trial('II', 0.2, 2.0, 0.7), Trial('I', 0.25, 4.0, 0.5)]
    on, readings = np.zeros(2, complex), []
    for trial in trials:
        on = on if keep_trial else np.zeros(2, complex)
        on[('I', 'II').index(trial.plane)] += trial.unbalance
        readings.append(baseline + alpha @ on)
    calibration = calibrate(baseline, trials, readings, keep_trial=keep_trial)
    assert calibration.planes == ('I', 'II')
    assert np.max(np.abs(calibration.matrix - alpha)) < 1e-12 * np.max(np.abs(alpha))


def test_coefficient_ci95_covers_the_truth_95_percent():
    rng = np.random.default_rng(7)
    alpha, baseline = synthetic(rng, 3, 2)
    trials = [Trial('I', 1.0, 0.0), Trial('II', 1.0, 1.0)]
    sigma, inside, total = 0.05, 0, 0
    for _ in range(600):
        noisy = [baseline + sigma * (rng.normal(size=3) + 1j * rng.normal(size=3))]
        for k, trial in enumerate(trials):
            on = np.zeros(2, complex)
            on[k] = trial.unbalance
            noisy.append(baseline + alpha @ on
                         + sigma * (rng.normal(size=3) + 1j * rng.normal(size=3)))
        calibration = calibrate(noisy[0], trials, noisy[1:], None, False, np.full(3, sigma),
                                np.full((2, 3), sigma))
        inside += int(np.sum(np.abs(calibration.matrix - alpha) <= calibration.ci95))
        total += alpha.size
    # 3600 coefficients: 95 % +- 1.1 % (3 binomial standard errors); measured 94.75 %.
    assert 0.939 <= inside / total <= 0.961, inside / total


def test_a_trial_too_small_to_see_is_said_and_flagged():
    rng = np.random.default_rng(9)
    alpha, baseline = synthetic(rng, 2, 2)
    sigma = 0.02
    trials = [Trial('I', 1.0, 0.0), Trial('II', 0.005, 0.0)]      # plane II's: 1/200
    readings = [baseline + alpha @ [trials[0].unbalance, 0],
                baseline + alpha @ [0, trials[1].unbalance]]
    calibration = calibrate(baseline, trials, readings, None, False, np.full(2, sigma),
                            np.full((2, 2), sigma))
    first, second = calibration.checks
    assert not first.too_small and not first.weak
    assert second.too_small and second.snr < 5.0
    assert len(calibration.warnings) == 1
    text = calibration.warnings[0]
    assert 'trial run 2 (plane II' in text and 'too small to see' in text
    assert 'times heavier' in text
    # Its coefficients' 95 % radius is larger than the coefficients themselves: no sense.
    assert np.all(calibration.ci95[:, 1] > np.abs(calibration.matrix[:, 1]))


def test_a_trial_too_small_by_hand_is_said():
    calibration = calibrate([reading('100@0')], [hand_trial('I', '1@0')], [[reading('104@1')]])
    assert calibration.checks[0].too_small
    assert 'too small to see' in calibration.warnings[0]
    assert 'changed by at most 4.' in calibration.warnings[0]


def test_runs_that_cannot_give_coefficients_are_refused():
    with pytest.raises(ValueError, match='must be > 0'):
        calibrate([1, 2], [Trial('I', 0.0, 0.0)], [[2, 3]])
    with pytest.raises(ValueError, match='readings'):
        calibrate([1, 2], [Trial('I', 1, 0)], [[2, 3, 4]])
    with pytest.raises(ValueError, match='no trial run'):
        calibrate([1, 2], [], np.zeros((0, 2)))


# -- notation ------------------------------------------------------------------------------

@pytest.mark.parametrize('text', ['170', '170@', '@12', 'abc@12', '-3@10', 'nan@1', '1@inf',
                                  '1@2@3', '1e400@3', '5@1e9'])
def test_bad_readings_are_named(text):
    with pytest.raises(ValueError) as error:
        reading(text)
    assert 'reading' in str(error.value) and '\n' not in str(error.value)


def test_bag_trial_notation():
    trial = bag_trial('II:0.2@90,0.68')
    assert (trial.plane, trial.mass, trial.radius) == ('II', 0.2, 0.68)
    assert abs(trial.unbalance - 0.136j) < 1e-15
    for bad in ('II:0.2@90', 'II 0.2@90,0.68', 'II:0@90,0.68', 'II:0.2@90,-1', 'I I:1@0,1'):
        with pytest.raises(ValueError):
            bag_trial(bad)


# -- order tracking ----------------------------------------------------------------------

def test_order_tracking_exact_on_a_first_harmonic_with_others_present():
    t = np.arange(0.0, 10.0, 1.0 / 997.0)
    omega = 20.0
    q = omega * t + 0.3
    x = 4.0 + 2.5 * np.cos(q + 0.7) + 0.8 * np.cos(2 * q - 1.0) + 0.3 * np.sin(3 * q)
    window = steady_window(t, q, np.full_like(t, omega))
    assert window.revolutions == math.floor((q[-1] - q[0]) / (2 * math.pi))
    phasor = track(t, x, t, q, window)
    # Whole revolutions sampled finely: 2x and 3x leak below 1e-4 of their amplitude.
    assert abs(phasor.value - polar(2.5, math.degrees(0.7))) < 2e-4
    assert abs(phasor.offset - 4.0) < 2e-4
    exact = track(t, 4.0 + 2.5 * np.cos(q + 0.7), t, q, window)
    assert abs(exact.value - polar(2.5, math.degrees(0.7))) < 1e-12
    assert exact.sigma < 1e-12


def test_order_tracking_95_percent_circles_cover_the_truth():
    rng = np.random.default_rng(12)
    t = np.arange(0.0, 6.0, 1.0 / 200.0)
    q = 23.27 * t
    truth = polar(60.0, 40.0)
    window = steady_window(t, q, np.full_like(t, 23.27))
    inside = 0
    for _ in range(400):
        jitter = t + rng.uniform(0.0, 1.0 / 200.0, len(t))      # readings off the encoder
        qt = 23.27 * jitter
        x = 100.0 + (truth * np.exp(1j * qt)).real + rng.normal(0.0, 15.0, len(t))
        phasor = track(jitter, x, t, q, window)
        inside += abs(phasor.value - truth) <= math.sqrt(5.991464547107979) * phasor.sigma
    # 400 draws: 95 % +- 3.3 % (3 binomial standard errors); measured 94.25 %.
    assert 0.917 <= inside / 400 <= 0.983, inside / 400


def test_steady_window_of_a_spin_up_steady_coast_down():
    t = np.arange(0.0, 12.0, 0.002)
    omega = np.interp(t, [0.0, 3.0, 9.0, 11.0, 12.0], [0.0, 24.0, 24.0, 4.0, 0.0])
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * np.diff(t))])
    window = steady_window(t, angle, omega)
    # Steady is within 1 % of 24 rad/s: from 2.97 s on the ramp (23.76 rad/s).
    assert 2.97 - 1e-9 <= window.start < 3.0 and window.end <= 9.0 + 0.01 * 2.0
    assert abs(window.speed - 24.0) < 0.002             # the mean, ramp ends in: 23.9989
    turned = np.interp(window.end, t, angle) - np.interp(window.start, t, angle)
    assert abs(turned - 2 * math.pi * window.revolutions) < 1e-6
    steady = np.flatnonzero(np.abs(omega - 24.0) <= 0.24)     # one unbroken stretch here
    assert window.revolutions == math.floor((angle[steady[-1]] - angle[steady[0]])
                                            / (2 * math.pi)) == 23
    with pytest.raises(ValueError, match='no steady stretch at 30'):
        steady_window(t, angle, omega, speed=30.0)
    short = t[t < 1.0]                                  # 5 rad/s for 1 s: 0.8 of a turn
    with pytest.raises(ValueError, match='whole revolution'):
        steady_window(short, 5.0 * short, np.full(len(short), 5.0))


# -- corrections at sites: split, kit, and the plan against brute force -------------------

def test_vector_split_between_neighbouring_sites():
    sites = WeightSites('I', tuple(np.radians([0.0, 30.0, 220.0])), 0.5, (0.01,), 1)
    correction = polar(0.1 * 0.5, 10.0)                 # 100 g at 10 deg, at 0.5 m
    (a, ma), (b, mb) = vector_split(correction, sites)
    assert (round(math.degrees(a)), round(math.degrees(b))) == (0, 30)
    # By the sine rule: 100 sin(20) / sin(30) and 100 sin(10) / sin(30) grams.
    assert abs(ma - 0.1 * math.sin(math.radians(20)) / 0.5) < 1e-15
    assert abs(mb - 0.1 * math.sin(math.radians(10)) / 0.5) < 1e-15
    assert abs(0.5 * (ma * cmath.exp(1j * a) + mb * cmath.exp(1j * b)) - correction) < 1e-16
    with pytest.raises(ValueError, match='half a turn'):
        vector_split(polar(0.05, 100.0), sites)          # between 30 and 220 deg: 190 deg


def test_kit_rounding_against_enumeration():
    sites = WeightSites('I', (0.0,), 0.5, (0.05, 0.1, 0.2, 0.5), 3)
    stacks = [()] + [c for n in range(1, 4)
                     for c in itertools.combinations_with_replacement(sites.masses, n)]
    for mass in np.linspace(0.0, 1.8, 181):
        best = min(abs(sum(s) - mass) for s in stacks)
        got = round_to_kit(mass, sites)
        assert len(got) <= 3 and set(got) <= set(sites.masses)
        assert abs(abs(sum(got) - mass) - best) < 1e-12


K = 32
TURNS = np.exp(-2j * np.pi * np.arange(K) / K)


def gauge(values, weights):
    """Return the plan's measure of a residual: sum of w max_l Re(r e^{-i theta_l})."""
    return float(np.sum(weights * np.max((values[:, None] * TURNS[None, :]).real, axis=1)))


def plane_options(sites):
    """Every way to load a plane's sites: (unbalance, weights) of each."""
    per_site = [()] + [c for n in range(1, sites.stack + 1)
                       for c in itertools.combinations_with_replacement(sites.masses, n)]
    options = []
    for choice in itertools.product(per_site, repeat=len(sites.angles)):
        u = sum(sum(s) * sites.radius * cmath.exp(1j * a) for s, a in zip(choice, sites.angles))
        options.append((complex(u), sum(len(s) for s in choice)))
    return options


def brute_force(problem, sites, objective, cap=None):
    """
    Best ((gauge, count) or (count, gauge), u) by enumeration, None if nothing fits.

    'residual': the smallest gauge, then the fewest weights among plans within 1e-7 of it
    (the plan's own tie tolerance); 'fewest': within the limits' inner polygon, the fewest
    weights, then the smallest gauge.
    """
    planes = [plane_options(sites[p]) for p in problem.planes]
    found = []
    for combo in itertools.product(*planes):
        u = np.array([c[0] for c in combo])
        count = sum(c[1] for c in combo)
        if cap is not None and count > cap:
            continue
        r = problem.residual(u)
        if objective == 'fewest':
            limited = np.isfinite(problem.limits)
            reach = np.max((r[limited, None] * TURNS[None, :]).real, axis=1) \
                / problem.limits[limited]
            if np.any(reach > math.cos(math.pi / K) + 1e-12):
                continue
        found.append((gauge(r, problem.weights), count, u))
    if not found:
        return None
    if objective == 'fewest':
        fewest = min(f[1] for f in found)
        value, count, u = min((f for f in found if f[1] == fewest), key=lambda f: f[0])
        return (count, value), u
    smallest = min(f[0] for f in found)
    near = [f for f in found if f[0] <= smallest * (1 + 1e-7) + 1e-12]
    _, count, u = min(near, key=lambda f: f[1])
    return (smallest, count), u


KITS = {
    'coupled, 4 sites x 2 sizes': ({'I': WeightSites('I', tuple(np.radians([0, 60, 150, 240])),
                                                     0.5, (0.1, 0.25), 1),
                                    'II': WeightSites('II', tuple(np.radians([30, 120, 200,
                                                                              300])),
                                                      0.6, (0.1, 0.25), 1)}, 3),
    'stacks of 2': ({'I': WeightSites('I', tuple(np.radians([0, 90, 180, 270])), 0.5,
                                      (0.1, 0.3), 2),
                     'II': WeightSites('II', tuple(np.radians([45, 165, 285])), 0.5,
                                       (0.2,), 2)}, 2),
}


@pytest.mark.parametrize('kit', sorted(KITS))
@pytest.mark.parametrize('seed', range(4))
def test_plan_smallest_residual_equals_brute_force(kit, seed):
    sites, sensors = KITS[kit]
    rng = np.random.default_rng(100 + seed)
    alpha, baseline = synthetic(rng, sensors, 2)
    problem = BalancingProblem(('I', 'II'), tuple('abc'[:sensors]), 0.3 * baseline, alpha,
                               rng.uniform(0.5, 2.0, sensors))
    plan = optimal_plan(problem, sites, 'residual', polygon=K)
    (value, count), u = brute_force(problem, sites, 'residual')
    assert plan.status == 'optimal'
    got = gauge(problem.residual(plan.corrections), problem.weights)
    assert abs(got - value) <= 1e-6 * value, (got, value)      # measured: <= 2e-16
    assert plan.count == count
    # And in Euclidean terms within the polygon's 1 / cos(pi / 32) of the best.
    pairs = itertools.product(plane_options(sites['I']), plane_options(sites['II']))
    euclid = min(float(np.sum(problem.weights * np.abs(problem.residual(np.array(
        [a[0], b[0]]))))) for a, b in pairs)
    assert plan.residual.total <= euclid / math.cos(math.pi / K) * (1 + 1e-9)


@pytest.mark.parametrize('seed', range(4))
def test_plan_fewest_weights_within_limits_equals_brute_force(seed):
    sites, _ = KITS['stacks of 2']
    rng = np.random.default_rng(200 + seed)
    unbalance = 0.12 * (rng.normal(size=2) + 1j * rng.normal(size=2))
    problem = problem_from_unbalance(('I', 'II'), unbalance, permissible=[0.03, 0.04])
    plan = optimal_plan(problem, sites, 'fewest', polygon=K)
    best = brute_force(problem, sites, 'fewest')
    if best is None:
        assert plan.status == 'infeasible' and plan.weights == ()
        return
    (count, value), _ = best
    assert plan.status == 'optimal' and plan.count == count
    assert abs(gauge(problem.residual(plan.corrections), problem.weights) - value) \
        <= 1e-6 * max(value, 1e-12)
    assert plan.residual.within_limits and plan.residual.worst <= 1.0


def test_plan_with_a_weight_cap_and_a_plane_without_sites():
    rng = np.random.default_rng(5)
    alpha, baseline = synthetic(rng, 3, 2)
    sites = {'I': KITS['stacks of 2'][0]['I']}
    problem = BalancingProblem(('I', 'II'), ('a', 'b', 'c'), 0.3 * baseline, alpha, np.ones(3))
    plan = optimal_plan(problem, sites, 'residual', max_weights=2, polygon=K)
    assert plan.count <= 2 and set(plan.free) == {'II'}
    # Enumerate plane I's options with at most 2 weights; plane II free: a convex problem
    # in u_II for each, solved by least squares as a bound on the gauge (the gauge is
    # <= the sum of |r| and >= cos(pi/K) times it).
    best = math.inf
    for u1, count in plane_options(sites['I']):
        if count > 2:
            continue
        rest = problem.baseline + alpha[:, 0] * u1
        u2, *_ = np.linalg.lstsq(alpha[:, 1:], -rest, rcond=None)
        best = min(best, float(np.sum(np.abs(rest + alpha[:, 1] * u2[0]))))
    assert plan.residual.total <= best / math.cos(math.pi / K) * (1 + 1e-6)


def test_unbalance_limit_channels_do_not_move_the_least_squares():
    rng = np.random.default_rng(8)
    alpha, baseline = synthetic(rng, 4, 2)
    problem = BalancingProblem(('I', 'II'), tuple('abcd'), baseline, alpha, np.ones(4))
    limited = with_unbalance_limits(problem, ('I', 'II'), [0.1, 0.2j], [0.05, 0.05])
    assert np.allclose(continuous_correction(limited), continuous_correction(problem),
                       rtol=1e-13, atol=0)
    assert len(limited.channels) == 6 and limited.limits[0] == math.inf
    u = continuous_correction(problem)
    assert abs(limited.measure(u).rms - problem.measure(u).rms) < 1e-13


def test_split_plan_recombines_before_rounding():
    sites = {'I': WeightSites('I', tuple(np.radians(np.arange(0, 360, 15))), 0.68,
                              (0.05, 0.1, 0.2, 0.5), 3)}
    problem = problem_from_unbalance(('I',), [polar(0.1171, 177.6)])
    correction = continuous_correction(problem)
    plan = split_plan(problem, sites, correction)
    shares = vector_split(correction[0], sites['I'])
    exact = sum(0.68 * m * cmath.exp(1j * a) for a, m in shares)
    assert abs(exact - correction[0]) < 1e-15
    assert all(set(w.masses) <= {0.05, 0.1, 0.2, 0.5} for w in plan.weights)
    assert {round(math.degrees(w.angle)) for w in plan.weights} <= {345, 0}
