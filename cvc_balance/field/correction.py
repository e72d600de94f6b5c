"""
The balancing problem: readings that corrections change linearly, and the best correction.

A problem has channels c (sensors, or correction planes when the unbalance itself is
known) with baseline readings A_c, and planes j whose added unbalance u_j (complex: kg m,
or by hand the trial's mass unit) changes them by the influence coefficients:

    r = A + alpha u.

Each channel has a weight w_c (1 / its permissible value, 1 / its noise, or 1), so that
channels of different units or allowances can be added. The continuous optimum is the
weighted least-squares u (complex, any mass at any angle); the plans of
:mod:`cvc_balance.field.plan` place it at fixed sites with a kit's weights. When the
unbalance per plane is itself known (identified from load cells), alpha is the identity,
A the unbalance, and w_c = 1 / U_per,c: the residual in each plane as a share of what the
grade allows.
"""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class BalancingProblem:
    """
    Readings r = ``baseline`` + ``influence`` u, with channel ``weights`` and ``limits``.

    ``planes``/``channels`` names; ``baseline`` (C,) complex; ``influence`` (C, N)
    complex; ``weights`` (C,) > 0; ``limits`` (C,) the largest |r_c| allowed (the grade)
    or None; ``unit`` of u ('kg m', or the trial's mass unit by hand).
    """

    planes: tuple
    channels: tuple
    baseline: np.ndarray
    influence: np.ndarray
    weights: np.ndarray
    limits: np.ndarray = None
    unit: str = 'kg m'

    def residual(self, correction):
        """Return r = A + alpha u (C,) for corrections ``correction`` (N,) complex."""
        return self.baseline + self.influence @ np.asarray(correction, complex)

    def measure(self, correction):
        """Return the :class:`Residual` the corrections leave."""
        return Residual.of(self, self.residual(correction))


@dataclass(frozen=True)
class Residual:
    """
    What a correction leaves: ``values`` (C,) complex readings.

    ``rms``: root mean square of w_c |r_c| over the channels; ``total``: the sum of
    w_c |r_c| (what the plans minimise); ``within_limits``: every |r_c| within its limit
    (None without limits); ``worst``: the largest |r_c| / limit_c (None without limits).
    """

    values: np.ndarray
    rms: float
    total: float
    within_limits: bool
    worst: float

    @classmethod
    def of(cls, problem, values):
        """Measure readings ``values`` of ``problem`` (rms over the weighted channels)."""
        weighted = problem.weights * np.abs(values)
        worst = within = None
        if problem.limits is not None:
            worst = float(np.max(np.abs(values) / problem.limits))
            within = bool(worst <= 1.0)
        counted = max(int(np.count_nonzero(problem.weights)), 1)
        return cls(values, float(math.sqrt(np.sum(weighted ** 2) / counted)),
                   float(weighted.sum()), within, worst)


def problem_from_readings(calibration, readings, weights=None, limits=None, unit='kg m'):
    """
    Return the :class:`BalancingProblem` of a run's ``readings`` (sensors,) and coefficients.

    ``calibration``: a :class:`~cvc_balance.field.influence.Calibration`; ``weights``
    per sensor (default 1); ``limits`` per sensor or None.
    """
    readings = np.asarray(readings, complex).reshape(-1)
    if len(readings) != len(calibration.sensors):
        raise ValueError(f'{len(readings)} readings for {len(calibration.sensors)} sensors')
    weights = np.ones(len(readings)) if weights is None else np.asarray(weights, float)
    return BalancingProblem(calibration.planes, calibration.sensors, readings,
                            np.asarray(calibration.matrix, complex), weights,
                            None if limits is None else np.asarray(limits, float), unit)


def problem_from_unbalance(planes, unbalance, permissible=None):
    """
    Return the :class:`BalancingProblem` of a known unbalance per plane (kg m, complex).

    The channels are the planes themselves (alpha = identity); ``permissible`` U_per of
    each plane (kg m) weighs and limits them (None: weight 1, no limits).
    """
    unbalance = np.asarray(unbalance, complex).reshape(-1)
    if permissible is None:
        weights, limits = np.ones(len(unbalance)), None
    else:
        limits = np.asarray(permissible, float).reshape(-1)
        weights = 1.0 / limits
    return BalancingProblem(tuple(planes), tuple(planes), unbalance,
                            np.eye(len(unbalance), dtype=complex), weights, limits, 'kg m')


def with_unbalance_limits(problem, planes, unbalance, limits):
    """
    Return ``problem`` with each plane's unbalance as a channel that only limits.

    ``planes`` names, ``unbalance`` (kg m, complex) per plane before the correction and
    ``limits`` the largest |unbalance| allowed after (the grade): channels of weight 0
    (they add nothing to the residual minimised), moved one to one by the corrections of
    the problem's planes of the same name. The problem's corrections must be in kg m.
    """
    if problem.unit != 'kg m':
        raise ValueError(f'corrections in {problem.unit}, not kg m: no unbalance to limit')
    rows = np.zeros((len(planes), len(problem.planes)), complex)
    for i, plane in enumerate(planes):
        if plane in problem.planes:
            rows[i, problem.planes.index(plane)] = 1.0
    old = np.full(len(problem.channels), np.inf) if problem.limits is None else problem.limits
    return BalancingProblem(
        problem.planes, problem.channels + tuple(f'plane {p} unbalance' for p in planes),
        np.concatenate([problem.baseline, np.asarray(unbalance, complex)]),
        np.vstack([problem.influence, rows]),
        np.concatenate([problem.weights, np.zeros(len(planes))]),
        np.concatenate([old, np.asarray(limits, float)]), problem.unit)


def continuous_correction(problem):
    """
    Return the weighted least-squares corrections u (N,) complex: any mass at any angle.

    Minimises sum_c (w_c |A_c + (alpha u)_c|)^2; exact (no residual) when the planes
    are as many as the independent channels.
    """
    weighted = problem.weights[:, None] * problem.influence
    solution, *_ = np.linalg.lstsq(weighted, -problem.weights * problem.baseline, rcond=None)
    return solution
