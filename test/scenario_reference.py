"""
What a bundled bag's outputs must be, from its scenario, through Pinocchio.

Independent of the replay's reading, its vectorised alpha and cvc_balance's physics: the
scenario regenerates the samples, the live estimator (plain floats, the node's) gives
alpha, and Pinocchio's RNEA of the layout in force gives every output, the support loads
split by statics and the unbalance from Pinocchio's mass properties
(:class:`independent.PinocchioRotor`).
"""

from cvc_balance.bag.scenario import load_scenario
from cvc_balance.physics.motion import AccelerationEstimator
from independent import PinocchioRotor


def expected_outputs(scenario_file):
    """Return {stamp ns: {topic: [fx, fy, fz, tx, ty, tz]}} plus per stamp q, omega, alpha."""
    scenario = load_scenario(scenario_file)
    stamps = scenario.stamps_ns()
    angle, omega = scenario.measured()
    rotors = [(round((scenario.start + at - 0.5 / scenario.rate) * 1e9), PinocchioRotor(m))
              for at, m in scenario.layouts]
    estimator = AccelerationEstimator(0.1)
    expected, motion = {}, {}
    for ns, q, w in zip(stamps.tolist(), angle, omega):
        alpha = estimator.update(ns * 1e-9, w)
        rotor = [r for t, r in rotors if t <= ns][-1]
        ref = rotor.loads(float(q), float(w), alpha)
        force, torque = rotor.unbalance(float(w))
        expected[ns] = {
            '/bearing_load': list(ref['force']) + list(ref['moment']),
            '/unbalance': list(force) + list(torque),
            '/drive_torque': [0, 0, 0, 0, 0, ref['drive_torque']]}
        for name, (force, moment) in ref['supports'].items():
            expected[ns][f'/supports/{name}/load'] = list(force) + list(moment)
        motion[ns] = (q, w, alpha)
    return expected, motion
