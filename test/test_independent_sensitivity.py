"""
A component's aggregates and their derivatives on grids, by complex numbers (design).

Written another way than the code's real and imaginary parts: a component of mass m at
(R, theta, z) with own products p' = p_x' + i p_y' (kg m^2, its own frame) adds m, the
first moment S = m R e^(i theta), m z and the products P = (m R z + p') e^(i theta)
about O (the own products turn with it). Their derivatives by the parameters: d/dm
(1, R e, z, R z e), d/dR (0, m e, 0, m z e), d/dtheta (0, i S, 0, i P), d/dz (0, 0, m,
m R e), e = e^(i theta). Checked on a 2 x 3 grid of components, with and without own
products, and against central differences of the aggregates themselves.
"""

import numpy as np

from cvc_balance.design.sensitivity import aggregate_derivatives, component_aggregates

RNG = np.random.default_rng(29)
M, R = RNG.uniform(0.5, 5.0, (2, 3)), RNG.uniform(0.0, 0.7, (2, 3))
THETA, Z = RNG.uniform(-np.pi, 2 * np.pi, (2, 3)), RNG.uniform(-0.3, 0.3, (2, 3))
OWN = RNG.uniform(-0.2, 0.2, (2, 3, 2))


def parts(aggregates):
    """(m, S, m z, P) complex from the last axis (mass, s_x, s_y, s_z, p_xz, p_yz)."""
    a = np.moveaxis(aggregates, -1, 0)
    return a[0], a[1] + 1j * a[2], a[3], a[4] + 1j * a[5]


def test_a_components_aggregates_by_complex_numbers():
    e = np.exp(1j * THETA)
    for own, p_own in ((None, 0.0), (OWN, OWN[..., 0] + 1j * OWN[..., 1])):
        got = component_aggregates(M, R, THETA, Z, own)
        assert got.shape == (2, 3, 6)
        m, s, s_z, p = parts(got)
        assert np.array_equal(m, M) and np.allclose(s_z, M * Z, rtol=1e-15, atol=0)
        assert np.allclose(s, M * R * e, rtol=1e-14, atol=1e-16)
        assert np.allclose(p, (M * R * Z + p_own) * e, rtol=1e-14, atol=1e-16)
    one = component_aggregates(2.0, 0.5, 0.0, 0.25)
    assert np.array_equal(one, [2.0, 1.0, 0.0, 0.5, 0.25, 0.0])


def test_their_derivatives_by_complex_numbers_and_by_differences():
    e = np.exp(1j * THETA)
    for own, p_own in ((None, 0.0), (OWN, OWN[..., 0] + 1j * OWN[..., 1])):
        got = aggregate_derivatives(M, R, THETA, Z, own)
        assert got.shape == (2, 3, 4, 6)
        s, p = M * R * e, (M * R * Z + p_own) * e
        want = [(1.0, R * e, Z, R * Z * e), (0.0, M * e, 0.0, M * Z * e),
                (0.0, 1j * s, 0.0, 1j * p), (0.0, 0.0, M, M * R * e)]
        for k, expected in enumerate(want):
            for part, value in zip(parts(got[..., k, :]), expected):
                assert np.allclose(part, value, rtol=1e-13, atol=1e-15), k
        # Central differences of the aggregates (step 1e-6): to 1e-8.
        values = [M, R, THETA, Z]
        for k in range(4):
            up, down = list(values), list(values)
            up[k], down[k] = values[k] + 1e-6, values[k] - 1e-6
            diff = (component_aggregates(*up, own) - component_aggregates(*down, own)) / 2e-6
            assert np.allclose(got[..., k, :], diff, rtol=1e-7, atol=1e-8), k
    one = aggregate_derivatives(2.0, 0.5, 0.0, 0.25)
    assert one.shape == (4, 6)
    assert np.array_equal(one[2], [0.0, -0.0, 1.0, 0.0, -0.0, 0.25])


def test_a_two_mass_layouts_balance_and_its_couple_by_mass_by_hand():
    """
    Give a two-mass layout's balance and its couple's derivatives by hand.

    A: 1 kg at 0.5 m, 0 deg, z -0.2; B: 2 kg at 0.25 m, 90 deg, z 0.3; planes -+0.4 m,
    supports -+0.5 m, 10 rad/s. S = 0.5 + 0.5 i kg m, P = -0.1 + 0.15 i kg m^2, z_com =
    0.4 / 3 m, couple C = P - z_com S; planes by the lever rule over b = 0.8; supports
    w^2 (P - z_front S) / 1 m at the rear, w^2 S less that at the front; size sum m R.
    dC/dm_A = R_A z_A - (z_A - z_com) / 3 S - z_com R_A.
    """
    from cvc_balance.design.sensitivity import sensitivities
    from cvc_balance.physics.engine import RotorModel
    from cvc_balance.physics.layout import parse_layout
    layout = parse_layout({
        'name': 'two', 'gravity': [0.0, -9.8, 0.0],
        'components': [{'name': 'A', 'mass': 1.0, 'radius': 0.5, 'angle_deg': 0.0, 'z': -0.2},
                       {'name': 'B', 'mass': 2.0, 'radius': 0.25, 'angle_deg': 90.0,
                        'z': 0.3}],
        'supports': [{'name': 'front', 'z': -0.5}, {'name': 'rear', 'z': 0.5, 'axial': True}],
        'balancing': {'planes': [-0.4, 0.4], 'grade': 6.3, 'service_speed': 10.0}})
    found = sensitivities(RotorModel.from_layout(layout), 10.0)
    b = found.nominal
    s, p, z_com = 0.5 + 0.5j, -0.1 + 0.15j, 0.4 / 3.0
    couple = p - z_com * s
    rear = 100.0 * (p + 0.5 * s)

    def pairs(*values):
        return [[v.real, v.imag] for v in values]
    assert np.allclose(b.static, pairs(s)[0], rtol=1e-14, atol=1e-16)
    assert np.allclose(b.couple, pairs(couple)[0], rtol=1e-13, atol=1e-16)
    assert np.allclose(b.planes, pairs(0.5 * 0.6 / 0.8 + 0.5j * 0.1 / 0.8,
                                       0.5 * 0.2 / 0.8 + 0.5j * 0.7 / 0.8), rtol=1e-13)
    assert np.allclose(b.supports, pairs(100.0 * s - rear, rear), rtol=1e-13)
    assert b.omega == 10.0 and found.size == 1.0
    assert str(found.parameters[0]) == "DesignParameter(index=0, component='A', name='mass')"
    d_couple = 0.5 * -0.2 - (-0.2 - z_com) / 3.0 * s - z_com * 0.5
    assert np.allclose(found.couple[0], pairs(d_couple)[0], rtol=1e-12, atol=1e-16)
    assert np.allclose(found.products[0], [0.5 * -0.2, 0.0], rtol=1e-14, atol=1e-16)
    # dC/dR_A = m_A (z_A - z_com) (its mass does not move: the centre of mass stays).
    named = [(q.component, q.name) for q in found.parameters]
    row = named.index(('A', 'radius'))
    assert np.allclose(found.couple[row], [1.0 * (-0.2 - z_com), 0.0], rtol=1e-12, atol=1e-16)
    assert np.isfinite(found.couple).all()


def test_the_norms_slopes_and_the_judged_vectors_by_hand():
    """
    Give the norm's slopes and the judged vectors by hand.

    |v| along d: v.d / |v| either side ((3, 4), (1, 2): 11 / 5); at balance (|v| <= 8 eps
    of the size, that bound included) a kink: -|d| below, +|d| above. Judged vectors: the
    two planes', or the static unbalance alone without planes.
    """
    from cvc_balance.design.sensitivity import judged_vectors, norm_slopes
    from cvc_balance.physics.layout import parse_layout
    minus, plus = norm_slopes([[3.0, 4.0], [0.0, 0.0], [8 * np.finfo(float).eps, 0.0]],
                              [[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]], 1.0)
    assert np.allclose(minus, [2.2, -np.sqrt(5.0), -np.sqrt(5.0)], rtol=1e-15)
    assert np.allclose(plus, [2.2, np.sqrt(5.0), np.sqrt(5.0)], rtol=1e-15)
    parts = [{'name': 'A', 'mass': 1.0, 'radius': 0.5, 'angle_deg': 0.0, 'z': 0.1}]
    one = parse_layout({'name': 'one', 'components': parts, 'gravity': [0.0, 0.0, -9.8],
                        'supports': [{'name': 'only', 'z': 0.0, 'axial': True}]})
    got = judged_vectors(one, np.array([[0.5, 0.25]]), np.array([[0.05, 0.0]]))
    assert got.shape == (1, 1, 2) and np.array_equal(got[0, 0], [0.5, 0.25])
    two = parse_layout({'name': 'two', 'components': parts, 'gravity': [0.0, -9.8, 0.0],
                        'supports': [{'name': 'a', 'z': -0.5},
                                     {'name': 'b', 'z': 0.5, 'axial': True}]})
    planes = judged_vectors(two, np.array([0.5, 0.0]), np.array([0.05, 0.0]))
    assert np.allclose(planes, [[0.5 * 0.4, 0.0], [0.5 * 0.6, 0.0]], rtol=1e-14)
