"""
cvc_balance: bearing loads, drive torque and unbalance of a single-axis rotor.

The engine (:mod:`~cvc_balance.physics.engine`, :mod:`~cvc_balance.physics.inertia`,
:mod:`~cvc_balance.physics.unbalance`, :mod:`~cvc_balance.physics.iso21940`) imports numpy
only; ROS, files and viewers are adapters around it.
"""
