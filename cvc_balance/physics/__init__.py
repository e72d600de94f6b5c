"""
The physics: layouts, their aggregates, the loads, the unbalance and its verdict.

numpy (and PyYAML and msgspec to read layouts) only: nothing here knows of ROS, bags or viewers.
Lowest layer of the package; every other part builds on it. Public API:

* layouts: :class:`Layout`, :func:`parse_layout`, :func:`load_layout`,
  :func:`layout_from_text`, :class:`LayoutError`;
* the engine: :class:`RotorModel` (aggregates once), :func:`sample_loads` (one sample,
  plain floats), :func:`loads` (arrays, vectorised);
* balance: :func:`static_unbalance`, :func:`couple_unbalance`, :func:`plane_unbalances`,
  :func:`assess_balance` (ISO 21940-11), :func:`judge_balance` (the verdict, one
  definition: at the service speed, or the top speed seen);
* plausibility: :func:`layout_warnings` (likely unit mistakes in a valid layout);
* loads as people read them: :func:`support_load_parts` (static weight, rotating part);
* motion: :class:`AccelerationEstimator`, :func:`acceleration_series`;
* conventions: :mod:`~cvc_balance.physics.frames` (frames, signs, units).
"""

from cvc_balance.physics.assessment import (assess_balance, BalanceAssessment, judge_balance,
                                            judging_speed, Verdict)
from cvc_balance.physics.engine import loads, Loads, RotorModel, sample_loads, SampleLoads
from cvc_balance.physics.layout import Layout, LayoutError, parse_layout
from cvc_balance.physics.layout_file import layout_from_text, load_layout
from cvc_balance.physics.load_parts import support_load_parts, SupportLoadParts
from cvc_balance.physics.motion import acceleration_series, AccelerationEstimator
from cvc_balance.physics.plausibility import layout_warnings
from cvc_balance.physics.unbalance import couple_unbalance, plane_unbalances, static_unbalance

__all__ = ['acceleration_series', 'AccelerationEstimator', 'assess_balance',
           'BalanceAssessment', 'couple_unbalance', 'judge_balance', 'judging_speed', 'Layout',
           'LayoutError', 'layout_from_text', 'layout_warnings', 'load_layout', 'loads', 'Loads',
           'parse_layout', 'plane_unbalances', 'RotorModel', 'sample_loads', 'SampleLoads',
           'static_unbalance', 'support_load_parts', 'SupportLoadParts', 'Verdict']
