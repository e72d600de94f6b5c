"""
Tolerance allocation: which tolerances to tighten, and how far, to meet the grade.

Cost model (stated): a tolerance costs in inverse proportion to its width, and
as given it costs 1: cost = sum over toleranced parameters of t_given / t.
Tolerances are only tightened (t <= t_given).

Under the linearised model the plane unbalances are Gaussian with variance
sum_p sigma_p^2 J_p J_p^T (J_p = dU/dp). Minimising sum c_p / t_p under one
weighted variance budget sum_p g_p^2 t_p^2 <= V gives, with the bounds
t_p <= t_given (KKT of a separable convex problem),

    t_p = min(t_given_p, lambda (c_p / g_p^2)^(1/3)),  c_p = t_given_p,

where g_p^2 = sum over planes of w_plane (sigma_p / t_p)^2 |J_p,plane|^2 / A_plane^2
(A: the plane's allowance). The split w = (1 - rho, rho) of the budget between
the two planes and lambda are searched: for each rho, lambda by bisection
until the Gaussian probability of meeting the grade reaches the target; the
least cost wins. The result is then checked by the exact Monte Carlo
(:mod:`cvc_balance.design.monte_carlo`) and lambda lowered until that meets
the target too.
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.design.sensitivity import judged_vectors, sensitivities
from cvc_balance.design.stack import analyse
from cvc_balance.design.tolerances import NORMAL_SIGMA, Tolerances, UNIFORM_SIGMA
from cvc_balance.physics.assessment import assess_balance

GAUSSIAN_DRAWS = 20000
"""Draws of the Gaussian estimate used in the search (common to every candidate)."""
SPLITS = 21
"""Budget splits rho tried between the two planes."""


@dataclass(frozen=True)
class ToleranceChange:
    """One parameter's tolerance, given and proposed (SI), and the factor given / proposed."""

    parameter: object
    given: float
    proposed: float

    @property
    def factor(self):
        """How many times tighter the proposal is (1: unchanged)."""
        return self.given / self.proposed if self.proposed > 0.0 else math.inf


@dataclass(frozen=True)
class Allocation:
    """
    A proposed set of tolerances and what it achieves.

    ``changes``: every toleranced parameter (tightest first); ``tolerances``
    the proposal (:class:`cvc_balance.design.tolerances.Tolerances`);
    probabilities from the exact Monte Carlo with their standard errors.
    """

    target: float
    changes: tuple
    tolerances: object
    cost_given: float
    cost_proposed: float
    probability_given: float
    probability_proposed: float
    stderr_proposed: float
    samples: int


def allocate(model, tolerances, target, samples, seed, omega=None, grade=None):
    """
    Propose tolerances for ``model`` that meet the grade with probability ``target``.

    ``omega`` rad/s (default the layout's service speed) and ``grade`` mm/s
    (default the layout's) give the allowances. Raises ValueError (one line)
    when the target cannot be reached: no speed, or the nominal layout itself
    out of grade.
    """
    layout = model.layout
    if omega is None:
        omega = layout.balancing.service_speed
    if omega is None or not omega > 0.0:
        raise ValueError('allocation needs a speed to judge the grade at: give --omega or '
                         'the layout a balancing.service_speed')
    assessment = assess_balance(model, omega, grade)
    allowed = np.asarray(assessment.plane_permissible if assessment.planes
                         else (assessment.permissible,))
    nominal = judged_vectors(layout, np.array((model.s_x, model.s_y)),
                             np.array((model.p_xz, model.p_yz)))
    amount = np.hypot(nominal[:, 0], nominal[:, 1])
    if np.any(amount >= allowed):
        worst = int(np.argmax(amount / allowed))
        raise ValueError(f'target probability cannot be reached: the nominal layout is out '
                         f'of G {assessment.grade:g} ({_plane_name(layout, worst)} '
                         f'{amount[worst] * 1e6:.4g} g mm > {allowed[worst] * 1e6:.4g} g mm '
                         'allowed); balance it first (cvc-balance balance)')
    given = analyse(model, tolerances, samples, seed, omega, grade)
    sens = sensitivities(model)
    steep = judged_vectors(layout, sens.static, sens.products)     # (P, planes, 2)
    t_given = tolerances.values.reshape(-1)
    per_unit = np.repeat(np.where(tolerances.normal, NORMAL_SIGMA, UNIFORM_SIGMA), 4)
    active = t_given > 0.0
    search = _Search(nominal, allowed, steep, per_unit, t_given, active, seed)
    if given.probability_within_grade >= target:
        proposed, result = t_given.copy(), given
    else:
        shape, lam = search.least_cost(target)
        proposed, result = _verified(model, tolerances, search, shape, lam, target, samples,
                                     seed, omega, grade)
    cost = (lambda t: float(np.sum(t_given[active] / t[active])))
    changes = sorted((ToleranceChange(p, float(t_given[i]), float(proposed[i]))
                      for i, p in enumerate(sens.parameters) if active[i]),
                     key=lambda change: -change.factor)
    return Allocation(target, tuple(changes), _with_values(tolerances, proposed),
                      cost(t_given), cost(proposed), given.probability_within_grade,
                      result.probability_within_grade, result.probability_stderr, samples)


class _Search:
    """The Gaussian estimate and the least-cost search over (rho, lambda)."""

    def __init__(self, nominal, allowed, steep, per_unit, t_given, active, seed):
        self.nominal, self.allowed, self.steep = nominal, allowed, steep
        self.per_unit, self.t_given, self.active = per_unit, t_given, active
        dims = steep.shape[1] * 2
        self.normal = np.random.default_rng(seed).standard_normal((GAUSSIAN_DRAWS, dims))
        # Per parameter and plane: (sigma_p / t_p)^2 |J_p,plane|^2 / A_plane^2.
        self.weight = (per_unit[:, None] ** 2 * np.sum(steep ** 2, axis=-1)
                       / allowed[None, :] ** 2)

    def probability(self, t):
        """Gaussian (linearised) probability that every plane is within its allowance."""
        flat = self.steep.reshape(len(t), -1) * (self.per_unit * t)[:, None]
        covariance = flat.T @ flat
        jitter = 1e-30 + 1e-14 * np.trace(covariance)
        factor = np.linalg.cholesky(covariance + jitter * np.eye(len(covariance)))
        draws = (self.normal @ factor.T).reshape(GAUSSIAN_DRAWS, -1, 2) + self.nominal
        inside = np.hypot(draws[..., 0], draws[..., 1]) <= self.allowed
        return float(np.all(inside, axis=1).mean())

    def shape(self, rho):
        """Tolerances per unit lambda for the budget split rho: (t_given / g^2)^(1/3)."""
        split = np.array([1.0 - rho, rho]) if self.weight.shape[1] == 2 else np.ones(1)
        g2 = self.weight @ split
        with np.errstate(divide='ignore'):
            return np.where(g2 > 0.0, np.cbrt(self.t_given / g2), np.inf)

    def tolerances(self, shape, lam):
        """t_p = min(t_given, lambda shape_p) (untoleranced parameters stay exact)."""
        return np.where(self.active, np.minimum(self.t_given, lam * shape), 0.0)

    def least_cost(self, target):
        """(shape, lambda) of least cost whose Gaussian probability reaches ``target``."""
        best = None
        splits = np.linspace(0.0, 1.0, SPLITS) if self.weight.shape[1] == 2 else (0.0,)
        for rho in splits:
            shape = self.shape(rho)
            finite = shape[self.active & np.isfinite(shape)]
            if not finite.size:
                continue
            # lambda_high: every tolerance at its given value; lambda_low: all tight.
            high = float(np.max(self.t_given[self.active & np.isfinite(shape)] / finite))
            low = high * 1e-6
            for _ in range(40):
                middle = math.sqrt(low * high)
                if self.probability(self.tolerances(shape, middle)) >= target:
                    low = middle
                else:
                    high = middle
            t = self.tolerances(shape, low)
            cost = float(np.sum(self.t_given[self.active] / t[self.active]))
            if best is None or cost < best[0]:
                best = (cost, shape, low)
        return best[1], best[2]


def _verified(model, tolerances, search, shape, lam, target, samples, seed, omega, grade):
    """Lower lambda until the exact Monte Carlo (its own seed) meets ``target``."""
    for _ in range(80):
        t = search.tolerances(shape, lam)
        result = analyse(model, _with_values(tolerances, t), samples, seed + 1, omega, grade)
        if result.probability_within_grade >= target:
            return t, result
        lam *= 0.97
    raise ValueError(f'target probability {target:g} not reached by the Monte Carlo: raise '
                     '--samples or lower the target')


def _with_values(tolerances, flat):
    return Tolerances(np.asarray(flat, dtype=float).reshape(-1, 4), tolerances.normal)


def _plane_name(layout, index):
    if layout.correction_planes() is None:
        return 'static unbalance'
    return ('plane I', 'plane II')[index]
