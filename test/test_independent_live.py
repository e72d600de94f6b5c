"""
The live fit's bookkeeping by hand: revolutions counted, readings taken or dropped, channels.

A rotor turned by steps of 1 rad closes a revolution each time the angle turned reaches
2 pi (the remainder carried): floor(steps / 2 pi) of them, backwards as forwards. Which
readings are summed, and into which channel, read back from the sums' per-channel counts
and sums of readings (``count``, ``yb``): a reading is taken within 0.05 s of the latest
motion sample, both ways, at most 1e12 in every component (moment too); a moment only for
a single support, in its own channel.
"""

import copy
import math
from pathlib import Path

import pytest
import yaml

from cvc_balance.identify.live import SlidingFit
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
MODEL = RotorModel.from_layout(parse_layout(GANTRY))


def test_a_window_of_less_than_a_revolution_is_refused():
    for bad in (0, 0.5, -1, math.nan):
        with pytest.raises(ValueError) as caught:
            SlidingFit(MODEL.supports, -9.8, window_revs=bad)
        assert str(caught.value) == f'window must be >= 1 revolution, got {bad}'
    live = SlidingFit(MODEL.supports, -9, window_revs=2.7)
    assert (live.window_revs, live.g_z, live.revolutions, live.dropped) == (2, -9.0, 0, 0)
    assert type(live.g_z) is float
    assert SlidingFit(MODEL.supports, 0.0, window_revs=1).window_revs == 1
    assert SlidingFit(MODEL.supports, 0.0).window_revs == 10          # the default


def test_revolutions_are_counted_by_the_angle_turned_either_way():
    live = SlidingFit(MODEL.supports, 0.0)
    for k in range(40):
        steps = k if k < 20 else 19 + (k - 19)          # 19 steps forward, then back
        angle = k if k < 20 else 19 - (k - 19)
        live.motion(0.01 * k, math.remainder(float(angle), 2 * math.pi), 10.0, 0.0)
        assert live.revolutions == math.floor(steps / (2 * math.pi)), k


def test_the_window_holds_its_revolutions_and_the_one_under_way():
    """
    One reading a revolution, window 2: after 6 closed, 2 + the 1 under way.

    Five steps of 1.3 rad a revolution: 6.5 k rad after k of them, each closing at its
    last step (6.5 k >= 2 pi k > 6.5 k - 1.3 for k <= 6).
    """
    live = SlidingFit(MODEL.supports, 0.0, window_revs=2)
    live.motion(0.0, 0.0, 10.0, 0.0)
    turned = 0.0
    for k in range(1, 7):
        assert live.reading('front', 0.01 * k - 0.005, (float(k), 0.0))
        for step in range(5):
            turned += 1.3
            live.motion(0.01 * k, math.remainder(turned, 2 * math.pi), 10.0, 0.0)
        assert live.revolutions == k
    assert live.reading('front', 0.065, (7.0, 0.0))
    sums = live.sums()
    assert sums.count == [3, 0] and sums.yb == [5.0 + 6.0 + 7.0 + 0j, 0j]


def test_which_readings_are_taken_and_where_they_go():
    live = SlidingFit(MODEL.supports, 0.0)
    live.motion(0.0, 0.0, 10.0, 0.0)
    assert live.reading('rear', 0.05, (3.0, 4.0))                  # 0.05 s after: taken
    assert live.reading('rear', -0.05, (1.0, 0.0))                 # 0.05 s before: taken
    assert not live.reading('rear', 0.05 + 1e-9, (1.0, 0.0))
    assert not live.reading('rear', -0.05 - 1e-9, (1.0, 0.0))
    assert live.reading('front', 0.0, (1.0, 2.0), moment=(5.0, 6.0))    # two supports
    assert not live.reading('front', 0.0, (1.0, 2.0), moment=(2e12, 0.0))
    assert not live.reading('front', 0.0, (1.0, 2.0), moment=(0.0, math.nan))
    assert live.reading('front', 0.0, (-1e12, 1e12))
    sums = live.sums()
    assert sums.count == [2, 2] and sums.yb == [(1 - 1e12) + (2 + 1e12) * 1j, 4.0 + 4.0j]
    assert live.dropped == 4


def test_a_single_supports_moment_goes_into_its_own_channel():
    single = copy.deepcopy(GANTRY)
    single['supports'] = [{'name': 'only', 'z': 0.0, 'axial': True}]
    model = RotorModel.from_layout(parse_layout(single))
    live = SlidingFit(model.supports, 0.0)
    live.motion(0.0, 0.3, 10.0, 0.0)
    assert live.reading('only', 0.001, (1.0, 2.0), moment=(5.0, 6.0))
    assert live.reading('only', 0.002, (3.0, 4.0))
    sums = live.sums()
    assert sums.count == [2, 1] and sums.yb == [4.0 + 6.0j, 5.0 + 6.0j]
