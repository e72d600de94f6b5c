"""
Tolerance stack of a layout's residual unbalance: Monte Carlo, RSS, worst case.

For each correction plane (or, without planes, the static unbalance: the
quantity the ISO verdict judges), from the exact derivatives
(:mod:`cvc_balance.design.sensitivity`) and the draws
(:mod:`cvc_balance.design.monte_carlo`):

* the Monte-Carlo distribution of |U| (mean, median, 95th and 99th percentile)
  and the probability that every plane is within its ISO 21940-11 allowance
  (the nominal rotor's, as a balancing specification states it);
* the linearised root-sum-square: sigma = sqrt(sum_p sigma_p^2 |dU/dp|^2),
  the RMS of |U - U_nominal| to first order;
* the worst case: |U_nominal| + sum over components of the largest change
  that component can make within its tolerances. Component k adds
  U_k = (f + c) e^{i theta} with f = m R (alpha + beta z) (alpha, beta: the
  plane's split of S and P) and c = beta p' (own products), so
  |dU_k| <= max |f - f_0| + |f_0 + c| 2 sin(t_theta / 2); f is multilinear in
  (m, R, z), so its extremes are at the corners of the tolerance box. The
  bound holds for every draw (draws stay within their tolerances), and to
  first order it is sum_p |dU/dp| t_p, the linear worst case, also given;
* each tolerance's share of the mean squared change sum |dU_p|^2 sigma_p^2,
  per plane, and in the plane that judges the rotor (the less likely to be
  within its allowance, or the larger p95 without a grade).

SI inside (kg m); the command line reports g mm.
"""

from dataclasses import dataclass
import itertools
import math

import numpy as np

from cvc_balance.design.monte_carlo import simulate
from cvc_balance.design.parameters import own_products
from cvc_balance.design.sensitivity import judged_vectors, sensitivities
from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.unbalance import two_plane_split


@dataclass(frozen=True)
class PlaneStack:
    """
    One judged plane's residual unbalance under tolerances, kg m.

    ``z`` m (None: the static unbalance, no planes); ``permissible`` kg m and
    ``probability_within`` None when there is no speed to judge at.
    """

    z: float
    nominal: float
    mean: float
    p50: float
    p95: float
    p99: float
    rms_change: float
    rss_sigma: float
    worst_case: float
    worst_case_linear: float
    max_drawn: float
    permissible: float
    probability_within: float


@dataclass(frozen=True)
class Contribution:
    """A tolerance's share of the mean squared change: judging plane, and per plane."""

    parameter: object
    share: float
    share_planes: tuple


@dataclass(frozen=True)
class StackResult:
    """A tolerance stack: planes, joint probability within grade, contributions."""

    planes: tuple
    probability_within_grade: float
    probability_stderr: float
    contributions: tuple
    judging_plane: int
    samples: int
    seed: int
    omega: float
    grade: float


def plane_weights(layout):
    """
    (alpha, beta) per judged plane: U = alpha S + beta P (S, P complex, about O).

    Read off :func:`cvc_balance.physics.unbalance.two_plane_split`; without
    correction planes, the static unbalance (1, 0).
    """
    planes = layout.correction_planes()
    if planes is None:
        return ((1.0, 0.0),)
    from_s = two_plane_split((1.0, 0.0), (0.0, 0.0), *planes)
    from_p = two_plane_split((0.0, 0.0), (1.0, 0.0), *planes)
    return tuple((s[0], p[0]) for s, p in zip(from_s, from_p))


def worst_case_bounds(layout, tolerances, own):
    """
    Bound the change each component can make in each judged plane: (n, n_planes), kg m.

    ``own`` (n, 2): the components' own products (kg m^2). See the module's
    description; exact bound, the linear worst case to first order.
    """
    mass, radius, angle, z = layout.placement
    t = tolerances.values
    bounds = []
    for alpha, beta in plane_weights(layout):
        f0 = mass * radius * (alpha + beta * z)
        corners = [(mass + sm * t[:, 0]) * (radius + sr * t[:, 1])
                   * (alpha + beta * (z + sz * t[:, 3])) - f0
                   for sm, sr, sz in itertools.product((-1.0, 1.0), repeat=3)]
        moved = np.max(np.abs(corners), axis=0)
        c = beta * own
        turned = np.hypot(f0 + c[:, 0], c[:, 1]) * 2.0 * np.sin(np.minimum(t[:, 2], math.pi)
                                                                / 2.0)
        bounds.append(moved + turned)
    return np.stack(bounds, axis=-1)


def analyse(model, tolerances, samples, seed, omega=None, grade=None):
    """
    Analyse the tolerance stack of ``model`` (a RotorModel) under ``tolerances``.

    ``samples`` Monte-Carlo draws from ``seed``; judged at ``omega`` rad/s
    (default: the layout's service speed; None: not judged) against
    ``grade`` mm/s (default the layout's). Returns :class:`StackResult`.
    """
    layout = model.layout
    if omega is None:
        omega = layout.balancing.service_speed
    sens = sensitivities(model)
    judged_d = judged_vectors(layout, sens.static, sens.products)
    nominal = judged_vectors(layout, np.array((model.s_x, model.s_y)),
                             np.array((model.p_xz, model.p_yz)))
    sigma = tolerances.sigma().reshape(-1)
    steep = np.hypot(judged_d[..., 0], judged_d[..., 1])           # (P, planes) |dU/dp|
    variance = (sigma[:, None] * steep) ** 2
    rss = np.sqrt(variance.sum(axis=0))
    nominal_amount = np.hypot(nominal[:, 0], nominal[:, 1])
    linear = nominal_amount + (tolerances.values.reshape(-1)[:, None] * steep).sum(axis=0)
    exact = nominal_amount + worst_case_bounds(layout, tolerances,
                                               own_products(layout)).sum(axis=0)
    draws = simulate(model, tolerances, samples, seed)
    vectors = judged_vectors(layout, draws.first_moment, draws.products)
    amounts = np.hypot(vectors[..., 0], vectors[..., 1])           # (N, planes)
    change = vectors - nominal
    rms_change = np.sqrt(np.mean(np.sum(change * change, axis=-1), axis=0))
    permissible, within, probability, stderr = None, None, None, None
    if omega is not None and omega > 0.0:
        assessment = assess_balance(model, omega, grade)
        grade = assessment.grade
        permissible = (assessment.plane_permissible if assessment.planes
                       else (assessment.permissible,))
        inside = amounts <= np.asarray(permissible)
        within = inside.mean(axis=0)
        probability = float(np.all(inside, axis=1).mean())
        stderr = math.sqrt(max(probability * (1.0 - probability), 1.0 / samples) / samples)
    percentiles = np.percentile(amounts, (50.0, 95.0, 99.0), axis=0)
    planes_z = layout.correction_planes() or (None,)
    planes = tuple(PlaneStack(
        planes_z[i], float(nominal_amount[i]), float(amounts[:, i].mean()),
        float(percentiles[0, i]), float(percentiles[1, i]), float(percentiles[2, i]),
        float(rms_change[i]), float(rss[i]), float(exact[i]), float(linear[i]),
        float(amounts[:, i].max()),
        None if permissible is None else float(permissible[i]),
        None if within is None else float(within[i])) for i in range(len(planes_z)))
    judging = (int(np.argmin(within)) if within is not None
               else int(np.argmax(percentiles[1])))
    total = variance.sum(axis=0)
    shares = variance / np.where(total > 0.0, total, 1.0)
    order = np.argsort(-shares[:, judging], kind='stable')
    contributions = tuple(Contribution(sens.parameters[p], float(shares[p, judging]),
                                       tuple(float(v) for v in shares[p]))
                          for p in order if sigma[p] > 0.0)
    return StackResult(planes, probability, stderr, contributions, judging, samples, seed,
                       omega, grade if grade is not None else layout.balancing.grade)
