"""
The balancing problem's inputs in other shapes, by hand (field/correction.py).

Readings and permissible shares given as columns (n x 1, as a spreadsheet's export gives
them) are the same channels as a flat list; the limits added for each plane's unbalance
keep the problem's unit.
"""

import numpy as np

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
