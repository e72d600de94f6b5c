"""
The smallest-residual weight plan by pruned enumeration: proven optimal, in seconds.

The mixed-integer plan's continuous relaxation is the continuous optimum, so HiGHS proves a
smallest-residual plan only by enumeration, slowly. Here the enumeration is done directly,
with bounds that cut almost all of it. The objective is the plan's own (the sum over the
channels of w_c g(r_c), g the magnitude measured on ``polygon`` directions:
g(r) = |r| cos(d), d the angle from arg r to the nearest direction), and it depends on a plan
only through the unbalance u_j each plane's weights add. For plane j alone, whatever the
other planes do,

    sum_c w_c g(r_c) >= cos(pi / K) ||w r||_2 >= cos(pi / K) ||P_j (w A + w alpha_j u_j)||_2,

P_j the projection away from the other planes' columns (their best continuous
corrections): a bound in closed form for every loading at once. Loadings of each plane are
made weight by weight (each stack once: slots in order, at most ``stack`` a site), and a
partial loading is dropped with all its completions when even the bound less the most its
remaining weights can move it (its Lipschitz constant times their largest effect) cannot
beat the best plan found; the pairs of the two planes' surviving loadings are then measured
exactly. The first best is the best plan with at most two weights a plane (or the vector
split), then every bound uses the improving best. One or two planes, every plane with
sites, at most ``max_weights`` weights; :func:`search_plan` returns None when the
enumeration would be too large (the caller uses HiGHS).
"""

import math

import numpy as np

MAX_LOADINGS = 3_000_000
"""Most loadings of one plane kept at one count before the search gives way to HiGHS."""
TIE = 1e-7
"""Plans within this share of the best count as equal; then the fewest weights wins."""


def gauge_sum(residuals, directions):
    """
    Return sum_c g(r_c) of weighted residuals (n, C): |r| cos of the angle to the polygon.

    g(r) = max_l Re(r e^{-i 2 pi l / K}) for K = ``directions``.
    """
    step = 2.0 * math.pi / directions
    phase = np.mod(np.angle(residuals), step)
    return np.sum(np.abs(residuals) * np.cos(np.minimum(phase, step - phase)), axis=-1)


class _Plane:
    """One plane's loadings by count: unbalance, and how each was made (parent, slot)."""

    def __init__(self, sites):
        self.sites = sites
        self.slots = [(angle, size) for angle in sites.angles for size in sites.masses]
        self.effect = np.array([size * sites.radius * complex(math.cos(angle), math.sin(angle))
                                for angle, size in self.slots])
        self.site = np.repeat(np.arange(len(sites.angles)), len(sites.masses))
        self.largest = float(np.max(np.abs(self.effect)))
        # Per count: unbalance, last slot, run of weights at the last site, parent index.
        self.levels = [(np.zeros(1, complex), np.full(1, -1), np.zeros(1, np.int64),
                        np.full(1, -1))]

    def grow(self, keep=None):
        """
        Add one weight to each loading of the last count; keep the new ones ``keep`` takes.

        ``keep``: a function of the new loadings' unbalance (array) to bool, or None (all).
        Return False (nothing added) when that would make over :data:`MAX_LOADINGS`.
        """
        u, last, run, _ = self.levels[-1]
        parents = np.arange(len(u))
        grown, made = [], 0
        for slot in range(len(self.slots)):
            fits = parents[last[parents] <= slot]
            same = self.site[np.maximum(last[fits], 0)] == self.site[slot]
            same &= last[fits] >= 0
            runs = np.where(same, run[fits] + 1, 1)
            fits, runs = fits[runs <= self.sites.stack], runs[runs <= self.sites.stack]
            if keep is not None:
                wanted = keep(u[fits] + self.effect[slot])
                fits, runs = fits[wanted], runs[wanted]
            made += len(fits)
            if made > MAX_LOADINGS:
                return False
            grown.append((u[fits] + self.effect[slot], np.full(len(fits), slot), runs, fits))
        self.levels.append(tuple(np.concatenate(parts) for parts in zip(*grown)))
        return True

    def loading(self, count, index):
        """Return {(angle, size): how many} of loading ``index`` of ``count`` weights."""
        out = {}
        for level in range(count, 0, -1):
            _, last, _, parent = self.levels[level]
            key = self.slots[int(last[index])]
            out[key] = out.get(key, 0) + 1
            index = int(parent[index])
        return out


def search_plan(problem, sites, max_weights, incumbent=None, directions=32):
    """
    Return ({plane: {(angle, size): count}}, objective) of the best plan, or None.

    ``problem`` a BalancingProblem whose planes (one or two) all have ``sites``;
    ``max_weights`` the most weights in all; ``incumbent`` (N,) complex corrections of a
    plan to start the bound from (the vector split), or None. None when the search does not
    apply or would be too large.
    """
    planes = problem.planes
    if max_weights is None or not 1 <= len(planes) <= 2 or any(p not in sites for p in planes):
        return None
    used = problem.weights > 0.0
    weights = problem.weights[used]
    base = weights * problem.baseline[used]
    columns = weights[:, None] * problem.influence[used]
    cos_half = math.cos(math.pi / directions)

    def measure(*u):
        r = base + sum(columns[:, j][None, :] * np.asarray(v)[:, None] for j, v in enumerate(u))
        return gauge_sum(r, directions)

    bounds = [_bound(base, columns, j, cos_half) for j in range(len(planes))]
    loads = [_Plane(sites[p]) for p in planes]
    best = math.inf
    if incumbent is not None:
        best = float(measure(*[[value] for value in incumbent])[0])
    # First the loadings of at most two weights a plane: a good plan to bound the rest by.
    first = min(2, max_weights)
    for count in range(first):
        for plane in loads:
            plane.grow()
    best = min(best, _quick(loads, bounds, measure, max_weights))
    best = min(best, _pairs(loads, bounds, measure, max_weights, best)[0])
    for count in range(first, max_weights):
        # A loading of count + 1 weights is kept while it or a completion (at most the
        # weights left, each moving the bound by at most its slope times the largest
        # weight's effect) could still beat the best.
        for plane, (value, slope) in zip(loads, bounds):
            reach = cos_half * slope * (max_weights - count - 1) * plane.largest
            limit = best * (1.0 + TIE) + reach

            def keep(u, value=value, limit=limit):
                return value(u) < limit
            if not plane.grow(keep):
                return None
    found, choice = _pairs(loads, bounds, measure, max_weights, best)
    if choice is None:
        return None
    counts = {}
    for plane, name, (count, index) in zip(loads, planes, choice):
        counts[name] = plane.loading(count, index)
    return counts, found


def _quick(loads, bounds, measure, most, top=40):
    """Return the objective of the best pair among each plane's ``top`` loadings by bound."""
    picks = []
    for plane, (value, _) in zip(loads, bounds):
        u = np.concatenate([level[0] for level in plane.levels])
        count = np.concatenate([np.full(len(level[0]), c) for c, level in
                                enumerate(plane.levels)])
        order = np.argsort(value(u))[:top]
        picks.append((u[order], count[order]))
    if len(picks) == 1:
        u, count = picks[0]
        return float(np.min(measure(u[count <= most]), initial=math.inf))
    (u1, c1), (u2, c2) = picks
    fits = (c1[:, None] + c2[None, :]) <= most
    first, second = np.nonzero(fits)
    return float(np.min(measure(u1[first], u2[second]), initial=math.inf))


def _bound(base, columns, j, cos_half):
    """
    Return (bound(u), slope): cos(pi/K) ||P_j (base + column_j u)||, and its Lipschitz factor.

    P_j projects away from the other planes' columns (their continuous corrections).
    """
    others = np.delete(columns, j, axis=1)
    if others.shape[1]:
        basis, _ = np.linalg.qr(others)

        def away(v):
            return v - basis @ (basis.conj().T @ v)
    else:
        def away(v):
            return v
    v0, v1 = away(base), away(columns[:, j])
    a, b, c = np.vdot(v0, v0).real, np.vdot(v1, v1).real, np.vdot(v1, v0)

    def value(u):
        square = a + b * np.abs(u) ** 2 + 2.0 * np.real(np.conj(u) * c)
        return cos_half * np.sqrt(np.maximum(square, 0.0))
    return value, math.sqrt(b)


def _pairs(loads, bounds, measure, most, best):
    """
    Return (best objective, ((count, index) per plane) or None) over surviving pairs.

    Loadings of plane j whose bound is not under ``best`` (with the tie share) are left
    out; among plans within the tie share of the best, the fewest weights.
    """
    limit = best * (1.0 + TIE) + 1e-300
    alive = [[np.flatnonzero(value(level[0]) < limit) for level in plane.levels]
             for plane, (value, _) in zip(loads, bounds)]
    found = []                                  # (objective, weights, choice)
    if len(loads) == 1:
        for count, index in enumerate(alive[0]):
            if count <= most and len(index):
                g = measure(loads[0].levels[count][0][index])
                k = int(np.argmin(g))
                found.append((float(g[k]), count, ((count, int(index[k])),)))
    else:
        for c1, first in enumerate(alive[0]):
            for c2, second in enumerate(alive[1][:most - c1 + 1]):
                if not len(first) or not len(second):
                    continue
                u2 = loads[1].levels[c2][0][second]
                for start in range(0, len(first), max(1, 200_000 // len(second))):
                    part = first[start:start + max(1, 200_000 // len(second))]
                    u1 = loads[0].levels[c1][0][part]
                    g = measure(np.repeat(u1, len(u2)), np.tile(u2, len(u1)))
                    k = int(np.argmin(g))
                    found.append((float(g[k]), c1 + c2,
                                  ((c1, int(part[k // len(u2)])), (c2, int(second[k % len(u2)])))))
    if not found:
        return best, None
    smallest = min(f[0] for f in found)
    near = [f for f in found if f[0] <= smallest * (1.0 + TIE) + 1e-12]
    value, _, choice = min(near, key=lambda f: (f[1], f[0]))
    return value, choice
