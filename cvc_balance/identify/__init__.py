"""
The real rotor's unbalance, identified from measured support loads (load cells).

The loads are linear in the rotor's first moments S and products P (the engine's own
equations, :mod:`~cvc_balance.identify.regressors`), so a least-squares fit of the
readings over a window of samples gives the actual static, couple and per-plane unbalance,
with 95 % intervals and each cell's bias (its zero, the weight). Builds on the physics;
numpy only. Public API: :func:`fit` and :class:`Motion`, :class:`CellReadings` (a run at
once), :class:`SlidingFit` (the live node's O(1) window), :func:`identified_unbalance`,
:func:`layout_unbalance`, :func:`residual` (what the layout does not know).
"""

from cvc_balance.identify.batch import CellReadings, fit, Motion
from cvc_balance.identify.estimate import (identified_unbalance, layout_unbalance, residual,
                                           RotorUnbalance, UnbalanceVector)
from cvc_balance.identify.fit import Estimate, Sums

__all__ = ['CellReadings', 'Estimate', 'fit', 'identified_unbalance', 'layout_unbalance',
           'Motion', 'residual', 'RotorUnbalance', 'Sums', 'UnbalanceVector']
