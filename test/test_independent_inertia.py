"""
The layout's aggregates (:func:`cvc_balance.physics.inertia.place`) against sums by hand.

Components on the rotor's X axis (angle 0: cos 1 and sin 0 exactly) with dyadic masses,
radii and heights make every aggregate a sum of dyadic terms, whose exact value
``fractions.Fraction`` gives; the aggregates must be those values, correctly rounded, also
where a float64 sum of the same terms loses their last bits.
"""

from fractions import Fraction

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
