"""
Correction weights at fixed sites, from a kit: the vector split and a mixed-integer plan.

A plane with :class:`~cvc_balance.physics.layout.WeightSites` takes weights only at its
sites' angles phi_k, at its radius R, in the kit's sizes m_s, at most ``stack`` per site;
n_jks weights of size s at site k of plane j add the unbalance n m_s R e^{i phi_k}. A plane
without sites takes its continuous correction (any mass, any angle).

* **Vector split** (the simple rule): each plane's continuous correction M e^{i psi} is
  shared between the two sites either side of psi, m_a e^{i phi_a} + m_b e^{i phi_b} =
  M e^{i psi}, and each share is rounded to the nearest stack the kit can make.
* **Mixed-integer plan** (scipy's HiGHS, :func:`scipy.optimize.milp`): integer counts
  n_jks that minimise the residual, sum_c w_c |r_c|, each |r_c| taken as the largest
  projection Re(r_c e^{-i theta_l}) on ``POLYGON`` directions (a regular polygon about
  the circle: within 1 - cos(pi / 32) = 0.48 % of |r_c| from below), then, among plans
  as good, the fewest weights. Its continuous relaxation is the continuous optimum, so
  HiGHS proves optimality only by enumeration: on a full kit it stops at ``time_limit``
  with the best plan found and its gap. Or (``objective='fewest'``) the fewest weights for which
  every |r_c| stays within its limit (the grade; the polygon inside the circle, so the
  limit holds exactly), then the smallest residual with that many.
"""

from dataclasses import dataclass
import math

import numpy as np

POLYGON = 32
"""Directions on which a complex residual's magnitude is measured in the plan."""
MIP_GAP = 1e-7
"""Relative optimality gap HiGHS closes before it stops."""
TIME_LIMIT = 60.0
"""Seconds HiGHS may search; the best plan found so far is kept, its gap reported."""
SAME_SITE = 1e-6
"""A weight on already within this angle of a site (rad) sits at that site."""
MAX_STACK_STATES = 200_000
"""Most partial sums the kit rounding enumerates (then it rounds greedily)."""


def _scipy_optimize():
    """scipy.optimize (HiGHS): imported when a plan is made, not at every command's start."""
    import scipy.optimize
    return scipy.optimize


@dataclass(frozen=True)
class PlacedWeight:
    """Weights stacked at one site: ``plane``, ``angle`` rad, ``radius`` m, ``masses`` kg."""

    plane: str
    angle: float
    radius: float
    masses: tuple

    @property
    def mass(self):
        """Return the total of the stack's weights, kg."""
        return float(sum(self.masses))

    @property
    def unbalance(self):
        """Return the stack's unbalance m R e^{i angle}, kg m."""
        return self.mass * self.radius * complex(math.cos(self.angle), math.sin(self.angle))


@dataclass(frozen=True)
class Plan:
    """
    A correction: ``weights`` at sites, ``free`` continuous corrections {plane: complex}.

    ``corrections`` (N,) complex: the unbalance added per plane; ``residual`` the
    :class:`~cvc_balance.field.correction.Residual` it leaves; ``status`` 'optimal',
    'time limit' (best found; ``gap`` its relative optimality gap), 'infeasible' (no
    plan meets the limits: no weights) or 'exact' (no search); ``note`` why a rule could
    not be applied (else ''); ``removed`` weights on already to take off (a trim).
    """

    name: str
    weights: tuple
    free: dict
    corrections: np.ndarray
    residual: object
    status: str = 'exact'
    gap: float = 0.0
    note: str = ''
    removed: tuple = ()

    @property
    def count(self):
        """Return the changes: weights to bolt on plus weights to take off."""
        return sum(len(w.masses) for w in self.weights + self.removed)


def continuous_plan(problem, correction):
    """Return the continuous correction (N,) complex as a :class:`Plan` with no sites."""
    correction = np.asarray(correction, complex)
    return Plan('continuous', (), dict(zip(problem.planes, correction.tolist())), correction,
                problem.measure(correction))


def split_plan(problem, sites, correction):
    """
    Return the vector split of the continuous ``correction`` at the ``sites``, as a Plan.

    ``sites``: {plane: WeightSites}. A plane whose sites leave a gap of half a turn or
    more around the correction's angle cannot be split: it keeps its continuous
    correction, and ``note`` says so.
    """
    weights, free, notes = [], {}, []
    added = np.zeros(len(problem.planes), complex)
    for j, plane in enumerate(problem.planes):
        plane_sites = sites.get(plane)
        if plane_sites is None:
            free[plane] = complex(correction[j])
            added[j] = correction[j]
            continue
        try:
            shares = vector_split(correction[j], plane_sites)
        except ValueError as error:
            notes.append(f'plane {plane}: {error}')
            free[plane] = complex(correction[j])
            added[j] = correction[j]
            continue
        for angle, mass in shares:
            masses = round_to_kit(mass, plane_sites)
            if masses:
                weight = PlacedWeight(plane, angle, plane_sites.radius, masses)
                weights.append(weight)
                added[j] += weight.unbalance
    return Plan('split', tuple(weights), free, added, problem.measure(added),
                note='; '.join(notes))


def vector_split(correction, sites):
    """
    Return ((phi_a, m_a), (phi_b, m_b)): the correction shared by the two sites around it.

    ``correction`` complex kg m; masses kg at ``sites.radius``; a share may be 0. Raises
    ValueError when the neighbouring sites are half a turn or more apart.
    """
    mass = abs(correction) / sites.radius
    if mass == 0.0:
        return ()
    psi = math.atan2(correction.imag, correction.real) % (2.0 * math.pi)
    angles = sorted(a % (2.0 * math.pi) for a in sites.angles)
    after = next((a for a in angles if a >= psi), angles[0] + 2.0 * math.pi)
    before = max((a for a in angles if a <= psi), default=angles[-1] - 2.0 * math.pi)
    if after - before < 1e-12:                       # exactly at a site
        return ((before % (2.0 * math.pi), mass),)
    gap = after - before
    if gap >= math.pi - 1e-9:
        raise ValueError(f'no vector split: the sites either side of {math.degrees(psi):.1f} '
                         f'deg are {math.degrees(gap):.1f} deg apart (half a turn or more)')
    share_before = mass * math.sin(after - psi) / math.sin(gap)
    share_after = mass * math.sin(psi - before) / math.sin(gap)
    return ((before % (2.0 * math.pi), share_before), (after % (2.0 * math.pi), share_after))


def round_to_kit(mass, sites):
    """
    Return the stack of kit weights (tuple of kg, heaviest first) nearest to ``mass`` kg.

    At most ``sites.stack`` weights of the sizes ``sites.masses``; () when none is nearest.
    """
    best = ((abs(mass), ()))
    level = {0.0: ()}
    states = 1
    for _ in range(sites.stack):
        grown = {}
        for total, stack in level.items():
            if total > mass:                 # adding more only goes further away
                continue
            for size in sites.masses:
                if stack and size > stack[-1]:
                    continue                 # each multiset once: sizes non-increasing
                key = round(total + size, 12)
                if key not in grown:
                    grown[key] = stack + (size,)
        for total, stack in grown.items():
            if abs(total - mass) < best[0]:
                best = (abs(total - mass), stack)
        states += len(grown)
        level = grown
        if states > MAX_STACK_STATES:
            return _greedy(mass, sites)
    return best[1]


def _greedy(mass, sites):
    stack, left = [], mass
    for _ in range(sites.stack):
        size = min(sites.masses, key=lambda s: abs(left - s))
        if abs(left - size) >= abs(left):
            break
        stack.append(size)
        left -= size
    return tuple(sorted(stack, reverse=True))


def optimal_plan(problem, sites, objective='residual', max_weights=None, polygon=POLYGON,
                 time_limit=TIME_LIMIT, mip_gap=MIP_GAP, method='auto', existing=()):
    """
    Return the mixed-integer :class:`Plan` (see the module's description).

    ``sites``: {plane: WeightSites}; planes without sites take free continuous
    corrections. ``objective``: 'residual' or 'fewest' (needs the problem's limits).
    ``method``: 'auto' (the smallest residual by :mod:`~cvc_balance.field.search` where it
    applies, else HiGHS), 'search' (None when it does not apply) or 'milp' (HiGHS).
    ``existing``: PlacedWeights on already (a trim): the plan may take them off, the
    counts are changes (added and taken off) and a site's stack holds for the loading after.
    """
    if objective not in ('residual', 'fewest'):
        raise ValueError(f"objective must be 'residual' or 'fewest', got {objective!r}")
    if objective == 'fewest' and problem.limits is None:
        raise ValueError('the fewest weights need a limit on the residual (a grade, or '
                         'limits on the readings)')
    if objective == 'residual' and method in ('auto', 'search') and not existing:
        found = _searched(problem, sites, max_weights, polygon)
        if found is not None or method == 'search':
            return found
    model = _Model(problem, sites, polygon, existing)
    cap = () if max_weights is None else (model.count_at_most(max_weights),)
    if objective == 'residual':
        first = model.solve(model.residual_cost(), cap, time_limit, mip_gap)
        if first.x is None:
            return model.failed(first)
        if first.status != 0:        # not proven optimal: fewer weights as good is moot
            return model.plan(first, _gap(first), 'time limit')
        bound = first.fun * (1.0 + 1e-7) + 1e-9
        second = model.solve(model.count_cost(), (model.residual_at_most(bound), *cap),
                             time_limit, mip_gap)
    else:
        limits = model.within_limits()
        first = model.solve(model.count_cost(), (limits, *cap), time_limit, mip_gap)
        if first.x is None:
            return model.failed(first)
        count = round(first.fun)
        second = model.solve(model.residual_cost(), (limits, model.count_at_most(count)),
                             time_limit, mip_gap)
    chosen = second if second.x is not None else first
    return model.plan(chosen, max(_gap(first), _gap(second)),
                      'optimal' if first.status == 0 and second.status == 0 else 'time limit')


def _searched(problem, sites, max_weights, polygon):
    """Return the smallest-residual Plan by pruned enumeration, or None where it does not go."""
    from cvc_balance.field.correction import continuous_correction
    from cvc_balance.field.search import search_plan

    incumbent = None
    if all(p in sites for p in problem.planes):
        split = split_plan(problem, sites, continuous_correction(problem))
        if max_weights is not None and split.count <= max_weights and not split.free:
            incumbent = split.corrections
    found = search_plan(problem, sites, max_weights, incumbent, polygon)
    if found is None:
        return None
    counts, _ = found
    return plan_of_counts(problem, sites, counts, 'optimal', 0.0)


def plan_of_counts(problem, sites, counts, status, gap):
    """Return the :class:`Plan` of {plane: {(angle, size): count}} at ``sites``."""
    added = np.zeros(len(problem.planes), complex)
    weights = []
    for j, plane in enumerate(problem.planes):
        stacks = {}
        for (angle, size), count in counts.get(plane, {}).items():
            stacks.setdefault(angle, []).extend([size] * count)
        for angle, masses in sorted(stacks.items()):
            weight = PlacedWeight(plane, angle % (2.0 * math.pi), sites[plane].radius,
                                  tuple(sorted(masses, reverse=True)))
            weights.append(weight)
            added[j] += weight.unbalance
    return Plan('optimal', tuple(weights), {}, added, problem.measure(added), status, gap)


def _gap(result):
    gap = getattr(result, 'mip_gap', None)
    return float(gap) if gap is not None and math.isfinite(gap) else 0.0


class _Model:
    """
    The plan's variables and constraints: counts n, free corrections (x, y), and t.

    Each slot is (plane index, WeightSites, angle, size, sign): +1 weights to add (0 to
    ``stack``), -1 weights on already that may be taken off (0 to how many are on).
    """

    def __init__(self, problem, sites, polygon, existing=()):
        optimize = _scipy_optimize()
        self.problem, self.sites = problem, sites
        channels, planes = problem.influence.shape
        self.slots = []
        upper_of = []
        self.free = []                        # plane indexes without sites
        site_rows = {}                        # (plane, angle): [(slot, sign)], limit
        on = {}
        for weight in existing:
            key = (weight.plane, _site_angle(sites, weight))
            for mass in weight.masses:
                on[key + (mass,)] = on.get(key + (mass,), 0) + 1
        for j, plane in enumerate(problem.planes):
            plane_sites = sites.get(plane)
            if plane_sites is None:
                self.free.append(j)
                continue
            for angle in plane_sites.angles:
                here = {m: c for (p, a, m), c in on.items() if p == plane and a == angle}
                rows = []
                for size in plane_sites.masses:
                    rows.append((len(self.slots), 1.0))
                    self.slots.append((j, plane_sites, angle, size, 1))
                    upper_of.append(plane_sites.stack)
                for size, count in sorted(here.items()):
                    rows.append((len(self.slots), -1.0))
                    self.slots.append((j, plane_sites, angle, size, -1))
                    upper_of.append(count)
                site_rows[(j, angle)] = (rows, plane_sites.stack - sum(here.values()))
        slots, free = len(self.slots), len(self.free)
        # Columns: the reading change per variable (complex), channels x variables.
        columns = np.zeros((channels, slots + 2 * free), complex)
        for v, (j, plane_sites, angle, size, sign) in enumerate(self.slots):
            columns[:, v] = problem.influence[:, j] * sign * size * plane_sites.radius \
                * complex(math.cos(angle), math.sin(angle))
        for f, j in enumerate(self.free):
            columns[:, slots + 2 * f] = problem.influence[:, j]
            columns[:, slots + 2 * f + 1] = 1j * problem.influence[:, j]
        self.columns = columns
        w = problem.weights
        scale = float(np.sum(w * np.abs(problem.baseline)))
        if not scale > 0.0:
            scale = float(np.max(w[:, None] * np.abs(columns))) if columns.size else 1.0
        self.scale = scale if scale > 0.0 else 1.0
        self.turns = np.exp(-2j * math.pi * np.arange(polygon) / polygon)
        self.cos_half = math.cos(math.pi / polygon)
        self.size = slots + 2 * free + channels
        self.slot_count, self.free_count, self.channels = slots, free, channels
        # Residual rows: Re(w_c e^{-i theta_l} r_c) / scale - t_c <= 0 for every c and l.
        projected = (w[:, None, None] * self.turns[None, :, None] * columns[:, None, :])
        rows = np.zeros((channels * polygon, self.size))
        rows[:, :slots + 2 * free] = projected.real.reshape(channels * polygon, -1) / scale
        rows[:, slots + 2 * free:] = -np.kron(np.eye(channels), np.ones((polygon, 1)))
        base = (w[:, None] * self.turns[None, :] * problem.baseline[:, None]).real / scale
        self.residual_rows = optimize.LinearConstraint(rows, -np.inf, -base.reshape(-1))
        # A site holds at most ``stack`` weights after: added - taken off <= stack - on.
        stacks = np.zeros((len(site_rows), self.size))
        limits = np.zeros(len(site_rows))
        for row, (entries, limit) in enumerate(site_rows.values()):
            for v, sign in entries:
                stacks[row, v] = sign
            limits[row] = limit
        self.stack_rows = (optimize.LinearConstraint(stacks, -np.inf, limits) if site_rows
                           else None)
        upper = np.full(self.size, np.inf)
        lower = np.full(self.size, -np.inf)
        lower[:slots], upper[:slots] = 0.0, upper_of
        lower[slots + 2 * free:] = 0.0
        self.bounds = optimize.Bounds(lower, upper)
        self.integrality = np.zeros(self.size)
        self.integrality[:slots] = 1

    def residual_cost(self):
        cost = np.zeros(self.size)
        cost[self.slot_count + 2 * self.free_count:] = 1.0
        return cost

    def count_cost(self):
        cost = np.zeros(self.size)
        cost[:self.slot_count] = 1.0
        return cost

    def residual_at_most(self, bound):
        optimize = _scipy_optimize()
        return optimize.LinearConstraint(self.residual_cost()[None, :], -np.inf, bound)

    def count_at_most(self, count):
        optimize = _scipy_optimize()
        return optimize.LinearConstraint(self.count_cost()[None, :], -np.inf, count + 0.5)

    def within_limits(self):
        optimize = _scipy_optimize()
        # Re(e^{-i theta_l} r_c) <= limit_c cos(pi / K): the polygon inside the circle.
        limited = np.flatnonzero(np.isfinite(self.problem.limits))
        limits = self.problem.limits[limited]
        channels, polygon = len(limited), len(self.turns)
        projected = self.turns[None, :, None] * self.columns[limited, None, :] \
            / limits[:, None, None]
        rows = np.zeros((channels * polygon, self.size))
        rows[:, :self.slot_count + 2 * self.free_count] = \
            projected.real.reshape(channels * polygon, -1)
        base = (self.turns[None, :] * self.problem.baseline[limited, None]).real \
            / limits[:, None]
        return optimize.LinearConstraint(rows, -np.inf, (self.cos_half - base).reshape(-1))

    def solve(self, cost, extra, time_limit, mip_gap):
        optimize = _scipy_optimize()
        constraints = [self.residual_rows, *extra]
        if self.stack_rows is not None:
            constraints.append(self.stack_rows)
        return optimize.milp(cost, integrality=self.integrality, bounds=self.bounds,
                             constraints=constraints,
                             options={'time_limit': time_limit, 'mip_rel_gap': mip_gap})

    def failed(self, result):
        status = 'infeasible' if result.status == 2 else 'time limit'
        empty = np.zeros(len(self.problem.planes), complex)
        return Plan('optimal', (), {}, empty, self.problem.measure(empty), status, math.inf,
                    note=f'HiGHS: {result.message}')

    def plan(self, result, gap, status):
        x = result.x
        counts = np.round(x[:self.slot_count]).astype(int)
        problem = self.problem
        added = np.zeros(len(problem.planes), complex)
        stacks = {1: {}, -1: {}}
        for v, (j, plane_sites, angle, size, sign) in enumerate(self.slots):
            if counts[v] > 0:
                stacks[sign].setdefault((j, angle), []).extend([size] * int(counts[v]))
        placed = {1: [], -1: []}
        for sign, groups in stacks.items():
            for (j, angle), masses in sorted(groups.items()):
                plane_sites = self.sites[problem.planes[j]]
                weight = PlacedWeight(problem.planes[j], angle % (2.0 * math.pi),
                                      plane_sites.radius, tuple(sorted(masses, reverse=True)))
                placed[sign].append(weight)
                added[j] += sign * weight.unbalance
        free = {}
        for f, j in enumerate(self.free):
            value = complex(x[self.slot_count + 2 * f], x[self.slot_count + 2 * f + 1])
            free[problem.planes[j]] = value
            added[j] += value
        return Plan('optimal', tuple(placed[1]), free, added, problem.measure(added), status,
                    gap, removed=tuple(placed[-1]))


def _site_angle(sites, weight):
    """Return the site angle (as the sites hold it) a weight on already sits at."""
    plane_sites = sites.get(weight.plane)
    if plane_sites is not None:
        for angle in plane_sites.angles:
            if abs(math.remainder(angle - weight.angle, 2.0 * math.pi)) < SAME_SITE:
                return angle
    raise ValueError(f'a weight on already at {math.degrees(weight.angle):g} deg in plane '
                     f'{weight.plane}: no site there')


def final_loading(existing, plan):
    """Return the loading after a plan: what is on, less what it takes off, plus what it adds."""
    loads = {}
    for weight in existing:
        loads.setdefault((weight.plane, round(weight.angle % (2 * math.pi), 9)),
                         [weight.radius, []])[1].extend(weight.masses)
    for weight in plan.removed:
        masses = loads[(weight.plane, round(weight.angle % (2 * math.pi), 9))][1]
        for mass in weight.masses:
            masses.remove(next(m for m in masses if abs(m - mass) < 1e-12))
    for weight in plan.weights:
        loads.setdefault((weight.plane, round(weight.angle % (2 * math.pi), 9)),
                         [weight.radius, []])[1].extend(weight.masses)
    return tuple(PlacedWeight(plane, angle, radius, tuple(sorted(masses, reverse=True)))
                 for (plane, angle), (radius, masses) in sorted(loads.items()) if masses)
