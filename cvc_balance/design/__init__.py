"""
Design for balance: how each component's mass, radius, angle and z move the balance.

Built on :mod:`cvc_balance.physics` (numpy, scipy; matplotlib only in :mod:`charts`).
Public API:

* parameters: :class:`DesignParameter`, :func:`parse_parameter`, :func:`with_values`;
* :func:`sensitivities`: exact derivatives of the plane, static and couple unbalance
  vectors and the supports' unbalance loads for every parameter; :func:`norm_slopes`;
* tolerances: :func:`load_tolerances` (the tolerance file), :class:`Tolerances`;
  :func:`simulate` (vectorised exact Monte Carlo), :func:`analyse` (the stack: Monte
  Carlo, RSS, worst case, probability within grade, contributions), :func:`allocate`
  (least-cost tightening to a target probability);
* :func:`solve_balance`: free parameters that zero the unbalance vectors, and how
  sensitive the solution is;
* :func:`sweep` (the thesis's charts as numbers) and :mod:`charts` (as pictures).
"""

from cvc_balance.design.allocation import allocate, Allocation
from cvc_balance.design.balance_point import BalanceSolution, solve_balance
from cvc_balance.design.monte_carlo import Draws, simulate
from cvc_balance.design.parameters import (DesignParameter, parse_parameter, PARAMETERS,
                                           with_values)
from cvc_balance.design.sensitivity import norm_slopes, Sensitivity, sensitivities
from cvc_balance.design.stack import analyse, StackResult
from cvc_balance.design.sweep import Sweep, sweep
from cvc_balance.design.tolerances import (load_tolerances, ToleranceError, Tolerances,
                                           typical_tolerances)

__all__ = ['allocate', 'Allocation', 'analyse', 'BalanceSolution', 'DesignParameter', 'Draws',
           'load_tolerances', 'norm_slopes', 'PARAMETERS', 'parse_parameter', 'Sensitivity',
           'sensitivities', 'simulate', 'solve_balance', 'StackResult', 'Sweep', 'sweep',
           'ToleranceError', 'Tolerances', 'typical_tolerances', 'with_values']
