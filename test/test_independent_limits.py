"""The limits' words (cvc_balance/physics/limits.py), each message written out by hand."""

import pytest

from cvc_balance.physics.limits import check, Limit


def test_a_limits_message_in_full():
    grade = Limit(0.1, 4000.0, 'mm/s', 'ISO 21940-11 grades')
    assert grade.describe() == 'from 0.1 to 4000 mm/s'
    assert grade.message('layout: field balancing.grade', 1e-300) == (
        'layout: field balancing.grade must be from 0.1 to 4000 mm/s (ISO 21940-11 grades), '
        'got 1e-300 mm/s')
    # Whole numbers and the shorter text that reads back as the value; no unit, no space.
    count = Limit(1, 64, '', 'a few')
    assert count.describe() == 'from 1 to 64'
    assert count.message('--workers', 65) == '--workers must be from 1 to 64 (a few), got 65'
    assert count.message('x', 100000.0) == 'x must be from 1 to 64 (a few), got 100000'
    assert count.message('x', 1234567.0) == 'x must be from 1 to 64 (a few), got 1234567.0'
    symmetric = Limit(-5.0, 5.0, 'm', 'inside the machine')
    assert symmetric.describe() == 'within +-5 m'
    assert check(5.0, symmetric, 'z') == 5.0
    with pytest.raises(KeyError) as caught:
        check(-5.5, symmetric, 'z', KeyError)
    assert caught.value.args[0] == 'z must be within +-5 m (inside the machine), got -5.5 m'
    assert not symmetric.contains(float('nan'))
