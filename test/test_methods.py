"""
The ways to compute the loads, judged by the 40-digit reference (cvc_balance.study.exact).

The reference itself is checked against Pinocchio; then each method's accuracy regime:
the aggregated engine and Newton-Euler (matrices or ZXZ Euler angles) exact to rounding;
particle clouds converging as the particles multiply; the thesis's sums losing every
bearing moment and the alpha terms; float32 at its epsilon.
"""

import numpy as np
import pytest

from cvc_balance.physics.layout import parse_layout
from cvc_balance.study.bench import _relative, pareto_front
from cvc_balance.study.exact import exact_loads
from cvc_balance.study.methods import METHODS
from reference import method_error, pinocchio_loads, random_layout, relative_error


@pytest.fixture(scope='module')
def case():
    rng = np.random.default_rng(11)
    mapping = random_layout(rng, n=6, supports=2, every_kind=True)
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(0, 6, 8), rng.uniform(5, 25, 8), rng.uniform(-4, 4, 8)
    return mapping, layout, q, omega, alpha, exact_loads(layout, q, omega, alpha,
                                                         layout.gravity)


def error_of(name, case):
    _, layout, q, omega, alpha, _ = case
    return method_error(name, layout, q, omega, alpha)


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


@pytest.mark.parametrize('omega', [1e-12, 1e-3, 1e3, 1e4])
def test_engine_exact_from_rest_to_very_high_speed(omega, case):
    _, layout, q, _, alpha, _ = case
    assert method_error('aggregated', layout, q, np.full(len(q), omega), alpha) < 1e-13


@pytest.mark.parametrize('scale', [1e-6, 1e-3, 1.0, 1e2, 1e4])
def test_engine_exact_for_masses_from_a_milligram_to_ten_tonnes(scale):
    rng = np.random.default_rng(4)
    mapping = random_layout(rng, n=5, supports=2, every_kind=True)
    for item in mapping['components']:
        item['mass'] *= scale / 40.0
        if 'inertia' in item:
            item['inertia'] = {k: v * scale / 40.0 for k, v in item['inertia'].items()}
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(0, 6, 6), rng.uniform(5, 25, 6), rng.uniform(-4, 4, 6)
    assert method_error('aggregated', layout, q, omega, alpha) < 1e-13


def test_unbalance_vector_is_smooth_where_its_norm_has_a_kink():
    """Thesis Eq. 4.16-4.19: |F| kinks at balance; the vector's derivative does not jump."""
    from cvc_balance.physics.engine import RotorModel
    from cvc_balance.physics.unbalance import static_unbalance

    def vector(r2):
        model = RotorModel.from_layout(parse_layout({
            'name': 'two', 'supports': [{'name': 'a', 'z': 0.0}],
            'components': [{'name': 'p1', 'mass': 40.0, 'radius': 1.0, 'angle': 0.0},
                           {'name': 'p2', 'mass': 40.0, 'radius': r2, 'angle': np.pi}]}))
        return np.array(static_unbalance(model))
    step = 1e-6
    below = (vector(1.0) - vector(1.0 - step)) / step
    above = (vector(1.0 + step) - vector(1.0)) / step
    np.testing.assert_allclose(below, above, atol=1e-6)          # d U / d R2 = -m2 e_x
    np.testing.assert_allclose(below, [-40.0, 0.0], rtol=1e-6, atol=1e-6)
    norm = [np.linalg.norm(vector(1.0 + d)) for d in (-step, 0.0, step)]
    assert (norm[1] - norm[0]) / step == pytest.approx(-40.0, rel=1e-5)
    assert (norm[2] - norm[1]) / step == pytest.approx(40.0, rel=1e-5)


def bench_rows():
    import csv
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / 'docs' / 'bench.csv'
    rows = []
    with open(path, newline='') as stream:
        for row in csv.DictReader(stream):
            row['samples'] = int(row['samples'])
            if row['samples']:
                row['seconds_per_sample'] = float(row['seconds_per_sample'])
                row['max_relative_error'] = float(row['max_relative_error'])
            rows.append(row)
    return rows


def test_engine_is_on_the_pareto_front_of_every_scene_of_the_bench():
    """docs/bench.csv (cvc-balance bench): no method both faster and more accurate."""
    rows = bench_rows()
    scenes = list(dict.fromkeys(r['scene'] for r in rows))
    assert scenes == ['planar', 'axial offsets', 'tilt', 'spin-up', 'near-balance',
                      '1e5 components']
    for scene in scenes:
        assert 'aggregated' in pareto_front(rows, scene), scene


def test_bench_table_is_the_current_engine():
    """The CSV's engine errors are what the engine gives now (same scenes, same seed)."""
    from cvc_balance.study.bench import scenes
    rows = {(r['scene'], r['method']): r for r in bench_rows()}
    for scene, (layout, q, omega, alpha, gravity) in scenes(np.random.default_rng(0)).items():
        if scene == '1e5 components':
            continue                                # its reference takes a minute
        error = method_error('aggregated', layout, q, omega, alpha, gravity)
        assert error == pytest.approx(rows[(scene, 'aggregated')]['max_relative_error'],
                                      rel=1e-6, abs=1e-18)
