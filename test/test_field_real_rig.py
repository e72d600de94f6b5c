"""
Influence coefficients on a real rotor: a balancing rig's known weight, predicted back.

The recording (docs/validation/real_data.md; ``test_real_rig.py`` reads it and checks its 1x
against plain fits): github.com/hstarmans/rotorbalancer @ 7b7d24915e157335320b43085016d6d92906e491
(GPL-3.0, not copied here: read from shared/recordings, skipped when absent). Ten runs of a
small rotor without its balance weight and ten with 0.060 g of putty, an IR keyphasor and an
accelerometer, at four motor settings (49, 52, 56 and 59 rev/s).

One run without the weight and one with it at the same speed are a baseline and a trial run
(trial 0.060 g, its angle the zero of the angles): ``field.calibrate`` gives the coefficient,
and ``field``'s continuous correction of every other run at that speed is what that run asks
for. The weight left 1/k of the 1x in its runs (k the recording's own before/after ratio,
5.7), so the full correction the data allow is 0.060 k / (k - 1) g at the weight's angle:
each prediction is checked against that, within the spread the runs themselves show.
"""

import math

import numpy as np
import pytest

from cvc_balance.field import calibrate, continuous_correction, problem_from_readings, Trial
from test_real_rig import readings as rig_readings, RUNS  # noqa: F401 (its fixture)

TRIAL = Trial('I', 0.060, 0.0, 1.0)           # grams: the corrections come out in grams


@pytest.fixture(scope='module')
def runs(rig_readings):  # noqa: F811 (the fixture imported above)
    """{(case, run): (1x over the speed squared, complex counts s^2, speed rev/s)}."""
    out = {}
    for key, (_, longest, _, _) in rig_readings.items():
        reading = longest.channels[0]
        # A suspended body far below its resonance: the 1x grows as the speed squared.
        out[key] = (reading.amplitude * np.exp(1j * math.radians(reading.phase_deg))
                    / longest.speed ** 2, longest.speed / (2 * math.pi))
    return out


def test_coefficients_from_one_run_predict_the_known_weight_in_the_others(runs):
    before = [runs['without_weight', n][0] for n in RUNS]
    after = [runs['weight', n][0] for n in RUNS]
    ratio = np.mean(np.abs(before)) / np.mean(np.abs(after))
    full = TRIAL.mass * ratio / (ratio - 1.0)      # what balances it fully, by the data
    predicted = []
    for a in RUNS:
        for b in RUNS:
            base, speed = runs['without_weight', a]
            trial, trial_speed = runs['weight', b]
            if abs(trial_speed / speed - 1.0) > 0.005:
                continue
            calibration = calibrate([base], [TRIAL], [[trial]])
            for c in RUNS:
                reading, other = runs['without_weight', c]
                if c == a or abs(other / speed - 1.0) > 0.005:
                    continue
                problem = problem_from_readings(calibration, [reading], unit='g')
                predicted.append(complex(continuous_correction(problem)[0]))
    masses = np.abs(predicted)
    angles = np.degrees(np.angle(predicted))
    # 72 predictions (pairs of runs at one speed, each applied to the other runs there).
    assert len(predicted) == 72
    assert ratio == pytest.approx(5.7, abs=0.1)
    assert full == pytest.approx(0.0728, abs=0.001)
    # Each within 25 % and 15 deg of the full correction (measured: 0.0586-0.0908 g, median
    # 0.0728; -13 to +6 deg, median -3): the runs' own spread, the error the data allow.
    assert np.all(np.abs(masses / full - 1.0) < 0.25), masses
    assert np.median(masses) == pytest.approx(full, rel=0.03)
    assert np.all(np.abs(angles) < 15.0), angles
