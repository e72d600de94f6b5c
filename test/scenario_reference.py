"""
What a bundled bag's outputs must be, from its scenario, through the engine alone.

Independent of the replay's reading and vectorised alpha: the scenario regenerates the
samples, the live estimator (plain floats) gives alpha, and the engine's one-sample path
gives every output.
"""

from cvc_balance.bag.scenario import load_scenario
from cvc_balance.physics.engine import RotorModel, sample_loads
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.motion import AccelerationEstimator
from cvc_balance.physics.unbalance import couple_unbalance, static_unbalance


def expected_outputs(scenario_file):
    """Return {stamp ns: {topic: [fx, fy, fz, tx, ty, tz]}} plus per stamp q, omega, alpha."""
    scenario = load_scenario(scenario_file)
    stamps = scenario.stamps_ns()
    angle, omega = scenario.measured()
    models = [(round((scenario.start + at - 0.5 / scenario.rate) * 1e9),
               RotorModel.from_layout(parse_layout(m))) for at, m in scenario.layouts]
    estimator = AccelerationEstimator(0.1)
    expected, motion = {}, {}
    for ns, q, w in zip(stamps.tolist(), angle, omega):
        alpha = estimator.update(ns * 1e-9, w)
        model = [m for t, m in models if t <= ns][-1]
        result = sample_loads(model, q, w, alpha)
        (u_x, u_y), (p_xz, p_yz) = static_unbalance(model), couple_unbalance(model)
        expected[ns] = {
            '/bearing_load': list(result.force_stator) + list(result.moment_stator),
            '/unbalance': [w * w * u_x, w * w * u_y, 0, -w * w * p_yz, w * w * p_xz, 0],
            '/drive_torque': [0, 0, 0, 0, 0, result.drive_torque]}
        for name, (force, moment) in result.supports.items():
            expected[ns][f'/supports/{name}/load'] = list(force) + list(moment)
        motion[ns] = (q, w, alpha)
    return expected, motion
