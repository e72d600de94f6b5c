"""
Where methods fail, and the engine must not: each regime judged by extended precision.

* double-double arithmetic (cvc_balance.physics.compensated) against mpmath at 60 digits;
* near-balance: a rotor balanced to 1e-9 of its mass moment keeps its residual;
* 10^6 components, balanced in pairs to ~1e-11, against aggregates summed exactly
  (dyadic masses, radii and offsets on 64 angles: integer sums times 60-digit cosines);
* tilt through the Euler angles' gimbal lock (nutation 0 and pi): the engine has no
  angle singularity; the ZXZ angle rates of the same motion are 0/0 there.
"""

from fractions import Fraction
import math

import mpmath as mp
import numpy as np
import pytest

from cvc_balance.physics import compensated
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.inertia import place
from cvc_balance.physics.layout import parse_layout
from cvc_balance.study.bench import _near_balance, _relative
from cvc_balance.study.exact import body_load, gravity_in_rotor
from cvc_balance.study.methods import zxz_angle_rates
from reference import method_error, random_layout


def mp_value(dd):
    return mp.mpf(float(dd[0])) + mp.mpf(float(dd[1]))


def test_double_double_cos_sin_to_thirty_digits():
    rng = np.random.default_rng(5)
    angles = np.concatenate([rng.uniform(-30.0, 30.0, 300), [0.0, 1e-300, -5e-324],
                             np.pi * np.arange(-4, 5) / 4, [1e6 + 0.3, 2.0 ** 30]])
    (c_hi, c_lo), (s_hi, s_lo) = compensated.cos_sin(angles)
    with mp.workdps(60):
        for k, angle in enumerate(angles):
            exact_cos, exact_sin = mp.cos(mp.mpf(angle)), mp.sin(mp.mpf(angle))
            assert abs(mp_value((c_hi[k], c_lo[k])) - exact_cos) < 1e-31
            assert abs(mp_value((s_hi[k], s_lo[k])) - exact_sin) < 1e-31
            if 0 < abs(angle) < 1e-8:                   # tiny angles: sin x = x, relative
                assert abs(mp_value((s_hi[k], s_lo[k])) / exact_sin - 1) < 1e-30


def test_double_double_sum_of_products_is_within_an_ulp_of_the_exact_sum():
    rng = np.random.default_rng(6)
    a = rng.normal(size=20001) * 10.0 ** rng.integers(-8, 8, 20001)
    b = rng.normal(size=20001)
    b[-1] = -a[:-1] @ b[:-1] / a[-1]                   # the float dot product cancels
    exact = sum(Fraction(x) * Fraction(y) for x, y in zip(a, b))
    ulp = np.spacing(abs(float(exact)))                 # sum ~2e-7 of terms up to 1e8
    assert abs(compensated.total(compensated.two_prod(a, b)) - float(exact)) <= ulp
    assert abs(float(a @ b) - float(exact)) > 1e6 * ulp  # what float64 alone gives


def near_balanced_layout(seed):
    rng = np.random.default_rng(seed)
    layout = parse_layout(random_layout(rng, n=10, supports=2, tilt=False, every_kind=True))
    return _near_balance(layout), rng


def test_engine_keeps_the_residual_of_a_rotor_balanced_to_1e_9():
    layout, rng = near_balanced_layout(7)
    q, omega, alpha = rng.uniform(0, 6, 16), np.full(16, 23.27), rng.uniform(-2, 2, 16)
    gravity = (0.0, 0.0, 0.0)              # a balancing machine: only the unbalance loads
    errors = {name: method_error(name, layout, q, omega, alpha, gravity)
              for name in ('aggregated', 'newton_euler', 'particles_1')}
    assert errors['aggregated'] < 1e-15                   # measured 2.0e-16
    # The regime is real: summing per body in float64 keeps ~7 digits of 16 (Newton-Euler:
    # measured 6.0e-7); point masses lose the bodies' own inertia besides (1.8e-2).
    assert errors['newton_euler'] > 1e-8 and errors['particles_1'] > 1e-8


def million_component_layout():
    """
    10^6 point masses and boxes in mirrored pairs (theta, fl(theta + pi)), plus 1 g at 0.5 m.

    Masses k/64 kg, radii, offsets and box edges k/1024 m: every product of them is
    an exact binary fraction, so each aggregate is an integer sum (exact in int64) per
    angle times 60-digit cosines. Returns the arrays for place() and the exact sums.
    """
    rng = np.random.default_rng(8)
    half, groups = 500_000, 32
    base = rng.uniform(0.0, math.pi, groups)
    angle_of_group = np.concatenate([base, base + math.pi])   # floats: pairs not exact
    group = np.concatenate([rng.integers(0, groups, half)] * 2)
    group[half:] += groups
    k_m = np.concatenate([rng.integers(64, 3840, half)] * 2)        # 1 to 60 kg
    k_r = np.concatenate([rng.integers(200, 720, half)] * 2)        # 0.2 to 0.7 m
    k_z = np.concatenate([rng.integers(-300, 300, half)] * 2)       # -0.3 to 0.3 m
    k_a = np.concatenate([rng.integers(0, 300, half)] * 2)          # box edges, 0: point
    k_b = np.concatenate([rng.integers(0, 300, half)] * 2)
    # The residual: 1 g at 0.5 m, angle 0.
    group, k_m, k_r, k_z = (np.append(group, 2 * groups), np.append(k_m, 0),
                            np.append(k_r, 512), np.append(k_z, 0))
    k_a, k_b = np.append(k_a, 0), np.append(k_b, 0)
    angle_of_group = np.append(angle_of_group, 0.0)
    mass = k_m / 64.0
    mass[-1] = 1e-3

    order = np.argsort(group, kind='stable')
    starts = np.searchsorted(group[order], np.arange(2 * groups + 1))

    def per_group(values):
        return [int(v) for v in np.add.reduceat(values[order].astype(np.int64), starts)]

    mr = per_group(k_m * k_r)
    mrz = per_group(k_m * k_r * k_z)
    mz = per_group(k_m * k_z)
    mrr = per_group(k_m * k_r * k_r)
    own_zz = per_group(k_m * (k_a * k_a + k_b * k_b))
    # The residual's group holds only the gram: its sums from its own numbers.
    mr[-1], mrz[-1], mz[-1], mrr[-1], own_zz[-1] = 0, 0, 0, 0, 0
    with mp.workdps(60):
        scale_m, scale_l = mp.mpf(1) / 64, mp.mpf(1) / 1024      # exact in binary
        residual = mp.mpf(1e-3) * mp.mpf(0.5)
        cos = [mp.cos(mp.mpf(a)) for a in angle_of_group]
        sin = [mp.sin(mp.mpf(a)) for a in angle_of_group]
        s_x = sum(scale_m * scale_l * mr[j] * cos[j] for j in range(len(cos))) + residual
        s_y = sum(scale_m * scale_l * mr[j] * sin[j] for j in range(len(cos)))
        s_z = mp.mpf(sum(mz)) * scale_m * scale_l
        p_xz = sum(scale_m * scale_l ** 2 * mrz[j] * cos[j] for j in range(len(cos)))
        p_yz = sum(scale_m * scale_l ** 2 * mrz[j] * sin[j] for j in range(len(cos)))
        i_zz = (mp.mpf(sum(mrr)) * scale_m * scale_l ** 2 + mp.mpf(1e-3) / 4
                + mp.mpf(sum(own_zz)) * scale_m * scale_l ** 2 / 12)
        total_mass = mp.mpf(int(k_m.sum())) * scale_m + mp.mpf(1e-3)
    a, b = k_a / 1024.0, k_b / 1024.0
    own = np.zeros((mass.size, 3, 3))
    own[:, 0, 0] = mass * b * b / 12.0                 # box (a, b, 0): edges radial, tangential
    own[:, 1, 1] = mass * a * a / 12.0
    own[:, 2, 2] = mass * (a * a + b * b) / 12.0
    arrays = (mass, own, k_r / 1024.0, angle_of_group[group], k_z / 1024.0)
    return arrays, (total_mass, s_x, s_y, s_z, p_xz, p_yz, i_zz)


@pytest.fixture(scope='module')
def million():
    return million_component_layout()


def test_a_million_components_keep_a_residual_of_1e_11_of_their_mass_moment(million):
    arrays, exact = million
    body = place(*arrays)
    with mp.workdps(60):
        def rel(got, want):
            return float(abs(mp.mpf(float(got)) - want) / abs(want))
        # Sum |m R| ~ 1.5e7 kg m against a residual of 5e-4 kg m (S_y, P: pair mismatches).
        got = (body.mass, *body.first_moment, -body.inertia[0, 2], -body.inertia[1, 2],
               body.inertia[2, 2])
        for value, want in zip(got, exact):      # measured 5.9e-16 (P_xz), others < 1e-16
            assert rel(value, want) < 2e-15
    # Loads of the model built on these aggregates, against the exact ones.
    model = RotorModel(None, body, body.mass, *body.first_moment, -body.inertia[0, 2],
                       -body.inertia[1, 2], body.inertia[2, 2], (0.0, 0.0, 0.0))
    from cvc_balance.physics.engine import rotor_frame_loads
    q = np.linspace(0.0, 6.0, 7)
    omega, alpha = np.full(7, 23.27), np.full(7, 1.5)
    got = rotor_frame_loads(model, np.cos(q), np.sin(q), omega, alpha, (0.0, 0.0, 0.0))
    force, moment, torque = exact_body_loads(exact, q, omega, alpha)
    # Measured: 2.1e-16, 7.3e-17 and 0.
    assert _relative(np.stack(got[:2], 1), force[:, :2]) < 1e-15
    assert _relative(np.stack(got[3:5], 1), moment[:, :2]) < 1e-15
    assert _relative(got[5], torque) < 1e-15


def exact_body_loads(sums, q, omega, alpha):
    """
    Newton-Euler about O of the whole rotor from its exact mass properties (60 digits).

    ``sums`` = (mass, S_x, S_y, S_z, P_xz, P_yz, I_zz); for a spin about Z only the
    tensor's third column enters (I alpha e_z + omega e_z x I omega e_z), so the other
    elements are left at 0. No gravity (a balancing machine).
    """
    mass, s_x, s_y, s_z, p_xz, p_yz, i_zz = sums
    inertia = [[0, 0, -p_xz], [0, 0, -p_yz], [-p_xz, -p_yz, i_zz]]
    forces, moments, torques = [], [], []
    with mp.workdps(60):
        for qk, wk, ak in zip(q, omega, alpha):
            f, m, t = body_load(mass, [s_x, s_y, s_z], inertia,
                                gravity_in_rotor(qk, (0, 0, 0)), mp.mpf(wk), mp.mpf(ak))
            forces.append([float(v) for v in f])
            moments.append([float(v) for v in m])
            torques.append(float(t))
    return np.array(forces), np.array(moments), np.array(torques)


def test_float64_sums_lose_the_million_component_residual(million):
    """The same sums in float64 (numpy's pairwise sum): the residual's digits are gone."""
    arrays, exact = million
    mass, _, radius, angle, _ = arrays
    naive = float(np.sum(mass * radius * np.cos(angle)))
    assert abs(naive - float(exact[1])) / float(exact[1]) > 1e-8      # 8.8e-8 here


@pytest.mark.parametrize('tilt', [0.0, 1e-12, 1e-6, math.radians(20), math.pi / 2,
                                  math.pi - 1e-9, math.pi])
def test_engine_has_no_angle_singularity_through_gimbal_lock(tilt):
    """
    A gantry tilted by ``tilt`` about the stator X axis: ZXZ angles (0, tilt, q).

    At nutation 0 or pi the ZXZ rates of the spin are 0/0 (gimbal lock, thesis
    Sec. 6.2); the engine works with q and the gravity vector and stays exact.
    """
    rng = np.random.default_rng(9)
    mapping = random_layout(rng, n=6, supports=2, tilt=False, every_kind=True)
    g = 9.80665
    mapping['gravity'] = [0.0, -g * math.cos(tilt), g * math.sin(tilt)]
    layout = parse_layout(mapping)
    q, omega, alpha = rng.uniform(0, 6, 8), rng.uniform(5, 25, 8), rng.uniform(-4, 4, 8)
    assert method_error('aggregated', layout, q, omega, alpha) < 1e-15   # 2.0e-16 at most
    # The same spin in ZXZ angle rates: (0, 0, omega) about the body axis.
    rates = zxz_angle_rates(0.0, tilt, q[0], (0.0, 0.0, omega[0]))
    if math.sin(tilt) == 0.0:
        assert not np.all(np.isfinite(rates))
    else:
        np.testing.assert_allclose(rates, [0.0, 0.0, omega[0]], atol=1e-15 * omega[0])


def test_zxz_angle_rates_blow_up_near_nutation_zero():
    """A 1e-12 rad/s cross rate becomes a precession rate of ~1e-12 / sin(nutation)."""
    for nutation in (1e-2, 1e-6, 1e-10):
        rates = zxz_angle_rates(0.0, nutation, 0.3, (1e-12, 0.0, 20.0))
        assert abs(rates[0]) == pytest.approx(1e-12 * math.sin(0.3) / math.sin(nutation),
                                              rel=1e-14)          # measured: equal
