"""
cvc_balance: bearing loads, drive torque and unbalance of a single-axis rotor.

The engine (:mod:`~cvc_balance.engine`, :mod:`~cvc_balance.inertia`,
:mod:`~cvc_balance.unbalance`, :mod:`~cvc_balance.iso21940`) imports numpy
only; ROS, files and viewers are adapters around it.
"""
