"""
Field balancing as the service engineer does it: 1x readings, trial weights, corrections.

The math only (numpy, scipy's HiGHS; no files): :mod:`~cvc_balance.field.order_tracking`
reads a channel's once-per-revolution amplitude and phase against the encoder's angle;
:mod:`~cvc_balance.field.influence` gives the influence coefficients of a baseline and
trial-weight runs (least squares over runs, 95 % radii, trials too small to see);
:mod:`~cvc_balance.field.correction` the balancing problem and its continuous optimum
(weighted complex least squares); :mod:`~cvc_balance.field.plan` the weights at fixed
sites from a kit (the vector split, and a mixed-integer plan); :mod:`~cvc_balance.field.
coefficients` the coefficient record; :mod:`~cvc_balance.field.notation` AMPLITUDE@DEG.
Reading runs from bags is :mod:`cvc_balance.bag.field_run`'s job.
"""

from cvc_balance.field.correction import (BalancingProblem, continuous_correction,
                                          problem_from_readings, problem_from_unbalance,
                                          Residual)
from cvc_balance.field.influence import calibrate, Calibration, Trial, TrialCheck
from cvc_balance.field.order_tracking import (Phasor, steady_stretches, steady_window,
                                              SteadyWindow, track)
from cvc_balance.field.plan import (continuous_plan, optimal_plan, PlacedWeight, Plan,
                                    round_to_kit, split_plan, vector_split)

__all__ = ['BalancingProblem', 'calibrate', 'Calibration', 'continuous_correction',
           'continuous_plan', 'optimal_plan', 'Phasor', 'PlacedWeight', 'Plan',
           'problem_from_readings', 'problem_from_unbalance', 'Residual', 'round_to_kit',
           'split_plan', 'steady_stretches', 'steady_window', 'SteadyWindow', 'track', 'Trial',
           'TrialCheck', 'vector_split']
