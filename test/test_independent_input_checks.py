"""
The node's input checks (:mod:`cvc_balance.ros.input_checks`) in this process, by hand.

The node runs them on its live input (test/test_input_mistakes.py, through a ROS graph,
which a mutation run cannot see); here the same object is fed samples and a fit by hand:
a steady turn at 2 rad/s sampled at 1 kHz, its position in radians or in degrees (the
angle's rate 180 / pi = 57.2958 times the velocity), and cells whose static loads are
their supports' shares, or one of them with its sign reversed. Each status's level, line
and values and each log line are asserted as a person reads them.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from cvc_balance.identify.mistakes import DEGREES_PER_RADIAN
from cvc_balance.physics import assessment
from cvc_balance.ros.input_checks import InputChecks, WINDOW

OMEGA, RATE = 2.0, 1000.0


def turn(checks, seconds, scale=1.0, start=0.0):
    """Feed a steady turn: position ``scale`` x the angle (rad), velocity in rad/s."""
    for t in start + np.arange(int(seconds * RATE)) / RATE:
        checks.sample(float(t), scale * OMEGA * float(t), OMEGA)


def no_cells():
    return SimpleNamespace(cells=SimpleNamespace(found=None), shares={})


def cells(biases, read=('front', 'rear')):
    """Return a layout in force whose cells were fitted with these static loads (N)."""
    shares = {'front': complex(0.0, -3000.0), 'rear': complex(0.0, -1000.0)}
    model = SimpleNamespace(supports=[SimpleNamespace(name='front'),
                                      SimpleNamespace(name='rear')])
    estimate = SimpleNamespace(identifiable=True, biases=np.array(biases))
    return SimpleNamespace(shares=shares, cells=SimpleNamespace(
        found=(estimate,), model=model, readings={name: [1] for name in read}))


def test_before_any_turn_nothing_can_be_told():
    """No samples (or one): OK, 'nothing to check yet', the ratio 'not told yet'."""
    checks = InputChecks()
    for _ in range(2):
        assert checks.status(no_cells()) == (
            assessment.OK, 'inputs: nothing to check yet (no turn, no fit of the cells)',
            {'joint position rate / velocity': 'not told yet', 'input mistakes': ''})
        assert checks.news() == []
        checks.sample(0.0, 0.0, OMEGA)


def test_a_position_in_degrees_is_said_once_and_its_mending_once():
    """
    Degrees: WARN with the ratio by hand (57.3); logged once; radians again: 'agree again'.

    The window holds the last WINDOW samples: after a restart (a new time line) and a
    second of radians the ratio is 1 (exactly: steps and trapezoids of a steady turn).
    """
    checks = InputChecks()
    turn(checks, 0.4, scale=DEGREES_PER_RADIAN)      # turned 0.8 rad: too little to tell
    assert checks.status(no_cells())[0] == assessment.OK
    turn(checks, 0.6, scale=DEGREES_PER_RADIAN, start=0.4)
    level, line, values = checks.status(no_cells())
    said = 'joint position looks like degrees: its rate is 57.3 x the velocity'
    assert (level, line) == (assessment.WARN, said)
    assert math.isclose(values['joint position rate / velocity'], 180.0 / math.pi,
                        rel_tol=1e-12)
    assert values['joint position wraps at'] == 'no wrap seen'
    assert values['input mistakes'] == said
    assert checks.news() == [('warning', f'input mistake? {said}')]
    checks.status(no_cells())
    assert checks.news() == []                        # said once
    checks.restart()
    turn(checks, 1.0, start=10.0)
    level, line, values = checks.status(no_cells())
    assert (level, line) == (assessment.OK,
                             'inputs agree: joint position and velocity (rad, rad/s)')
    assert math.isclose(values['joint position rate / velocity'], 1.0, rel_tol=1e-9)
    assert values['input mistakes'] == ''
    assert checks.news() == [('info', 'inputs agree again')]
    assert checks.news() == []


def test_the_window_forgets_the_oldest_samples():
    """WINDOW (2000) samples in radians after 1000 in degrees: the degrees are out of it."""
    checks = InputChecks()
    turn(checks, 1.0, scale=DEGREES_PER_RADIAN)
    assert checks.status(no_cells())[0] == assessment.WARN
    checks.restart()
    turn(checks, 0.5, scale=DEGREES_PER_RADIAN, start=20.0)
    turn(checks, WINDOW / RATE, start=20.5)
    level, line, values = checks.status(no_cells())
    assert level == assessment.OK, line
    assert math.isclose(values['joint position rate / velocity'], 1.0, rel_tol=1e-9)


def test_cells_against_their_shares():
    """
    Cells reading their shares agree; the rear's sign reversed is named, figures by hand.

    Values per cell: its static load and its share (N, magnitudes). A cell without readings
    is not judged.
    """
    checks = InputChecks()
    turn(checks, 1.0)
    level, line, values = checks.status(cells([complex(0, -3000.0), complex(0, -1000.0)]))
    assert (level, line) == (assessment.OK, "inputs agree: joint position and velocity "
                             "(rad, rad/s) and the cells and their supports' shares")
    assert {k: v for k, v in values.items() if k.startswith('cell')} == {
        'cell front static load [N]': 3000.0, 'cell front share of the weight [N]': 3000.0,
        'cell rear static load [N]': 1000.0, 'cell rear share of the weight [N]': 1000.0}
    level, line, values = checks.status(cells([complex(0, -3000.0), complex(0, 1000.0)]))
    said = ("cell rear reads its support's static load with the sign reversed (1000 N where "
            'its support carries 1000 N)')
    assert (level, line, values['input mistakes']) == (assessment.WARN, said, said)
    assert checks.news() == [('warning', f'input mistake? {said}')]
    level, line, values = checks.status(cells([complex(0, -3000.0), complex(0, 1000.0)],
                                              read=('front',)))
    assert level == assessment.OK and 'cell rear static load [N]' not in values
    checks = InputChecks()
    level, line, _ = checks.status(cells([complex(0, -3000.0), complex(0, -1000.0)]))
    assert line == "inputs agree: the cells and their supports' shares"
    unfit = cells([0j, 0j])
    unfit.cells.found[0].identifiable = False
    assert checks.status(unfit)[1] == \
        'inputs: nothing to check yet (no turn, no fit of the cells)'


def test_a_motion_and_a_cell_mistake_are_both_said():
    """Degrees and a reversed cell: both, in one line ('; '), the values' ' | ', two log lines."""
    checks = InputChecks()
    assert checks.news() == []                 # before any status: nothing to say
    turn(checks, 1.0, scale=DEGREES_PER_RADIAN)
    level, line, values = checks.status(cells([complex(0, -3000.0), complex(0, 1000.0)]))
    motion = 'joint position looks like degrees: its rate is 57.3 x the velocity'
    cell = ("cell rear reads its support's static load with the sign reversed (1000 N where "
            'its support carries 1000 N)')
    assert (level, line) == (assessment.WARN, f'{motion}; {cell}')
    assert values['input mistakes'] == f'{motion} | {cell}'
    assert checks.news() == [('warning', f'input mistake? {motion}'),
                             ('warning', f'input mistake? {cell}')]


# -- identify/mistakes: the findings' figures, and a run's windows -------------------------

def test_each_cell_findings_cause_line_and_figure_by_hand():
    """
    A cell's scale, axes and static load off: each line and figure by hand.

    Shares 3000 N (front) and 1000 N (rear), straight down; the front cell reads its share
    halved (scale: figure 0.5), turned by 90 deg (axes: figure 90), halved and turned
    (static load: figure 0.5).
    """
    from cvc_balance.identify.mistakes import cell_mistakes, Finding
    shares = {'front': complex(0, -3000.0), 'rear': complex(0, -1000.0)}
    cases = {
        complex(0, -1500.0): Finding('scale', "cell front's scale looks off: it reads 0.5 x "
                                     "its support's static load (1500 N where its support "
                                     'carries 3000 N)', 0.5),
        complex(3000.0, 0): Finding('axes', "cell front's axes look turned by 90 deg: its "
                                    "static load points elsewhere than its support's (3000 N "
                                    'where its support carries 3000 N)', 90.0),
        complex(1500.0, 0): Finding('static load', "cell front reads 0.5 x its support's "
                                    'static load, turned by 90 deg (1500 N where its support '
                                    'carries 3000 N)', 0.5)}
    for got, finding in cases.items():
        assert cell_mistakes(shares, {'front': got, 'rear': shares['rear']}) == [finding]


def steady(seconds, omega=5.0, rate=1000.0, start=0.0):
    t = start + np.arange(int(seconds * rate)) / rate
    return t, omega * t, np.full(len(t), omega)


def test_a_position_wrapping_at_360_with_degrees_per_second_has_its_ratio_as_figure():
    """Both in degrees (wrapping at 360): 'wraps at 360', its figure the ratio (1)."""
    from cvc_balance.identify.mistakes import motion_units
    t, q, w = steady(2.0)
    check = motion_units(t, np.degrees(q) % 360.0, np.degrees(w))
    assert check.period == 360.0 and math.isclose(check.ratio, 1.0, rel_tol=1e-9)
    assert (check.finding.cause, check.finding.figure) == ('wraps at 360', check.ratio)


def test_a_runs_windows_spread_from_its_start_to_its_end():
    """
    ``run_motion_findings``: up to 16 windows of 2000 samples from the first to the last.

    3000 samples in degrees: 16 windows (starts 0 to 1000), each finding it; 500 samples
    (less than a window): one; 3000 at rest then 3000 turning: the windows at rest cannot
    tell and are passed over, the later ones find it (told = found, fewer than 16).
    """
    from cvc_balance.identify.mistakes import run_motion_findings
    t, q, w = steady(3.0)
    (found, count, told), = run_motion_findings(t, np.degrees(q), w)
    assert (found.cause, count, told) == ('degrees', 16, 16)
    (found, count, told), = run_motion_findings(t[:500], np.degrees(q[:500]), w[:500])
    assert (found.cause, count, told) == ('degrees', 1, 1)
    t2, q2, w2 = steady(3.0, start=3.0)
    time = np.concatenate([t, t2])
    angle = np.degrees(np.concatenate([np.zeros(3000), q2 - q2[0]]))
    omega = np.concatenate([np.zeros(3000), w2])
    (found, count, told), = run_motion_findings(time, angle, omega)
    assert found.cause == 'degrees' and 0 < count == told < 16


def test_what_a_position_wraps_at_by_hand():
    """
    ``wrap_period`` of step sequences worked by hand.

    A wrap alone between ordinary steps: its length from the steps beside it (counts:
    -3796 beside 300 is 4096; -3096 beside 1000 steps of 1000, 4096; radians: -6.1 beside
    0.1 is 6.2, 2 pi within 10 %), in the middle or one before the end. A position
    wrapping back and forth (4095 -> 1 -> 4095): no wrap alone, the wraps' median plus
    the typical step, 4194 (not within 1 % of 4096). A step of 1.2 rad among 0.1: no
    wrap (not over pi / 2). Two steps: too few to tell.
    """
    from cvc_balance.identify.mistakes import wrap_period
    middle = [100] * 10 + [300, -3796, 300] + [100] * 10
    assert wrap_period(middle) == 4096.0
    assert wrap_period(middle[:13]) == 4096.0                    # one before the end
    assert wrap_period([1000] * 5 + [-3096] + [1000] * 5) == 4096.0
    assert wrap_period([0.1, -6.1, 0.1]) == 2 * math.pi
    assert wrap_period([100] * 10 + [-4094, 4094] + [100] * 10) == 4194.0
    assert wrap_period([0.1] * 5 + [1.2] + [0.1] * 5) is None
    assert wrap_period([0.1, 6.0]) is None


def test_each_motion_findings_figure_is_its_ratio():
    """
    Each finding's figure is the ratio measured; a position in encoder counts is named.

    Steady turns at 5 rad/s: the velocity reversed (-1), in deg/s (1 / 57.3), the position
    in degrees and the velocity in rpm (57.3 / 9.55 = 6), the motor side of a 3:1 gear (3),
    and position and velocity in counts of 256 a turn (1, wrapping at 256).
    """
    from cvc_balance.identify.mistakes import motion_units
    t, q, w = steady(2.0)
    counts = 256 / (2 * math.pi)
    cases = {'reversed': (q, -w), 'deg/s': (q, np.degrees(w)),
             'degrees and rpm': (np.degrees(q), w * 30 / math.pi), 'ratio': (3 * q, w),
             'wraps': ((q * counts) % 256, w * counts)}
    for cause, (position, velocity) in cases.items():
        check = motion_units(t, position, velocity)
        assert (check.finding.cause, check.finding.figure) == (cause, check.ratio)
    assert check.finding.message == 'joint position wraps at 256, not 2 pi: it is not radians'
    assert math.isclose(check.ratio, 1.0, rel_tol=1e-9) and check.period == 256.0


def test_a_wrap_beside_unequal_steps_is_measured_from_their_mean():
    """Steps 100 and 500 beside a wrap of -3796 (typical 200): their mean 300, so 4096."""
    from cvc_balance.identify.mistakes import wrap_period
    assert wrap_period([200] * 10 + [100, -3796, 500] + [200] * 10) == 4096.0


def test_motion_units_at_its_edges_by_hand():
    """
    ``motion_units`` where its limits fall, each case by hand.

    21 samples (20 steps of 0.06 rad, 1.2 rad turned): judged, ratio 1. Steps of 0.75 rad
    (under 2 pi / 8, no wrap seen): judged; of 0.9 rad: too sparse, None. Degrees wrapping
    at 360 where the only wrap falls over a gap of exactly 5 sample spacings: the wrap is
    seen ('wraps at 360'); over a gap of 6: not seen (a pause), degrees and deg/s agree.
    A slip of 2 rad over a pause (not a wrap seen): left out, the ratio 1; of 1.2 rad
    (under pi / 2): kept, the ratio 1 + 1.2 / turned.
    """
    from cvc_balance.identify.mistakes import motion_units
    dt = 1.0 / 1024                                   # exact in binary
    k = np.arange(21)
    check = motion_units(k * dt, 0.06 * k, np.full(21, 0.06 / dt))
    assert check is not None and math.isclose(check.ratio, 1.0, rel_tol=1e-12)
    k = np.arange(30)
    assert motion_units(k * dt, 0.75 * k, np.full(30, 0.75 / dt)).ratio == \
        pytest.approx(1.0, rel=1e-12)
    assert motion_units(k * dt, 0.9 * k, np.full(30, 0.9 / dt)) is None
    for gap, cause in ((5, 'wraps at 360'), (6, None)):
        ticks = np.arange(2000.0)
        ticks[1000:] += gap - 1                       # one step of ``gap`` spacings
        t = ticks * dt
        w = np.full(len(t), 200.0)                    # deg/s
        q = (200.0 * (t - t[999]) + 359.9) % 360.0     # wraps in the gap only
        assert np.sum(np.abs(np.diff(q)) > 180) == 1 and np.diff(q)[999] < -180
        check = motion_units(t, q, w)
        assert (check.finding.cause if check.finding else None) == cause
        assert math.isclose(check.ratio, 1.0, rel_tol=1e-9)
    for slip, ratio in ((2.0, 1.0), (1.2, None)):
        ticks = np.arange(3000.0)
        ticks[1500:] += 9                             # a pause of ten spacings
        t = ticks * dt
        q = 5.0 * t
        q[1500:] += slip
        check = motion_units(t, q, np.full(len(t), 5.0))
        turned = 5.0 * (t[-1] - t[0])
        expected = ratio or 1.0 + slip / turned
        assert math.isclose(check.ratio, expected, rel_tol=1e-9), slip


def test_which_cells_are_judged_and_their_tolerance_by_hand():
    """
    Shares under 20 % of the radial weight are not judged; none when there is no weight.

    Shares 4000 N and 1000 N (weight 5000 N: 1000 N is exactly 20 %, judged): the rear
    cell reversed is named. Shares 4500 N and 500 N: the rear (10 %) reversed is not. No
    radial weight (a vertical axis: shares 0): nothing judged. A light rotor (shares 0.3
    and 0.2 N): judged as any. Within tolerance: 3000 N read as 3900 N (0.25 x 3000 +
    0.05 x 4000 = 950 N allowed) agrees. Swapped cells, and the front cell on the rear
    support: figure 1000 / 3000 by hand.
    """
    from cvc_balance.identify.mistakes import cell_mistakes
    down = lambda n: complex(0.0, -n)                       # noqa: E731
    found = cell_mistakes({'front': down(4000), 'rear': down(1000)},
                          {'front': down(4000), 'rear': down(-1000)})
    assert [f.cause for f in found] == ['sign']
    assert cell_mistakes({'front': down(4500), 'rear': down(500)},
                         {'front': down(4500), 'rear': down(-500)}) == []
    assert cell_mistakes({'front': 0j, 'rear': 0j}, {'front': down(10), 'rear': down(-10)}) \
        == []
    assert [f.cause for f in cell_mistakes({'front': down(0.3), 'rear': down(0.2)},
                                           {'front': down(0.3), 'rear': down(-0.2)})] == \
        ['sign']
    assert cell_mistakes({'front': down(3000), 'rear': down(1000)},
                         {'front': down(3900), 'rear': down(1000)}) == []
    (swapped,) = cell_mistakes({'front': down(3000), 'rear': down(1000)},
                               {'front': down(1000), 'rear': down(3000)})
    assert swapped.cause == 'swapped' and math.isclose(swapped.figure, 1000 / 3000)
    (elsewhere,) = cell_mistakes({'front': down(3000), 'rear': down(1000)},
                                 {'front': down(1000), 'rear': down(1000)})
    assert elsewhere.cause == 'wrong support' and math.isclose(elsewhere.figure, 1000 / 3000)


def test_the_turn_judged_is_the_velocitys_by_hand():
    """``turned``: the velocity's trapezoids over the steps judged, 5 rad/s x 1.999 s."""
    from cvc_balance.identify.mistakes import motion_units
    t, q, w = steady(2.0)
    assert math.isclose(motion_units(t, q, w).turned, 5.0 * 1.999, rel_tol=1e-12)
