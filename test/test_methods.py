"""
The ways to compute the loads, judged by the 40-digit reference (cvc_balance.exact).

The reference itself is checked against Pinocchio; then each method's accuracy regime:
the aggregated engine and Newton-Euler (matrices or ZXZ Euler angles) exact to rounding;
particle clouds converging as the particles multiply; the thesis's sums losing every
bearing moment and the alpha terms; float32 at its epsilon.
"""

import numpy as np
import pytest

from cvc_balance.bench import _relative, pareto_front
from cvc_balance.exact import exact_loads
from cvc_balance.layout import parse_layout
from cvc_balance.methods import METHODS
from reference import pinocchio_loads, random_layout, relative_error


@pytest.fixture(scope='module')
def case():
    rng = np.random.default_rng(11)
    mapping = random_layout(rng, n=6, supports=2, every_kind=True)
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(0, 6, 8), rng.uniform(5, 25, 8), rng.uniform(-4, 4, 8)
    return mapping, layout, q, omega, alpha, exact_loads(layout, q, omega, alpha,
                                                         layout.gravity)


def error_of(name, case):
    _, layout, q, omega, alpha, reference = case
    prepare, compute = METHODS[name]
    result = compute(prepare(layout), q, omega, alpha, layout.gravity)
    return max(_relative(got, ref) for got, ref in zip(result, reference))


def test_reference_agrees_with_pinocchio(case):
    mapping, layout, q, omega, alpha, (force, moment, torque) = case
    for k in range(len(q)):
        ref = pinocchio_loads(mapping, q[k], omega[k], alpha[k], mapping['gravity'])
        assert relative_error(force[k], ref['force_rotor']) < 1e-14
        assert relative_error(moment[k], ref['moment_rotor']) < 1e-14
        assert relative_error(torque[k], ref['drive_torque']) < 1e-14


@pytest.mark.parametrize('name', ['aggregated', 'newton_euler', 'euler_zxz'])
def test_exact_methods_to_rounding(name, case):
    assert error_of(name, case) < 1e-13


def test_float32_is_at_its_epsilon(case):
    assert 1e-9 < error_of('aggregated_f32', case) < 1e-5


def test_particles_converge_as_they_multiply(case):
    errors = [error_of(f'particles_{n}', case) for n in (1, 8, 64, 1000)]
    assert errors[0] > 1e-3                          # points: no body inertia at all
    assert errors[1] > errors[2] > errors[3]          # midpoint grids: ~ 1 / k^2
    assert errors[3] < 1e-3


@pytest.mark.parametrize('name', ['thesis_particles', 'thesis_cylinders'])
def test_thesis_sums_lose_the_bearing_moment(name, case):
    """F1 = F2: no moment at all, where z offsets and products make one."""
    _, layout, q, omega, alpha, (force, moment, torque) = case
    prepare, compute = METHODS[name]
    got_force, got_moment, _ = compute(prepare(layout), q, omega, alpha, layout.gravity)
    assert np.abs(got_moment).max() == 0.0 and np.abs(moment).max() > 1.0
    # The force misses alpha's tangential term only.
    assert 0.0 < _relative(got_force, force) < 1.0


def test_pareto_front_reading():
    rows = [{'scene': 's', 'method': 'a', 'samples': 1, 'seconds_per_sample': 1.0,
             'max_relative_error': 1e-15},
            {'scene': 's', 'method': 'b', 'samples': 1, 'seconds_per_sample': 2.0,
             'max_relative_error': 1e-10},
            {'scene': 's', 'method': 'c', 'samples': 1, 'seconds_per_sample': 0.5,
             'max_relative_error': 1e-7}]
    assert pareto_front(rows, 's') == ['a', 'c']
