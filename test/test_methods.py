"""
The ways to compute the loads, judged by the 40-digit reference (cvc_balance.study.exact).

The reference itself is checked against Pinocchio on many random layouts, and its
superposition of unit motions against summing per component and per sample; then each
method's accuracy regime: the aggregated engine and Newton-Euler (matrices or ZXZ Euler
angles) exact to rounding; particle clouds converging as the particles multiply, one
particle a body being exactly the point-mass model; the thesis's sums losing every
bearing moment and the alpha terms; float32 at its epsilon.
"""

from dataclasses import replace

import numpy as np
import pytest

from cvc_balance.physics.layout import parse_layout
from cvc_balance.study.bench import _relative, pareto_front
from cvc_balance.study.exact import direct_loads, exact_loads, unbalance_about_o
from cvc_balance.study.methods import METHODS
from reference import method_error, pinocchio_loads, random_layout


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


@pytest.mark.parametrize('seed', range(30))
def test_reference_agrees_with_pinocchio(seed):
    """
    Random layouts (every shape kind, one or two supports, tilted gravity), 6 samples.

    Each output's deviation from Pinocchio's RNEA over the samples, scaled by its largest
    value (the bench's measure); measured over the 30 layouts: at most 1.0e-15 for the
    force, 5.5e-16 for the moment, 5.1e-16 for the drive torque (Pinocchio's rounding).
    """
    rng = np.random.default_rng(seed)
    mapping = random_layout(rng, n=int(rng.integers(1, 12)), supports=1 + seed % 2,
                            every_kind=seed % 3 == 0)
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(-7, 7, 6), rng.uniform(-40, 40, 6), rng.uniform(-30, 30, 6)
    force, moment, torque = exact_loads(layout, q, omega, alpha, layout.gravity)
    refs = [pinocchio_loads(mapping, q[k], omega[k], alpha[k], mapping['gravity'])
            for k in range(len(q))]
    assert _relative(force, np.array([r['force_rotor'] for r in refs])) < 4e-15
    assert _relative(moment, np.array([r['moment_rotor'] for r in refs])) < 2e-15
    assert _relative(torque, np.array([r['drive_torque'] for r in refs])) < 2e-15


@pytest.mark.parametrize('seed', range(4))
def test_superposed_unit_motions_equal_the_per_sample_sums(seed):
    """The reference's linear combination of unit motions, against Newton-Euler per sample."""
    rng = np.random.default_rng(50 + seed)
    layout = parse_layout(random_layout(rng, n=8, supports=2, every_kind=True))
    q, omega, alpha = rng.uniform(-7, 7, 5), rng.uniform(-40, 40, 5), rng.uniform(-30, 30, 5)
    superposed = exact_loads(layout, q, omega, alpha, layout.gravity)
    direct = direct_loads(layout, q, omega, alpha, layout.gravity)
    for got, want in zip(superposed, direct):
        # Both are 40-digit values rounded to float64: equal (measured: bit for bit).
        assert np.array_equal(got, want)


# Measured on the case's layout and samples: engine 1.5e-16, both Newton-Euler 1.9e-15.
@pytest.mark.parametrize('name, bound', [('aggregated', 1e-15), ('newton_euler', 1e-14),
                                         ('euler_zxz', 1e-14)])
def test_exact_methods_to_rounding(name, bound, case):
    assert error_of(name, case) < bound


def test_float32_is_at_its_epsilon(case):
    """float32's unit roundoff u = 2^-24 = 6.0e-8; measured 9.9e-8 = 1.7 u."""
    u = 2.0 ** -24
    assert u / 4 < error_of('aggregated_f32', case) < 8 * u


def test_one_particle_a_body_is_the_point_mass_model(case):
    """
    One particle a body is the point-mass model.

    particles_1 is each shape's mass at its centre (a given tensor: six particles that
    reproduce it): the reference on the layout with its shapes dropped (measured 4.0e-15
    against it, 1.3e-2 against the bodies).
    """
    _, layout, q, omega, alpha, _ = case
    points = replace(layout, components=tuple(replace(c, shape=None)
                                              for c in layout.components))
    reference = exact_loads(points, q, omega, alpha, layout.gravity)
    prepare, compute = METHODS['particles_1']
    got = compute(prepare(layout), q, omega, alpha, layout.gravity)
    assert max(_relative(g, r) for g, r in zip(got, reference)) < 2e-14
    assert error_of('particles_1', case) > 1e-3      # the bodies' own inertia matters here


def test_particles_converge_as_they_multiply(case):
    """
    Midpoint grids of k^3 particles converge like 1 / k^2.

    Measured 7.0e-3, 4.8e-4, 6.8e-5 for k = 2, 4, 10: the last step 7.1 against
    (10 / 4)^2 = 6.25.
    """
    errors = [error_of(f'particles_{n}', case) for n in (8, 64, 1000)]
    assert errors[0] > errors[1] > errors[2]
    assert 6.25 / 1.5 < errors[1] / errors[2] < 6.25 * 1.5
    assert errors[2] < 1e-4


@pytest.mark.parametrize('name', ['thesis_particles', 'thesis_cylinders'])
def test_thesis_sums_lose_the_bearing_moment(name, case):
    """
    F1 = F2: no moment at all, where z offsets and products make one (peak 7.7e3 N m).

    The force is the load at alpha = 0 (measured 1.5e-16 from it): it misses exactly the
    tangential term alpha (S_y, -S_x, 0), S read off the reference's centrifugal load.
    """
    _, layout, q, omega, alpha, (force, moment, torque) = case
    prepare, compute = METHODS[name]
    got_force, got_moment, _ = compute(prepare(layout), q, omega, alpha, layout.gravity)
    assert np.abs(got_moment).max() == 0.0 and np.abs(moment).max() > 1e3
    at_rest, _, _ = exact_loads(layout, q, omega, np.zeros(len(q)), layout.gravity)
    assert _relative(got_force, at_rest) < 1e-15
    (s_x, s_y), _ = unbalance_about_o(layout)
    missed = np.stack([alpha * float(s_y), -alpha * float(s_x), 0.0 * alpha], 1)
    # A difference of loads up to 200 times the alpha term: measured 2.8e-14 of it.
    assert _relative(force - got_force, missed) < 2e-13


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
    """Measured 1.8e-16 to 2.2e-16 of each output's peak."""
    _, layout, q, _, alpha, _ = case
    assert method_error('aggregated', layout, q, np.full(len(q), omega), alpha) < 1e-15


@pytest.mark.parametrize('scale', [1e-6, 1e-3, 1.0, 1e2, 1e4])
def test_engine_exact_for_masses_from_a_milligram_to_ten_tonnes(scale):
    rng = np.random.default_rng(4)
    mapping = random_layout(rng, n=5, supports=2, every_kind=True)
    # The lightest component weighs ``scale`` kg: 1 mg is the lightest a layout takes.
    factor = scale / min(item['mass'] for item in mapping['components'])
    for item in mapping['components']:
        item['mass'] *= factor
        if 'inertia' in item:
            item['inertia'] = {k: v * factor for k, v in item['inertia'].items()}
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(0, 6, 6), rng.uniform(5, 25, 6), rng.uniform(-4, 4, 6)
    assert method_error('aggregated', layout, q, omega, alpha) < 1e-15   # 1.6e-16 to 2.1e-16


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
    from pathlib import Path
    from cvc_balance.study.bench import read_rows
    return read_rows(Path(__file__).resolve().parents[1] / 'docs' / 'bench.csv')


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


def bench_row(method, seconds, error, scene='s'):
    return {'scene': scene, 'method': method, 'samples': 8, 'seconds_per_sample': seconds,
            'max_relative_error': error}


def test_quick_bench_compared_with_the_full_one_conclusion_by_conclusion():
    """
    What ``bench`` says when a quick run's conclusions are not the full run's.

    Orders the full run sets 2x apart in time or 10x in error must hold; closer ones are
    ties (timing noise may swap them). A method on one run's Pareto front, and not nearly
    beaten there (by one 2x faster and not 10x less accurate, or 10x more accurate and not
    2x slower), must not be dominated in the other's (by one at least as fast and as
    accurate, 2x faster or 10x more accurate). A method skipped in one run but not the
    other is a different chart.
    """
    from cvc_balance.study.bench import compare
    full = [bench_row('engine', 1e-7, 1e-16), bench_row('f32', 0.4e-7, 1e-7),
            bench_row('sums', 3e-7, 1.0), bench_row('loop', 3.3e-7, 1e-14)]
    assert compare(full, full) == []
    # sums and loop are a tie in time (1.1x): swapping them says nothing.
    tie = [bench_row('engine', 1e-7, 1e-16), bench_row('f32', 0.4e-7, 1e-7),
           bench_row('sums', 3.3e-7, 1.0), bench_row('loop', 3e-7, 1e-14)]
    assert compare(tie, full) == []
    # loop, exact to rounding too, a hair faster than the engine in one run (on its front),
    # a hair slower in the other (off it): within the noise, not a different conclusion.
    near = [dict(r) for r in full]
    near[3].update(seconds_per_sample=0.9e-7, max_relative_error=2e-16)
    nearer = [dict(r) for r in near]
    nearer[3]['seconds_per_sample'] = 1.1e-7
    assert compare(nearer, near) == compare(near, nearer) == []
    # f32 slower than the engine: off the front, and one order swapped.
    slow = [bench_row('engine', 1e-7, 1e-16), bench_row('f32', 1.5e-7, 1e-7),
            bench_row('sums', 3e-7, 1.0), bench_row('loop', 3.3e-7, 1e-14)]
    assert compare(slow, full) == [
        's: f32 on the Pareto front of the full run, dominated in the quick run',
        's: f32 not faster than engine, as the full run has it']
    # loop's error above f32's and the sums': orders the full run sets 1e7 and 1e14 apart.
    wrong = [dict(r) for r in full]
    wrong[3]['max_relative_error'] = 2.0
    assert compare(wrong, full) == ['s: loop not more accurate than f32, as the full run has it',
                                    's: loop not more accurate than sums, as the full run has it']
    skipped = [dict(r) for r in full]
    skipped[3]['samples'] = 0
    assert compare(skipped, full) == ["s: methods run ['engine', 'f32', 'sums'], the full run "
                                      "['engine', 'f32', 'loop', 'sums']"]


def test_quick_bench_runs_costly_methods_on_fewer_samples_and_keeps_the_accuracy_conclusions(
        tmp_path):
    """
    The quick run on two scenes against the full run on the same: errors are not timings.

    The quick run gives the costly methods an eighth of the full run's work, but at least 32
    samples (particles_1000: 312 of 512 with 12 bodies; particles_10000: 32 of 250); the
    others keep every sample. The engine is the most accurate in both runs,
    and the order of every two methods the full run sets 10x apart in error is the quick
    run's. (Their speeds and fronts are compared by benchmarks/bench_time.py: timings vary
    with the machine's load.)
    """
    from cvc_balance.study.bench import ACCURACY_GAP, ranked_pairs, read_rows, run
    from cvc_balance.study.bench import scenes
    chosen = ('spin-up', 'near-balance')
    layouts = {name: scene[0].components for name, scene in
               scenes(np.random.default_rng(0), large=False).items()}
    rows = {}
    for full in (False, True):
        csv_path = tmp_path / f'{full}.csv'
        returned = run(csv_path, None, full=full, only=chosen, print_table=lambda line: None)
        rows[full] = read_rows(csv_path)
        assert [r['samples'] for r in returned] == [r['samples'] for r in rows[full]]
    assert {r['scene'] for r in rows[True]} == set(chosen) and len(rows[True]) == 22
    for quick, full in zip(rows[False], rows[True]):
        assert (quick['scene'], quick['method']) == (full['scene'], full['method'])
        per_body = {'particles_1000': 1000, 'particles_10000': 10_000}.get(full['method'], 1)
        bodies = len(layouts[full['scene']]) * per_body
        assert full['samples'] == min(512, int(3e7 // bodies))
        assert quick['samples'] == min(full['samples'], max(32, int(3e7 / 8 // bodies)))
        assert quick['samples'] < full['samples'] or bodies < 12_000
    for scene in chosen:
        for kind in (False, True):
            done = [r for r in rows[kind] if r['scene'] == scene]
            assert min(done, key=lambda r: r['max_relative_error'])['method'] == 'aggregated'
        wanted = ranked_pairs(rows[True], scene, 'max_relative_error', ACCURACY_GAP)
        assert len(wanted) > 20
        assert wanted <= ranked_pairs(rows[False], scene, 'max_relative_error', 1.0)


def test_stored_references_are_the_scenes():
    """
    The quick bench's stored 40-digit references: the scenes' layouts, computed again.

    Each of the six scenes' layouts has its entry (by digest; spin-up's is axial offsets');
    the small ones equal basis_wrenches computed now, digit for digit. The 10^5-component
    scene's (1.5 minutes to compute; the full bench does) is checked against the engine's
    double-double aggregates: mass, static unbalance and couple about O to 1e-15.
    """
    from cvc_balance.physics.engine import RotorModel
    from cvc_balance.study.bench import layout_digest, scenes, stored_references
    from cvc_balance.study.exact import basis_wrenches, BASIS
    stored = stored_references()
    every = scenes(np.random.default_rng(0))
    assert len(stored) == len({layout_digest(scene[0]) for scene in every.values()}) == 5
    for scene, (layout, *_) in every.items():
        basis = stored[layout_digest(layout)]
        if scene != '1e5 components':
            assert basis == basis_wrenches(layout), scene
            continue
        model = RotorModel.from_layout(layout)
        force, moment, _ = basis[BASIS.index('omega2')]     # (S_x, S_y, 0), (-P_yz, P_xz)
        assert float(force[0]) == pytest.approx(model.s_x, rel=1e-15)
        assert float(force[1]) == pytest.approx(model.s_y, rel=1e-15)
        assert float(moment[1]) == pytest.approx(model.p_xz, rel=1e-15)
        assert float(moment[0]) == pytest.approx(-model.p_yz, rel=1e-15)
        gravity_force, _, _ = basis[BASIS.index('g_z')]          # m e_z
        assert float(gravity_force[2]) == pytest.approx(model.mass, rel=1e-15)
