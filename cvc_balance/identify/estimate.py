"""
The identified unbalance as a service engineer reads it: static, couple, per plane.

From a fit (:class:`~cvc_balance.identify.fit.Estimate`: S and P about O) and the layout's
model (its mass and axial centre of mass, which load cells cannot see, and its correction
planes), the same quantities :mod:`cvc_balance.physics.unbalance` gives for a layout, each
with the radius of its 95 % circle. The maps from (S, P) to those quantities are taken
from that module (evaluated on unit aggregates), not written again here.
"""

from dataclasses import dataclass
import math
from types import SimpleNamespace

from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance


@dataclass(frozen=True)
class UnbalanceVector:
    """A planar unbalance vector, complex (x + i y, rotor frame), and its 95 % radius."""

    value: complex
    ci95: float = 0.0

    @property
    def amount(self):
        """Return |value| (its units: kg m, kg m^2)."""
        return abs(self.value)

    @property
    def angle(self):
        """Return its angle, rad, from rotor X toward rotor Y."""
        return math.atan2(self.value.imag, self.value.real)


@dataclass(frozen=True)
class RotorUnbalance:
    """
    Static (kg m), couple about the centre of mass (kg m^2) and per-plane (kg m) unbalance.

    ``planes``: ((z_I, vector), (z_II, vector)) or () without two correction planes.
    ``identifiable`` False when the readings could not tell (every ci95 inf).
    """

    static: UnbalanceVector
    couple: UnbalanceVector
    planes: tuple
    identifiable: bool = True


def rotor_with(model, static, products):
    """
    Return ``model`` (a RotorModel) with its S and P replaced: the rotor the cells measured.

    A value with the attributes the unbalance and the verdict read (``layout``, ``mass``,
    ``s_x``, ``s_y``, ``s_z``, ``p_xz``, ``p_yz``): load cells cannot see the mass and
    the axial centre of mass, which stay the layout's.
    """
    return SimpleNamespace(layout=model.layout, mass=model.mass, s_z=model.s_z,
                           s_x=static.real, s_y=static.imag, p_xz=products.real,
                           p_yz=products.imag)


def _weights(model, quantity):
    """Complex weights (w_S, w_P) of a quantity linear in (S, P), from unit aggregates."""
    unit_s = quantity(rotor_with(model, 1.0 + 0j, 0j))
    unit_p = quantity(rotor_with(model, 0j, 1.0 + 0j))
    zero = quantity(rotor_with(model, 0j, 0j))
    return tuple(complex(*unit) - complex(*zero) for unit in (unit_s, unit_p))


def _plane_vectors(model):
    planes = model.layout.correction_planes()
    if planes is None:
        return ()

    def plane(k):
        def vector(aggregates):
            chosen = plane_unbalances(aggregates, *planes, 1.0)[k]
            return chosen.vector
        return vector
    return tuple((planes[k], plane(k)) for k in range(2))


def unbalance_from(model, static, products, ci95_of=None, identifiable=True):
    """
    Return the :class:`RotorUnbalance` of aggregates S (``static``) and P about O.

    ``model``: the layout's RotorModel (mass, S_z, planes); ``ci95_of`` maps complex
    weights (w_S, w_P) to a 95 % radius (None: exact values, radius 0).
    """
    values = rotor_with(model, static, products)

    def vector(quantity):
        weights = _weights(model, quantity)
        return UnbalanceVector(complex(*quantity(values)),
                               ci95_of(weights) if ci95_of else 0.0)
    planes = tuple((z, vector(quantity)) for z, quantity in _plane_vectors(model))
    return RotorUnbalance(vector(static_unbalance), vector(couple_unbalance), planes,
                          identifiable)


def identified_unbalance(model, estimate):
    """Return the :class:`RotorUnbalance` a fit identified, with its 95 % radii."""
    return unbalance_from(model, estimate.static, estimate.products, estimate.ci95,
                          estimate.identifiable)


def layout_unbalance(model):
    """Return the :class:`RotorUnbalance` the layout declares (exact: radii 0)."""
    return unbalance_from(model, complex(model.s_x, model.s_y),
                          complex(model.p_xz, model.p_yz))


def residual(identified, declared):
    """Return identified - declared: what the layout does not know (the fit's radii)."""
    def minus(a, b):
        return UnbalanceVector(a.value - b.value, a.ci95)
    planes = tuple((z, minus(a, b)) for (z, a), (_, b) in zip(identified.planes,
                                                              declared.planes))
    return RotorUnbalance(minus(identified.static, declared.static),
                          minus(identified.couple, declared.couple), planes,
                          identified.identifiable)
