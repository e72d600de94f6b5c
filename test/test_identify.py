"""
The real rotor's unbalance from simulated load cells, where the truth is known.

Cell readings are made from the TRUE rotor (the declared layout plus a hidden change) by
Pinocchio's rigid-body dynamics (RNEA, split over the supports by statics) or by the
engine (itself checked against Pinocchio in test_pinocchio.py), plus each cell's bias and
Gaussian noise; the fit sees only the readings, the encoder and the DECLARED layout. The
truth is the hidden change, computed by hand (m R e^{i theta}, m R z e^{i theta}).
"""

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from cvc_balance.identify import (CellReadings, fit, identified_unbalance, layout_unbalance,
                                  Motion, residual)
from cvc_balance.identify.batch import channels
from cvc_balance.identify.estimate import unbalance_from
from cvc_balance.identify.live import SlidingFit
from cvc_balance.identify.regressors import moment_coefficients, support_coefficients
from cvc_balance.physics.engine import loads, RotorModel, support_loads
from cvc_balance.physics.frames import STANDARD_GRAVITY
from cvc_balance.physics.layout import parse_layout
from reference import pinocchio_loads

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
RUNS = 50


def run(true_layout, rng, duration=8.0, spin_up=4.0, omega_top=23.27, tilt_deg=0.0,
        noise=20.0, bias=((35.0, -120.0, 4.0), (-60.0, 80.0, -9.0)), rate=500.0,
        cell_rate=400.0, engine=True, cell_times=None):
    """Return (Motion, cells, true model) of a run of ``true_layout``: spin-up, steady."""
    layout = tilted(true_layout, tilt_deg)
    truth = RotorModel.from_layout(parse_layout(layout))
    alpha0 = omega_top / spin_up

    def exact(t):
        up = np.minimum(t, spin_up)
        omega = alpha0 * up
        angle = 0.5 * alpha0 * up ** 2 + omega_top * np.maximum(t - spin_up, 0.0)
        return angle, omega, np.where(t < spin_up, alpha0, 0.0)

    t = np.arange(0.0, duration, 1.0 / rate)
    angle, omega, alpha = exact(t)
    motion = Motion(t, np.remainder(angle + math.pi, 2 * math.pi) - math.pi, omega, alpha)
    cells = {}
    for k, support in enumerate(truth.supports):
        tc = np.arange(0.3 / cell_rate * (k + 1), duration - 0.01, 1.0 / cell_rate) \
            if cell_times is None else cell_times
        q, w, a = exact(tc)
        if engine:
            force = loads(truth, q, w, a).support_force[support.name]
            torque = loads(truth, q, w, a).support_moment[support.name]
        else:
            force, torque = pinocchio_support_loads(layout, truth.supports, support, q, w, a)
        force = force + np.asarray(bias[k]) + rng.normal(0.0, noise, force.shape)
        torque = torque + rng.normal(0.0, noise * 0.1, torque.shape)
        cells[support.name] = CellReadings(support.name, tc, force, torque)
    return motion, cells, truth


def tilted(layout, tilt_deg):
    """Return the layout on a gantry tilted by ``tilt_deg`` (gravity turned about X)."""
    out = copy.deepcopy(layout)
    tilt = math.radians(tilt_deg)
    out['gravity'] = [0.0, -STANDARD_GRAVITY * math.cos(tilt), STANDARD_GRAVITY * math.sin(tilt)]
    return out


def pinocchio_support_loads(layout, supports, support, q, omega, alpha):
    """Per-support loads from Pinocchio's RNEA (stator frame), split by statics."""
    forces, moments = [], []
    for qi, wi, ai in zip(q, omega, alpha):
        ref = pinocchio_loads(layout, float(qi), float(wi), float(ai), layout['gravity'])
        f, m = ref['force_stator'], ref['moment_stator']
        split = support_loads(supports, f[0], f[1], f[2], m[0], m[1])
        index = [s.name for s in supports].index(support.name)
        forces.append(split[index][0])
        moments.append(split[index][1])
    return np.array(forces), np.array(moments)


def with_component(layout, **component):
    out = copy.deepcopy(layout)
    out['components'].append(component)
    return out


def hidden(mass, radius, angle_deg, z):
    """Return the aggregates a point mass adds, by hand: S = m R e^{i theta}, P = S z."""
    s = mass * radius * complex(math.cos(math.radians(angle_deg)),
                                math.sin(math.radians(angle_deg)))
    return s, s * z


DECLARED = RotorModel.from_layout(parse_layout(GANTRY))
DECLARED_S = complex(DECLARED.s_x, DECLARED.s_y)
DECLARED_P = complex(DECLARED.p_xz, DECLARED.p_yz)


# -- the regressors are the engine's equations -----------------------------------------

@pytest.mark.parametrize('supports', [1, 2])
def test_coefficients_are_the_engines_loads_for_unit_aggregates(supports):
    rng = np.random.default_rng(supports)
    layout = copy.deepcopy(GANTRY)
    if supports == 1:
        layout['supports'] = [{'name': 'only', 'z': 0.07}]
    layout['gravity'] = [0.4, -9.7, 1.9]
    model = RotorModel.from_layout(parse_layout(layout))
    q, w, a = rng.uniform(-4, 4, 64), rng.uniform(-30, 30, 64), rng.uniform(-9, 9, 64)
    turn = np.exp(1j * q)

    def engine_with(s, p):
        unit = copy.copy(model)
        object.__setattr__(unit, 'mass', 0.0)
        object.__setattr__(unit, 's_z', 0.0)
        for name, value in (('s_x', s.real), ('s_y', s.imag), ('p_xz', p.real),
                            ('p_yz', p.imag)):
            object.__setattr__(unit, name, value)
        return loads(unit, q, w, a)

    for s, p in ((1 + 0j, 0j), (1j, 0j), (0j, 1 + 0j), (0j, 1j)):
        result = engine_with(s, p)
        for k, support in enumerate(model.supports):
            c_s, c_p = support_coefficients(model.supports, k, turn, w, a, model.gravity[2])
            force = result.support_force[support.name]
            np.testing.assert_allclose(c_s * s + c_p * p, force[:, 0] + 1j * force[:, 1],
                                       rtol=0, atol=1e-12 * (1 + np.abs(force).max()))
        if supports == 1:
            c_s, c_p = moment_coefficients(model.supports[0], turn, w, a, model.gravity[2])
            moment = result.support_moment['only']
            np.testing.assert_allclose(c_s * s + c_p * p, moment[:, 0] + 1j * moment[:, 1],
                                       rtol=0, atol=1e-12 * (1 + np.abs(moment).max()))


# -- known truth, seeded runs ------------------------------------------------------------

CASES = {
    # name: (hidden components, run options)
    'heavier tube side': ([dict(name='hidden', mass=0.5, radius=0.62, angle_deg=40.0,
                                z=0.05)], {}),
    'pure couple': ([dict(name='front_mass', mass=0.4, radius=0.6, angle_deg=120.0, z=-0.12),
                     dict(name='rear_mass', mass=0.4, radius=0.6, angle_deg=300.0, z=0.12)],
                    {}),
    'tilted gantry': ([dict(name='hidden', mass=0.3, radius=0.5, angle_deg=-70.0, z=0.1)],
                      {'tilt_deg': 20.0}),
    'spin-up only': ([dict(name='hidden', mass=0.5, radius=0.62, angle_deg=200.0, z=-0.05)],
                     {'duration': 3.9, 'spin_up': 4.0}),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_identified_unbalance_is_the_hidden_change(case):
    extra, options = CASES[case]
    # The declared layout knows the tilt (its gravity); not the hidden change.
    declared = RotorModel.from_layout(parse_layout(tilted(GANTRY, options.get('tilt_deg', 0.0))))
    true_layout = copy.deepcopy(GANTRY)
    s_true, p_true = DECLARED_S, DECLARED_P
    for component in extra:
        true_layout = with_component(true_layout, **component)
        s, p = hidden(component['mass'], component['radius'], component['angle_deg'],
                      component['z'])
        s_true, p_true = s_true + s, p_true + p
    inside = {'static': 0, 'plane I': 0, 'plane II': 0}
    for seed in range(RUNS):
        motion, cells, truth = run(true_layout, np.random.default_rng(seed), **options)
        estimate, dropped = fit(declared, motion, cells)
        assert dropped == 0 and estimate.identifiable
        found = identified_unbalance(declared, estimate)
        true_u = unbalance_from(declared, s_true, p_true)
        planes = zip(('plane I', 'plane II'), found.planes, true_u.planes)
        checks = [('static', found.static, true_u.static)] + [
            (label, f, t) for label, (_, f), (_, t) in planes]
        for label, got, want in checks:
            error = abs(got.value - want.value)
            sigma = got.ci95 / math.sqrt(5.991464547107979)
            # Each run within 2 % + the noise's 4 sigma (sigma of the estimate per component).
            assert error <= 0.02 * abs(want.value) + 4 * math.sqrt(2) * sigma, (label, seed)
            inside[label] += error <= got.ci95
    for label, count in inside.items():
        assert count >= 0.9 * RUNS, (label, count)


def test_pinocchio_made_readings_give_the_hidden_mass():
    true_layout = with_component(GANTRY, name='hidden', mass=0.5, radius=0.62, angle_deg=40.0,
                                 z=0.05)
    motion, cells, _ = run(true_layout, np.random.default_rng(7), duration=5.0, cell_rate=100.0,
                           engine=False, tilt_deg=10.0)
    declared = RotorModel.from_layout(parse_layout(tilted(GANTRY, 10.0)))
    estimate, _ = fit(declared, motion, cells)
    found = residual(identified_unbalance(declared, estimate), layout_unbalance(declared))
    s, _ = hidden(0.5, 0.62, 40.0, 0.05)
    assert abs(found.static.value - s) <= found.static.ci95
    assert found.static.ci95 < 0.05 * abs(s)           # and the interval is informative


def test_an_unchanged_rotor_has_no_residual_and_biases_are_not_unbalance():
    inside = 0
    for seed in range(20):
        motion, cells, _ = run(GANTRY, np.random.default_rng(100 + seed),
                               bias=((3000.0, -9000.0, 50.0), (-7000.0, 2500.0, 10.0)))
        estimate, _ = fit(DECLARED, motion, cells)
        found = residual(identified_unbalance(DECLARED, estimate), layout_unbalance(DECLARED))
        inside += all(abs(v.value) <= v.ci95 for v in
                      [found.static] + [v for _, v in found.planes])
        # The biases come back as the cells' zeros plus the static weight they carry.
        assert abs(estimate.biases[0].real - 3000.0) < 20.0
    assert inside >= 16


def test_no_rotation_cannot_tell_and_says_so():
    motion, cells, _ = run(GANTRY, np.random.default_rng(1), duration=2.0, spin_up=1e9,
                           omega_top=0.0)
    estimate, _ = fit(DECLARED, motion, cells)
    assert not estimate.identifiable
    assert math.isinf(identified_unbalance(DECLARED, estimate).static.ci95)


def test_less_than_a_turn_gives_a_wide_interval():
    short = run(GANTRY, np.random.default_rng(2), duration=1.0, spin_up=4.0)
    long = run(GANTRY, np.random.default_rng(2), duration=8.0, spin_up=4.0)
    wide = identified_unbalance(DECLARED, fit(DECLARED, *short[:2])[0]).static.ci95
    narrow = identified_unbalance(DECLARED, fit(DECLARED, *long[:2])[0]).static.ci95
    assert short[0].revolutions() < 0.5 and wide > 20 * narrow, (wide, narrow)


# -- the live fit --------------------------------------------------------------------------

def test_live_fit_equals_the_batch_fit_on_the_same_readings():
    true_layout = with_component(GANTRY, name='hidden', mass=0.5, radius=0.62, angle_deg=40.0,
                                 z=0.05)
    # Readings stamped at the motion samples: the live path's extrapolation is then exact.
    times = np.arange(0.0, 8.0, 1.0 / 500.0)
    motion, cells, _ = run(true_layout, np.random.default_rng(5), cell_times=times)
    live = SlidingFit(DECLARED.supports, DECLARED.gravity[2], window_revs=1000)
    for k in range(len(motion.time)):
        live.motion(motion.time[k], motion.angle[k], motion.omega[k], motion.alpha[k])
        for name, cell in cells.items():
            assert live.reading(name, cell.time[k], cell.force[k][:2])
    batch, _ = fit(DECLARED, motion, cells)
    got = live.estimate()
    # Measured: 2e-15 relative (cmath.rect against numpy.exp, sums in another order).
    assert abs(got.static - batch.static) < 1e-12 * abs(batch.static)
    assert abs(got.products - batch.products) < 1e-12 * abs(batch.products)
    assert got.sigma == pytest.approx(batch.sigma, rel=1e-9)


def test_live_window_forgets_old_revolutions():
    light = run(GANTRY, np.random.default_rng(8), duration=12.0)
    heavy_layout = with_component(GANTRY, name='hidden', mass=1.0, radius=0.6, angle_deg=0.0,
                                  z=0.0)
    heavy = run(heavy_layout, np.random.default_rng(9), duration=12.0)
    live = SlidingFit(DECLARED.supports, DECLARED.gravity[2], window_revs=5)
    for (motion, cells, _), offset in ((light, 0.0), (heavy, 12.0)):
        order = sorted((t, name, i) for name, c in cells.items() for i, t in enumerate(c.time))
        k = 0
        for t, name, i in order:
            while k < len(motion.time) and motion.time[k] <= t:
                live.motion(offset + motion.time[k], motion.angle[k], motion.omega[k],
                            motion.alpha[k])
                k += 1
            live.reading(name, offset + t, cells[name].force[i][:2])
    found = residual(identified_unbalance(DECLARED, live.estimate()), layout_unbalance(DECLARED))
    assert abs(found.static.value - 0.6) <= found.static.ci95     # only the heavy run counts


def test_bad_readings_are_dropped_and_counted():
    live = SlidingFit(DECLARED.supports, DECLARED.gravity[2])
    assert not live.reading('front', 0.0, (1.0, 2.0))          # no motion yet
    live.motion(0.0, 0.0, 10.0, 0.0)
    before = live.sums()
    assert not live.reading('front', 0.001, (math.nan, 2.0))
    assert not live.reading('middle', 0.001, (1.0, 2.0))       # no such support
    assert not live.reading('front', 5.0, (1.0, 2.0))          # far from the motion
    assert not live.reading('front', 0.001, (1.0, 1.0001e12))  # beyond MAX_READING
    assert not live.reading('front', 0.001, (1.0, -math.inf))
    assert live.dropped == 6
    assert live.sums() == before
    assert live.reading('front', 0.001, (1.0, 2.0))
    assert live.reading('front', 0.002, (1.0, 1e12))           # at the bound: taken


def test_readings_that_overflow_the_sums_cannot_tell_and_say_so():
    # Found by test_fuzz: readings of 1e308 N are finite, their squares are not; the fit
    # then published NaN. Now: not identifiable, every interval inf, nothing NaN.
    live = SlidingFit(DECLARED.supports, DECLARED.gravity[2], window_revs=1000)
    motion, cells, _ = run(GANTRY, np.random.default_rng(3),
                           cell_times=np.arange(0.0, 8.0, 1.0 / 500.0))
    for k in range(len(motion.time)):
        live.motion(motion.time[k], motion.angle[k], motion.omega[k], motion.alpha[k])
        for name, cell in cells.items():
            live.reading(name, cell.time[k], cell.force[k][:2])
    assert live.estimate().identifiable
    live._current.add(0, 1.0, 1.0, complex(1e308, 1e308))    # past the reading's check
    estimate = live.estimate()
    assert not estimate.identifiable and estimate.sigma == math.inf
    assert estimate.static == 0j and estimate.products == 0j
    huge = {name: CellReadings(name, cell.time,
                               np.where(np.arange(len(cell.time))[:, None] == 7, 1e13,
                                        cell.force), cell.torque)
            for name, cell in cells.items()}
    batch, dropped = fit(DECLARED, motion, huge)
    assert dropped == 2 and batch.identifiable           # reading 7 of each cell dropped


def test_channels_of_one_and_two_supports():
    assert channels(DECLARED.supports) == [(0, 'force'), (1, 'force')]
    component = {'name': 'a', 'mass': 1.0, 'radius': 1.0, 'angle': 0.0}
    single = parse_layout({'name': 's', 'components': [component],
                           'supports': [{'name': 'x', 'z': 0.0}]})
    assert channels(single.supports) == [(0, 'force'), (0, 'moment')]


def test_sums_and_their_solution_against_numpy_least_squares():
    """
    The fit's sums and solution against numpy's complex least squares of the same readings.

    Readings y = c_S S + c_P P + b_k + noise on channels 0 and 2 of three (channel 1 has
    none: its bias stays 0). Sums made one reading at a time equal those made from arrays
    in two parts and the sums' definitions; the estimate equals numpy's lstsq, with sigma^2
    = |residual|^2 / (2 n - 2 p) (real degrees of freedom) and (A^H A)^-1 for (S, P).
    """
    from cvc_balance.identify.fit import Sums
    rng = np.random.default_rng(7)
    n = 400
    c_s = rng.normal(size=n) + 1j * rng.normal(size=n)
    c_p = rng.normal(size=n) + 1j * rng.normal(size=n)
    channel = np.where(rng.random(n) < 0.5, 0, 2)
    truth_s, truth_p, bias = 0.3 - 0.2j, -0.05 + 0.1j, {0: 5.0 + 1.0j, 2: -3.0 + 0.5j}
    y = c_s * truth_s + c_p * truth_p + np.array([bias[c] for c in channel]) \
        + 0.01 * (rng.normal(size=n) + 1j * rng.normal(size=n))
    one_by_one, from_arrays = Sums(3), Sums(3)
    for k in range(n):
        one_by_one.add(int(channel[k]), complex(c_s[k]), complex(c_p[k]), complex(y[k]))
    for part in (slice(0, 150), slice(150, n)):
        for c in (0, 2):
            pick = np.flatnonzero(channel[part] == c) + part.start
            from_arrays.add_arrays(c, c_s[pick], c_p[pick], y[pick])
    definition = {'ss': np.sum(abs(c_s) ** 2), 'sp': np.sum(np.conj(c_s) * c_p),
                  'pp': np.sum(abs(c_p) ** 2), 'ys': np.sum(np.conj(c_s) * y),
                  'yp': np.sum(np.conj(c_p) * y), 'yy': np.sum(abs(y) ** 2)}
    for sums in (one_by_one, from_arrays):
        for name, value in definition.items():
            assert getattr(sums, name) == pytest.approx(value, rel=1e-12), name
        for c in range(3):
            mine = channel == c
            assert sums.count[c] == mine.sum()
            assert sums.sb[c] == pytest.approx(np.sum(np.conj(c_s[mine])), abs=1e-9)
            assert sums.pb[c] == pytest.approx(np.sum(np.conj(c_p[mine])), abs=1e-9)
            assert sums.yb[c] == pytest.approx(np.sum(y[mine]), abs=1e-9)
    design = np.column_stack([c_s, c_p, channel == 0, channel == 2]).astype(complex)
    theta = np.linalg.lstsq(design, y, rcond=None)[0]
    residual = y - design @ theta
    sigma = math.sqrt(np.sum(abs(residual) ** 2) / (2 * n - 2 * 4))
    inverse = np.linalg.inv(design.conj().T @ design)[:2, :2]
    for sums in (one_by_one, from_arrays):
        fit = sums.solve()
        assert fit.identifiable and fit.readings == n
        assert fit.static == pytest.approx(theta[0], rel=1e-10)
        assert fit.products == pytest.approx(theta[1], rel=1e-10)
        assert fit.biases[0] == pytest.approx(theta[2], rel=1e-10) and fit.biases[1] == 0j
        assert fit.biases[2] == pytest.approx(theta[3], rel=1e-10)
        assert fit.sigma == pytest.approx(sigma, rel=1e-6)
        np.testing.assert_allclose(fit.inverse, inverse, rtol=1e-10, atol=1e-16)


def test_what_cannot_be_told_is_said_whole():
    """Too few readings: nothing identified, every interval infinite, the count kept."""
    from cvc_balance.identify.fit import Sums
    sums = Sums(2)
    sums.add(0, 1.0 + 0j, 0.5j, 2.0 + 0j)
    fit = sums.solve()
    assert (fit.static, fit.products, fit.biases, fit.sigma, fit.readings,
            fit.identifiable) == (0j, 0j, (0j, 0j), math.inf, 1, False)
    assert fit.inverse.shape == (2, 2) and np.all(fit.inverse == math.inf)


def test_unbalance_and_its_circles_from_a_fit_by_hand():
    """
    Static, couple and plane unbalance of a fit, and each 95 % radius, by hand.

    With S and P about O from the fit, the centre of mass at z_c and planes z_I < z_II
    (b = z_II - z_I): static S (weights (1, 0)); couple P - z_c S ((-z_c, 1)); planes
    U_I = (z_II S - P) / b ((z_II / b, -1 / b)) and U_II = (P - z_I S) / b ((-z_I / b,
    1 / b)). A vector w_S S + w_P P has the 95 % radius sqrt(chi2_2(0.95) sigma^2 w^H N w)
    with chi2_2(0.95) = -2 ln 0.05. The residual is identified - declared with the fit's
    radii; the layout's own unbalance is exact (radius 0); not identifiable carries through.
    """
    from cvc_balance.identify.estimate import rotor_with
    from cvc_balance.identify.fit import Estimate
    model = RotorModel.from_layout(parse_layout({
        'name': 'offset', 'supports': [{'name': 'a', 'z': -0.5},
                                       {'name': 'b', 'z': 0.5, 'axial': True}],
        'components': [{'name': 'drum', 'mass': 30.0, 'radius': 0.0, 'angle': 0.0, 'z': 0.1},
                       {'name': 'tube', 'mass': 10.0, 'radius': 0.5, 'angle': 0.3, 'z': -0.2}],
        'balancing': {'planes': [-0.3, 0.4]}}))
    z_c, (z_1, z_2) = (30.0 * 0.1 - 10.0 * 0.2) / 40.0, (-0.3, 0.4)
    b = z_2 - z_1
    s, p, sigma = 0.2 - 0.7j, 0.05 + 0.02j, 3.0
    inverse = np.array([[2e-6, 1e-7 + 2e-7j], [1e-7 - 2e-7j, 5e-6]])
    fit = Estimate(s, p, (1.0 + 0j,), sigma, inverse, 1000, True)
    chi2 = -2.0 * math.log(0.05)

    def radius(w_s, w_p):
        w = np.array([w_s, w_p])
        return math.sqrt(chi2 * sigma ** 2 * float(np.real(np.conj(w) @ inverse @ w)))
    found = identified_unbalance(model, fit)
    expected = [(found.static, s, (1.0, 0.0)), (found.couple, p - z_c * s, (-z_c, 1.0)),
                (found.planes[0][1], (z_2 * s - p) / b, (z_2 / b, -1.0 / b)),
                (found.planes[1][1], (p - z_1 * s) / b, (-z_1 / b, 1.0 / b))]
    for vector, value, weights in expected:
        assert vector.value == pytest.approx(value, rel=1e-14, abs=1e-16)
        assert vector.ci95 == pytest.approx(radius(*weights), rel=1e-12)
    assert [z for z, _ in found.planes] == [z_1, z_2] and found.identifiable
    declared = layout_unbalance(model)
    assert declared.identifiable
    assert all(v.ci95 == 0.0 for v in (declared.static, declared.couple,
                                       declared.planes[0][1], declared.planes[1][1]))
    u = 10.0 * 0.5 * complex(math.cos(0.3), math.sin(0.3))
    declared_values = [u, u * (-0.2 - z_c), u * (z_2 + 0.2) / b, u * (-0.2 - z_1) / b]
    off = residual(found, declared)
    pairs = zip((off.static, off.couple, off.planes[0][1], off.planes[1][1]), expected,
                declared_values)
    for vector, (_, value, weights), known in pairs:
        assert vector.value == pytest.approx(value - known, rel=1e-13, abs=1e-15)
        assert vector.ci95 == pytest.approx(radius(*weights), rel=1e-12)
    assert off.identifiable
    assert rotor_with(model, s, p).layout is model.layout     # the verdict reads it
    blind = identified_unbalance(model, Estimate(s, p, (0j,), math.inf,
                                                 np.full((2, 2), math.inf), 3, False))
    assert not blind.identifiable and not residual(blind, declared).identifiable
    assert blind.static.ci95 == math.inf and blind.planes[1][1].ci95 == math.inf


def test_the_fits_edges_against_numpy():
    """
    Small regressors, a channel of one reading, exactly as many readings as unknowns.

    Regressors of 1e-3 (every normal-equation diagonal under 1) are still a fit; a channel
    with a single reading has its bias fitted to it (numpy's least squares with that
    column), so it leaves S and P alone; n readings for n complex unknowns leave no degree
    of freedom for the noise: not identifiable.
    """
    from cvc_balance.identify.fit import Sums
    rng = np.random.default_rng(11)
    n = 60
    c_s = 1e-3 * (rng.normal(size=n) + 1j * rng.normal(size=n))
    c_p = 1e-3 * (rng.normal(size=n) + 1j * rng.normal(size=n))
    channel = np.zeros(n, int)
    channel[17] = 1                                  # channel 1: one reading
    y = 40.0 * c_s - 7.0j * c_p + np.where(channel == 1, 9.0, 2.0) \
        + 1e-4 * (rng.normal(size=n) + 1j * rng.normal(size=n))
    sums = Sums(2)
    for k in range(n):
        sums.add(int(channel[k]), complex(c_s[k]), complex(c_p[k]), complex(y[k]))
    assert sums.ss < 1.0 and sums.pp < 1.0
    fit = sums.solve()
    design = np.column_stack([c_s, c_p, channel == 0, channel == 1]).astype(complex)
    theta = np.linalg.lstsq(design, y, rcond=None)[0]
    assert fit.identifiable
    assert fit.static == pytest.approx(theta[0], rel=1e-8)
    assert fit.products == pytest.approx(theta[1], rel=1e-8)
    assert fit.biases[1] == pytest.approx(theta[3], rel=1e-8)
    exact = Sums(1)
    for k in range(3):                               # 3 readings, 3 unknowns (S, P, bias)
        exact.add(0, complex(c_s[k]), complex(c_p[k]), complex(y[k]))
    assert not exact.solve().identifiable and exact.solve().sigma == math.inf
    exact.add(0, complex(c_s[3]), complex(c_p[3]), complex(y[3]))
    assert exact.solve().identifiable
