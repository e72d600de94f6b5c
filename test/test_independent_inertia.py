"""
The layout's aggregates (:func:`cvc_balance.physics.inertia.place`) against sums by hand.

Components on the rotor's X axis (angle 0: cos 1 and sin 0 exactly) with dyadic masses,
radii and heights make every aggregate a sum of dyadic terms, whose exact value
``fractions.Fraction`` gives; the aggregates must be those values, correctly rounded, also
where a float64 sum of the same terms loses their last bits.
"""

from fractions import Fraction

import mpmath as mp
import numpy as np

from cvc_balance.physics.inertia import place


def test_each_aggregate_is_its_exact_sum_where_a_float_sum_loses_the_last_bits():
    """1 + 2^-53 + 2^-53 in float64 is 1 (each half-unit rounds to even); exactly 1 + 2^-52."""
    tiny = 2.0 ** -53
    mass, radius, z = [1.0, tiny, tiny], 2.0, 0.5
    got = place(mass, None, radius, 0.0, z)
    factor = 1 + Fraction(2, 2 ** 53)                        # sum of the masses, exactly

    def rounded(value):
        return float(Fraction(value) * factor)
    assert got.mass == rounded(1) == 1.0 + 2.0 ** -52
    assert got.first_moment.tolist() == [rounded(radius), 0.0, rounded(z)]
    x2, z2, xz = radius * radius, z * z, radius * z
    want = [[rounded(z2), 0.0, -rounded(xz)],
            [0.0, float(Fraction(x2 + z2) * factor), 0.0],
            [-rounded(xz), 0.0, rounded(x2)]]
    assert got.inertia.tolist() == want
    # The same terms summed in float64 lose them: what the extraction is for.
    assert float(np.sum(np.array(mass) * radius)) == radius


def test_each_turned_own_tensor_is_its_exact_value_rounded():
    """
    One body at the axis: its tensor turned by theta, each element correctly rounded (mpmath).

    R I R^T with R the turn by theta about z, at 50 digits; where an element cancels (a
    product of inertia near 0) within 1e-30 of the tensor's size instead.
    """
    rng = np.random.default_rng(8)
    special = [[[2.0, 0.5, 0.1], [0.5, 2.0, 0.2], [0.1, 0.2, 3.0]],    # I_xx = I_yy, I_xy
               [[1.0, 0.0, 0.1], [0.0, 2.0, 0.2], [0.1, 0.2, 3.0]],    # no I_xy
               [[1.0, 0.3, 0.0], [0.3, 2.0, 0.0], [0.0, 0.0, 3.0]],    # no I_xz, I_yz
               [[1.0, 0.3, 0.2], [0.3, 2.0, 0.0], [0.2, 0.0, 3.0]],    # no I_yz
               [[1.0, 0.3, 0.0], [0.3, 2.0, 0.2], [0.0, 0.2, 3.0]]]    # no I_xz
    for k in range(60):
        a = rng.uniform(0.5, 2.0, (3, 3))
        tensor = special[k % 5] if k < 30 else (a @ a.T).tolist()     # then all six differ
        angle = float(rng.uniform(-3.2, 3.2))
        got = place(1.0, tensor, 0.0, angle, 0.0).inertia
        with mp.workdps(50):
            c, s = mp.cos(angle), mp.sin(angle)
            turn = mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            want = turn * mp.matrix(tensor) * turn.T
            size = max(abs(v) for v in tensor[0] + tensor[1] + tensor[2])
            for i in range(3):
                for j in range(3):
                    assert got[i, j] == float(want[i, j]) or \
                        abs(got[i, j] - want[i, j]) <= 1e-30 * size, (angle, i, j)


def test_the_second_moments_of_full_precision_point_masses_are_rounded_once():
    """
    I_zz = m R^2 at any angle (x^2 + y^2 = R^2), and I_xx = m z^2 on the X axis (Fraction).

    Masses, radii and heights of 53 significant bits: the products' low parts matter.
    """
    rng = np.random.default_rng(9)
    for _ in range(40):
        m, r, z = (float(v) for v in rng.uniform(0.1, 10.0, 3))
        m_, r_, z_ = Fraction(m), Fraction(r), Fraction(z)
        turned = place(m, None, r, float(rng.uniform(-3.2, 3.2)), z).inertia
        assert turned[2, 2] == float(m_ * r_ * r_), (m, r, z)
        on_x = place(m, None, r, 0.0, z)
        assert on_x.inertia[0, 0] == float(m_ * z_ * z_)
        assert on_x.inertia[1, 1] == float(m_ * (r_ * r_ + z_ * z_))
        assert on_x.inertia[0, 2] == float(-m_ * r_ * z_)
        assert on_x.first_moment.tolist() == [float(m_ * r_), 0.0, float(m_ * z_)]
