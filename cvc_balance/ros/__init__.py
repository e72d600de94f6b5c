"""
The ROS 2 adapters: the ``balance_monitor`` node, ``play`` and ``record``.

Modules (imported on use: each pulls in rclpy, and the node runs with ``python -m``):
:mod:`~cvc_balance.ros.balance_monitor` (the node: ``BalanceMonitor``, ``main``),
:mod:`~cvc_balance.ros.recorder` (``BagRecorder``), :mod:`~cvc_balance.ros.player`
(``play``), :mod:`~cvc_balance.ros.qos` (the topics' QoS) and
:mod:`~cvc_balance.ros.executor` (``spin``, the one spin loop).
"""
