"""
Balance point: the free parameters that zero (or minimise) the dynamic unbalance.

The residual is the unbalance VECTOR in each correction plane (U_I, U_II, kg m;
the static unbalance without planes), which is smooth in every parameter, so
the solve is a smooth least-squares problem (scipy's trust-region reflective
method, with the exact Jacobian of :mod:`cvc_balance.design.sensitivity` and
the layout contract's bounds: mass > 0, radius >= 0), not a search on the
norm's kink. How sensitive the solution is:

* the Jacobian at the solution: how far each free parameter's error moves
  each plane (and so how far each may miss its value, alone, within the
  grade's allowance);
* the implicit-function derivatives d(solution)/d(other parameter) =
  -J_free^+ J_other: where the free parameters must go when another
  component's mass, radius, angle or z is not its nominal value;
* the singular values of the Jacobian with each free parameter scaled by its
  typical tolerance (kg m): a small one is a combination of ordinary misses
  that barely moves the planes, i.e. a solution the planes hardly fix.
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.design.parameters import all_parameters, value_of, with_values
from cvc_balance.design.sensitivity import judged_vectors, sensitivities
from cvc_balance.design.tolerances import typical_tolerances
from cvc_balance.physics.assessment import assess_balance
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.frames import wrap_angle

BALANCED = 1e-12
"""A solution is balanced when every plane is within this fraction of sum m R."""


@dataclass(frozen=True)
class BalanceSolution:
    """
    The solved free parameters and how sensitive they are.

    ``start``, ``values``: SI (angles rad, within half a turn of the start when
    unbounded); ``planes``
    (n, 2) judged vectors at the solution (kg m); ``jacobian`` (n_free, n, 2)
    kg m per unit; ``moves_with`` (n_free, n_other) d(value)/d(other);
    ``singular_values`` of the Jacobian times the typical tolerances (kg m);
    ``permissible`` kg m per plane (None without a speed); ``balanced``:
    every plane within :data:`BALANCED` of the size.
    """

    free: tuple
    start: np.ndarray
    values: np.ndarray
    layout: object
    planes: np.ndarray
    size: float
    balanced: bool
    jacobian: np.ndarray
    singular_values: np.ndarray
    others: tuple
    moves_with: np.ndarray
    permissible: np.ndarray
    within_grade: bool
    evaluations: int


def solve_balance(layout, free, omega=None, grade=None, bounds=None):
    """
    Solve ``layout`` for the ``free`` DesignParameters that balance it.

    Starts from the layout's values. ``bounds``: (lower, upper) arrays (SI)
    within the layout contract's, or None (the contract's). ``omega`` rad/s
    (default: the layout's service speed) and ``grade`` judge the solution
    against the ISO allowance when there is a speed.
    """
    free = tuple(dict.fromkeys(free))
    if not free:
        raise ValueError('give at least one free parameter (COMPONENT.PARAMETER)')
    start = np.array([value_of(layout, p) for p in free])
    lower = np.array([_lower(p) for p in free])
    upper = np.full(len(free), np.inf)
    if bounds is not None:
        lower = np.maximum(lower, bounds[0])
        upper = np.asarray(bounds[1], dtype=float)
    start = np.clip(start, lower, upper)

    def model_at(x):
        return RotorModel.from_layout(with_values(layout, dict(zip(free, x))))

    def residual(x):
        model = model_at(x)
        return judged_vectors(layout, np.array((model.s_x, model.s_y)),
                              np.array((model.p_xz, model.p_yz))).reshape(-1)

    def jacobian(x):
        return _jacobian(model_at(x), free).reshape(len(free), -1).T

    from scipy.optimize import least_squares   # here: scipy costs every command 1-2 s to import
    scale = np.sum(np.abs(layout.placement[0] * layout.placement[1]))
    fit = least_squares(residual, start, jac=jacobian, bounds=(lower, upper),
                        method='trf', x_scale='jac', xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=200 * len(free))
    # Angles within half a turn of where they started, unless bounded (a sweep's range).
    values = np.array([s + wrap_angle(float(v) - s) if p.name == 'angle' and bounds is None
                       else float(v) for p, v, s in zip(free, fit.x, start)])
    solved = with_values(layout, dict(zip(free, values)))
    model = RotorModel.from_layout(solved)
    planes = residual(values).reshape(-1, 2)
    sens = sensitivities(model)
    rows = {p: i for i, p in enumerate(sens.parameters)}
    steep = judged_vectors(layout, sens.static, sens.products)     # (P, n, 2)
    free_rows = [rows[p] for p in free]
    others = tuple(p for p in all_parameters(layout) if p not in set(free))
    j_free = steep[free_rows].reshape(len(free), -1).T
    j_other = steep[[rows[p] for p in others]].reshape(len(others), -1).T
    moves_with = -np.linalg.pinv(j_free) @ j_other
    typical = typical_tolerances(layout).values.reshape(-1)
    permissible, within = None, None
    if omega is None:
        omega = layout.balancing.service_speed
    if omega is not None and omega > 0.0:
        assessment = assess_balance(model, omega, grade)
        permissible = np.asarray(assessment.plane_permissible if assessment.planes
                                 else (assessment.permissible,))
        within = assessment.within_grade
    amounts = np.hypot(planes[:, 0], planes[:, 1])
    return BalanceSolution(free, start, values, solved, planes, float(scale),
                           bool(np.all(amounts <= BALANCED * scale)), steep[free_rows],
                           np.linalg.svd(j_free * typical[free_rows], compute_uv=False),
                           others, moves_with, permissible, within, int(fit.nfev))


def _jacobian(model, free):
    sens = sensitivities(model)
    rows = {p: i for i, p in enumerate(sens.parameters)}
    index = [rows[p] for p in free]
    return judged_vectors(model.layout, sens.static[index], sens.products[index])


def _lower(parameter):
    """Return the layout contract's lower bound of a parameter (mass > 0, radius >= 0)."""
    if parameter.name == 'mass':
        return 1e-12
    if parameter.name == 'radius':
        return 0.0
    return -math.inf
