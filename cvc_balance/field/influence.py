"""
Influence coefficients from a baseline run and trial-weight runs, as field balancing does.

Readings are complex 1x vectors per sensor (any unit: N, mm/s, um). A trial weight is a
complex unbalance T = m r e^{i theta} (kg m; by hand, the trial's mass unit with r = 1).
With the rotor linear in its unbalance, the readings of a run are

    R = A + alpha u,

A the baseline's readings, u the unbalance added per correction plane and alpha (sensors x
planes) the influence coefficients. Trial run k has the trial weights u_k on (its own
trial alone, or with ``keep_trial`` every trial so far); stacking the runs,
R_k - A = alpha u_k for every k, solved for alpha by least squares over the runs
(exactly when there is one trial per plane). Standard errors of the readings, when known,
give each coefficient's 95 % radius and each trial's signal-to-noise ratio; a trial whose
change is lost in the noise is reported, never silently used.
"""

from dataclasses import dataclass
import math

import numpy as np

CHI2_2DOF_95 = 5.991464547107979
"""95 % quantile of chi-square with 2 degrees of freedom: a complex error's 95 % circle."""
TOO_SMALL_SNR = 5.0
"""A trial whose largest change is under this many standard errors is too small to see."""
WEAK_SNR = 20.0
"""Under this signal-to-noise ratio the trial's coefficients are uncertain by over 12 %."""
TOO_SMALL_CHANGE = 0.1
"""Readings by hand (no noise known): a change under 10 % of the readings is too small."""
ILL_CONDITIONED = 100.0
"""Condition number of the coefficients above which the planes are nearly dependent."""
SINGULAR = 1e-9
"""Coefficients whose smallest singular value is under this share of the largest are
singular: two planes act alike (to 1e-9) or one acts on no sensor."""


@dataclass(frozen=True)
class Trial:
    """A trial weight: ``plane`` name, ``mass`` (kg, or any unit by hand), ``angle`` rad, r m."""

    plane: str
    mass: float
    angle: float
    radius: float = 1.0

    @property
    def unbalance(self):
        """Return m r e^{i angle}: kg m (with r = 1, the mass's own unit)."""
        return self.mass * self.radius * complex(math.cos(self.angle), math.sin(self.angle))


@dataclass(frozen=True)
class TrialCheck:
    """
    How visible one trial weight was.

    ``change`` the largest change of a sensor's reading that the trial made; ``snr`` that
    change over its standard error (None by hand); ``relative`` that change over the
    sensor's reading before it; ``too_small`` / ``weak``: see the module's thresholds.
    """

    run: int
    plane: str
    change: float
    snr: float
    relative: float
    too_small: bool
    weak: bool


@dataclass(frozen=True)
class Calibration:
    """
    Influence coefficients: ``matrix`` (sensors x planes, complex, reading per unbalance).

    ``ci95`` the 95 % radius of each coefficient (None when the noise is not known);
    ``condition`` the 2-norm condition number of ``matrix``; ``checks`` one
    :class:`TrialCheck` per trial run; ``warnings`` one line each.
    """

    planes: tuple
    sensors: tuple
    matrix: np.ndarray
    ci95: np.ndarray
    condition: float
    checks: tuple
    warnings: tuple


def calibrate(baseline, trials, readings, sensors=None, keep_trial=False,
              baseline_sigma=None, trial_sigmas=None):
    """
    Return the :class:`Calibration` of a baseline and trial runs.

    ``baseline`` (sensors,) complex readings; ``trials`` one :class:`Trial` per trial run;
    ``readings`` (runs, sensors) complex readings of the trial runs; ``sensors`` names;
    ``keep_trial``: each trial stays on for the runs after it. ``baseline_sigma``
    (sensors,) and ``trial_sigmas`` (runs, sensors): standard errors per component of the
    readings (None: not known). Planes are named in the order their first trial comes.
    Raises ValueError when the runs cannot give every plane's coefficients.
    """
    if not trials:
        raise ValueError('no trial run: give one per correction plane')
    baseline = np.asarray(baseline, complex).reshape(-1)
    readings = np.asarray(readings, complex).reshape(len(trials), -1)
    count = len(baseline)
    if readings.shape[1] != count:
        raise ValueError(f'each run needs {count} readings (as the baseline), '
                         f'got {readings.shape[1]}')
    sensors = tuple(sensors) if sensors is not None else \
        tuple(f'sensor {k + 1}' for k in range(count))
    planes = tuple(dict.fromkeys(t.plane for t in trials))
    for k, trial in enumerate(trials):
        if not (trial.mass > 0.0 and trial.radius > 0.0):
            raise ValueError(f'trial run {k + 1} (plane {trial.plane}): the trial mass and '
                             'radius must be > 0')
    weights_on = trial_weights_on(trials, planes, keep_trial)
    if np.linalg.matrix_rank(weights_on) < len(planes):
        raise ValueError('the trial runs cannot tell the planes apart (give each plane its '
                         'own trial run)')
    change = readings - baseline
    pseudo = np.linalg.pinv(weights_on)              # planes x runs
    matrix = (pseudo @ change).T                     # sensors x planes
    known = baseline_sigma is not None and trial_sigmas is not None
    ci95 = None
    if known:
        sigma_a = np.asarray(baseline_sigma, float).reshape(count)
        sigma_b = np.asarray(trial_sigmas, float).reshape(len(trials), count)
        ci95 = np.empty((count, len(planes)))
        for s in range(count):
            # The baseline is common to every run's change: its error is correlated.
            cov = np.diag(sigma_b[:, s] ** 2) + sigma_a[s] ** 2
            variance = np.real(np.einsum('jk,kl,jl->j', pseudo, cov, pseudo.conj()))
            ci95[s] = np.sqrt(CHI2_2DOF_95 * np.maximum(variance, 0.0))
    condition = checked_condition(matrix, 'the measured coefficients')
    checks = tuple(_check(k, trials[k], baseline, readings, keep_trial,
                          sigma_a if known else None, sigma_b if known else None)
                   for k in range(len(trials)))
    warnings = [_warning(check, trials[check.run]) for check in checks
                if check.too_small or check.weak]
    if condition > ILL_CONDITIONED:
        warnings.append(f'the coefficients are ill-conditioned (condition number '
                        f'{condition:.3g}): the planes act nearly alike on these sensors, '
                        'and reading errors are amplified up to that many times in the '
                        'corrections')
    return Calibration(planes, sensors, matrix, ci95, condition, checks, tuple(warnings))


def checked_condition(matrix, what='the coefficients'):
    """
    Return the 2-norm condition number of coefficients (sensors, planes); refuse singular.

    Raises ValueError when there are fewer sensors than planes, or the planes' columns
    are dependent (rank-deficient, to :data:`SINGULAR`): no correction follows.
    """
    matrix = np.asarray(matrix, complex)
    sensors, planes = matrix.shape
    if sensors < planes:
        raise ValueError(f'{what}: {sensors} sensor{"s" if sensors > 1 else ""} for {planes} '
                         'planes: rank-deficient, no correction follows (a sensor per plane '
                         'at least)')
    singular = np.linalg.svd(matrix, compute_uv=False)
    if not singular[-1] > SINGULAR * singular[0]:
        ratio = singular[0] / singular[-1] if singular[-1] > 0.0 else math.inf
        raise ValueError(f'{what} are singular (condition number {ratio:.3g}): a plane acts '
                         'on no sensor, or two planes act alike; no correction follows')
    return float(singular[0] / singular[-1])


def trial_weights_on(trials, planes, keep_trial=False):
    """
    Return the unbalance on per run and plane, (runs, planes) complex (kg m, or by hand).

    Run k has its own trial on, or with ``keep_trial`` every trial up to it; a trial in
    a plane not among ``planes`` adds nothing.
    """
    weights_on = np.zeros((len(trials), len(planes)), complex)
    for k, trial in enumerate(trials):
        if keep_trial and k > 0:
            weights_on[k] = weights_on[k - 1]
        if trial.plane in planes:
            weights_on[k, planes.index(trial.plane)] += trial.unbalance
    return weights_on


def _check(k, trial, baseline, readings, keep_trial, sigma_a, sigma_b):
    before = readings[k - 1] if keep_trial and k > 0 else baseline
    change = np.abs(readings[k] - before)
    largest = int(np.argmax(change))
    relative = float(np.max(change / np.maximum(np.abs(before), 1e-300)))
    if sigma_a is None:
        too_small = relative < TOO_SMALL_CHANGE
        return TrialCheck(k, trial.plane, float(change[largest]), None, relative, too_small,
                          False)
    sigma_before = sigma_b[k - 1] if keep_trial and k > 0 else sigma_a
    noise = np.sqrt(sigma_before ** 2 + sigma_b[k] ** 2)
    snr = float(np.max(change / np.maximum(noise, 1e-300)))
    return TrialCheck(k, trial.plane, float(change[largest]), snr, relative,
                      snr < TOO_SMALL_SNR, TOO_SMALL_SNR <= snr < WEAK_SNR)


def _warning(check, trial):
    what = f'trial run {check.run + 1} (plane {check.plane}, {trial.mass:g} at ' \
        f'{math.degrees(trial.angle):g} deg)'
    if check.snr is None:
        return (f'{what}: too small to see: the readings changed by at most '
                f'{check.relative:.1%} (under {TOO_SMALL_CHANGE:.0%}); its plane\'s '
                'coefficients and corrections are not to be trusted: use a trial weight '
                f'about {TOO_SMALL_CHANGE * 3 / max(check.relative, 1e-12):.3g} times heavier')
    factor = WEAK_SNR / max(check.snr, 1e-12)
    if check.too_small:
        return (f'{what}: too small to see: the largest change is {check.snr:.2g} standard '
                f'errors of the readings (under {TOO_SMALL_SNR:g}), within the noise; its '
                'plane\'s coefficients and corrections are not to be trusted: use a trial '
                f'weight about {factor:.3g} times heavier')
    return (f'{what}: weak: the largest change is {check.snr:.3g} standard errors (under '
            f'{WEAK_SNR:g}): the plane\'s coefficients are uncertain by about '
            f'{math.sqrt(CHI2_2DOF_95) / check.snr:.0%} (95 %); a trial weight about '
            f'{factor:.2g} times heavier would do')
