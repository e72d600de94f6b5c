"""
Speed against accuracy: every way to compute the loads, a 40-digit reference, the bench.

:mod:`~cvc_balance.study.methods` (``METHODS``), :mod:`~cvc_balance.study.exact`
(``exact_loads``, mpmath) and :mod:`~cvc_balance.study.bench` (``run``, the chart behind
``cvc-balance bench``); imported on use. Builds on the physics only.
"""
