"""
No more model than a scene needs: the smallest engine model within a stated tolerance.

The full model (rigid bodies, with the bearing-moment terms) is cut along two lines,
each only where a worst-case bound over the scene's motion envelope (|omega| <=
omega_max, |alpha| <= alpha_max, the layout's gravity) shows that no asked output moves
by more than its tolerance:

* point masses: the components' own inertia dropped (the aggregation skips turning and
  summing n tensors). Forces never depend on it (Newton: only m and S, as the thesis's
  Ch. 5 finds); it enters the moments through the own products P_xz, P_yz (non-zero
  only for components given by a tensor with xz, yz products: the shapes are symmetric
  about their own axes) and the drive torque through the own I_zz:
  |dM| <= (alpha_max + omega_max^2) sum |(I_xz, I_yz)|, |dtau| <= alpha_max sum I_zz;
* planar: the moment terms not evaluated (M_x = M_y = 0: the thesis's F1 = F2, kept
  only where true): |dM| <= |S_xy| |g_z| + |S_z| |g_xy| + (alpha_max + omega_max^2) |P|.
  With two supports each support force moves by |dM| / span; with one, its moment by
  |dM|.

Cheapest first: point masses and planar; rigid bodies and planar; point masses; rigid
bodies (the per-sample saving of dropping moments outweighs the one-off aggregation).
A tolerance of inf means the output is not asked for.
"""

from dataclasses import dataclass
import math

import numpy as np

from cvc_balance.physics.engine import own_elements, RotorModel, support_loads
from cvc_balance.physics.frames import tensors_from_elements


@dataclass(frozen=True)
class Tolerance:
    """Largest change the user accepts in each output: N, N m, N m (inf: not asked)."""

    force: float = math.inf      # total force and each support's force
    moment: float = math.inf     # moment about O, and a single support's moment
    torque: float = math.inf     # drive torque


@dataclass(frozen=True)
class Envelope:
    """The motion a scene covers: |omega| <= omega_max (rad/s), |alpha| <= alpha_max."""

    omega_max: float
    alpha_max: float = 0.0


@dataclass(frozen=True)
class Deviation:
    """Worst-case change of the outputs from the full model's: N, N m, N m."""

    force: float
    moment: float
    torque: float

    def within(self, tolerance):
        """Return True when every change is within ``tolerance``."""
        return (self.force <= tolerance.force and self.moment <= tolerance.moment
                and self.torque <= tolerance.torque)


MODELS = (('point masses, planar', False, False), ('rigid bodies, planar', True, False),
          ('point masses', False, True), ('rigid bodies', True, True))
"""(name, own inertia, moment terms), cheapest first."""


@dataclass(frozen=True)
class ModelChoice:
    """The model taken, why, and its worst-case deviation from the full model."""

    name: str
    model: RotorModel
    deviation: Deviation
    tolerance: Tolerance
    envelope: Envelope

    def describe(self):
        """One line for people: which model, and what it may change by."""
        d, t, e = self.deviation, self.tolerance, self.envelope
        return (f'model: {self.name} (worst case over |omega| <= {e.omega_max:g} rad/s, '
                f'|alpha| <= {e.alpha_max:g} rad/s^2: force {d.force:.3g} N, moment '
                f'{d.moment:.3g} N m, torque {d.torque:.3g} N m; tolerance {t.force:g} N, '
                f'{t.moment:g} N m, {t.torque:g} N m)')


def choose_model(layout, tolerance, envelope, gravity=None):
    """
    Return the cheapest :class:`ModelChoice` whose deviation is within ``tolerance``.

    ``gravity``: stator-frame m/s^2 the scene runs under (default the layout's).

    The bounds come from one float64 pass over the components (a few numpy calls,
    with a margin for its rounding); only the chosen model is then aggregated.
    """
    comps = layout.components
    mass, radius, angle, z = layout.placement
    own = np.array([own_elements(c) for c in comps], float).reshape(-1, 6)
    m_x, m_y = mass * radius * np.cos(angle), mass * radius * np.sin(angle)
    s_xy, s_z = math.hypot(m_x.sum(), m_y.sum()), abs(float((mass * z).sum()))
    p_point = math.hypot(float((m_x * z).sum()), float((m_y * z).sum()))
    dynamic = envelope.alpha_max + envelope.omega_max ** 2
    own_products = float(np.hypot(own[:, 4], own[:, 5]).sum())     # |(ixz, iyz)|
    own_zz = float(own[:, 2].sum())
    g_x, g_y, g_z = layout.gravity if gravity is None else gravity
    g_xy = math.hypot(g_x, g_y)
    # |M| of the full model, and the float64 pass's rounding at most (n + 2) eps of
    # the sums of magnitudes.
    magnitude = (mass * radius).sum() * (abs(g_z) + dynamic * np.abs(z).max(initial=0.0)) \
        + (mass * np.abs(z)).sum() * g_xy
    slack = (len(comps) + 2) * np.finfo(float).eps * float(magnitude)
    full_moment = (s_xy * abs(g_z) + s_z * g_xy + dynamic * (p_point + own_products)
                   + slack)
    for name, with_own, with_moments in MODELS:
        moment = (0.0 if with_own else dynamic * own_products) if with_moments \
            else full_moment
        deviation = Deviation(_support_force(layout.supports, moment), moment,
                              0.0 if with_own else envelope.alpha_max * own_zz)
        if deviation.within(tolerance) or name == MODELS[-1][0]:
            model = RotorModel.from_layout(
                layout, with_own, with_moments,
                own_tensors=tensors_from_elements(own) if with_own else None)
            return ModelChoice(name, model, deviation, tolerance, envelope)


def _support_force(supports, moment):
    # A moment alone, split as the engine splits loads: two supports take it as opposite
    # forces (|dM| / span each); one takes it whole, as a moment.
    per_support = support_loads(supports, 0.0, 0.0, 0.0, moment, 0.0)
    return max(math.hypot(*force) for force, _ in per_support)
