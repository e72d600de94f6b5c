"""
Field balancing's inputs in other shapes and its refusals, by hand.

The balancing problem (field/correction.py) and the coefficients (field/influence.py).
Readings, errors and permissible shares given as columns (n x 1, as a spreadsheet's export
gives them) are the same channels as flat lists; the limits added for each plane's
unbalance keep the problem's unit; coefficients that give no correction are refused in
the words people read, their condition numbers from diagonal matrices (whose entries are
their singular values).
"""

import numpy as np
import pytest

from cvc_balance.field import calibrate, Trial
from cvc_balance.field.correction import (BalancingProblem, problem_from_readings,
                                          problem_from_unbalance, with_unbalance_limits)


def test_readings_and_shares_given_as_columns_are_the_same_channels():
    baseline = np.array([120 + 40j, -90 + 10j])
    alpha = np.array([600 + 0j, -400 + 200j])
    trials = [Trial('I', 0.2, 0.5, 0.68)]
    found = calibrate(baseline, trials, [baseline + alpha * trials[0].unbalance], ['a', 'b'])
    column = problem_from_readings(found, baseline.reshape(2, 1), [[1.0], [0.5]])
    assert column.baseline.shape == (2,)
    assert np.array_equal(column.baseline, baseline)
    known = problem_from_unbalance(['I', 'II'], [[0.3 + 0.1j], [-0.2j]], [[0.5], [0.25]])
    assert known.baseline.shape == known.limits.shape == known.weights.shape == (2,)
    assert np.array_equal(known.limits, [0.5, 0.25]) and np.array_equal(known.weights, [2, 4])
    assert known.measure([0j, 0j]).worst == 0.8


def test_unbalance_limits_keep_the_problems_unit():
    problem = BalancingProblem(('I',), ('a',), np.array([1 + 1j]), np.array([[2 + 0j]]),
                               np.array([1.0]))
    limited = with_unbalance_limits(problem, ['I'], [0.1], [0.2])
    assert limited.unit == 'kg m' and limited.planes == ('I',)


def test_coefficients_that_give_no_correction_are_refused_in_these_words():
    """
    Refuse coefficients that give no correction, in these words.

    Fewer sensors than planes; a plane acting on no sensor (a zero singular value); the
    smallest singular value at 1e-10 of the largest (under the 1e-9 allowed): the words,
    the condition number by hand (diagonal matrices: their entries are the singular values).
    """
    from cvc_balance.field.influence import checked_condition
    refusals = (
        ([[1.0, 0.0]], 'the coefficients', 'the coefficients: 1 sensor for 2 planes: '
         'rank-deficient, no correction follows (a sensor per plane at least)'),
        ([[1.0, 0.0, 2.0], [0.0, 1.0, 0.0]], 'X', 'X: 2 sensors for 3 planes: '
         'rank-deficient, no correction follows (a sensor per plane at least)'),
        ([[1.0, 0.0], [2.0, 0.0]], 'X', 'X are singular (condition number inf): a plane acts '
         'on no sensor, or two planes act alike; no correction follows'),
        (np.diag([10.0, 5.0, 1e-9]), 'X', 'X are singular (condition number 1e+10): a plane '
         'acts on no sensor, or two planes act alike; no correction follows'))
    for matrix, what, said in refusals:
        with pytest.raises(ValueError) as caught:
            if what == 'the coefficients':
                checked_condition(matrix)
            else:
                checked_condition(matrix, what)
        assert str(caught.value) == said
    assert checked_condition(np.diag([10.0, 1e-7])) == pytest.approx(1e8, rel=1e-12)
    assert checked_condition([[3.0, 0.0], [0.0, 1.0], [0.0, 0.0]]) == 3.0


def test_trial_runs_that_cannot_give_coefficients_are_refused_in_these_words():
    """A trial of 1e-20 kg beside one of 0.2 kg: the runs cannot tell the planes apart."""
    baseline = np.array([1.0 + 0j, 2.0 + 0j])
    trials = [Trial('I', 1e-20, 0.0, 0.68), Trial('II', 0.2, 0.0, 0.68)]
    with pytest.raises(ValueError) as caught:
        calibrate(baseline, trials, [baseline + 1.0, baseline + 2.0])
    assert str(caught.value) == ('the trial runs cannot tell the planes apart (give each plane '
                                 'its own trial run)')
    # A trial that moves no sensor: the measured coefficients are singular.
    trials = [Trial('I', 0.1, 0.0, 0.68), Trial('II', 0.2, 0.0, 0.68)]
    with pytest.raises(ValueError) as caught:
        calibrate(baseline, trials, [baseline + [1.0, 0.5], baseline])
    assert str(caught.value) == ('the measured coefficients are singular (condition number '
                                 'inf): a plane acts on no sensor, or two planes act alike; no '
                                 'correction follows')


def test_a_baseline_and_its_errors_given_as_columns_and_each_trial_on_alone():
    """The same coefficients and radii as from flat lists; by hand: a trial's change."""
    from cvc_balance.field.influence import trial_weights_on
    baseline = np.array([120 + 40j, -90 + 10j])
    trials = [Trial('I', 0.2, 0.5, 0.68), Trial('II', 0.1, 1.0, 0.68)]
    alpha = np.array([[600 + 0j, 70j], [-400 + 200j, 60 - 10j]])
    readings = [baseline + alpha[:, 0] * trials[0].unbalance,
                baseline + alpha[:, 1] * trials[1].unbalance]
    flat = calibrate(baseline, trials, readings, baseline_sigma=[0.5, 0.7],
                     trial_sigmas=[[0.4, 0.6], [0.3, 0.2]])
    column = calibrate(baseline.reshape(2, 1), trials, readings,
                       baseline_sigma=[[0.5], [0.7]], trial_sigmas=[[0.4, 0.6], [0.3, 0.2]])
    assert np.allclose(column.matrix, alpha, rtol=1e-12)
    assert np.array_equal(column.matrix, flat.matrix) and np.array_equal(column.ci95, flat.ci95)
    by_hand = calibrate(baseline, trials, readings)
    for k in (0, 1):
        change = np.abs(alpha[:, k] * trials[k].unbalance)
        assert by_hand.checks[k].change == pytest.approx(change.max(), rel=1e-12)
    assert np.array_equal(trial_weights_on(trials, ('I', 'II')),
                          np.diag([trials[0].unbalance, trials[1].unbalance]))


def test_a_trials_visibility_on_its_thresholds_by_hand():
    """
    Judge a trial's visibility exactly on its thresholds.

    By hand (no noise known): a change of exactly 10 % of the reading is seen. With noise:
    sigmas 3 and 4 (5 in quadrature), changes of 25 and 100: exactly 5 standard errors is
    weak but seen, exactly 20 neither weak nor too small.
    """
    one = [Trial('I', 0.1, 0.0, 1.0)]
    seen = calibrate([10.0 + 0j, 10.0 + 0j], one, [[11.0 + 0j, 10.0 + 0j]])
    (check,) = seen.checks
    assert (check.relative, check.too_small, check.weak) == (0.1, False, False)
    assert seen.warnings == ()
    for change, weak in ((25.0, True), (100.0, False)):
        noisy = calibrate([10.0 + 0j], one, [[10.0 + change]], baseline_sigma=[3.0],
                          trial_sigmas=[[4.0]])
        (check,) = noisy.checks
        assert check.snr == change / 5.0
        assert (check.too_small, check.weak) == (False, weak)
