"""
No more model than a scene needs.

Which model is taken and that it stays within the stated tolerance against the 40-digit
reference. What a reduced model saves is measured by benchmarks/model_choice_cost.py.
"""

import math

import numpy as np
import pytest

from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.model_choice import choose_model, Envelope, Tolerance
from cvc_balance.study.exact import exact_loads
from reference import random_layout

SUPPORTS = [{'name': 'front', 'z': -0.4}, {'name': 'rear', 'z': 0.4, 'axial': True}]


def gantry(z_offsets=False, tilt=0.0, product=0.0):
    """Ten components: points, boxes and cylinders; optionally axial offsets and tilt."""
    rng = np.random.default_rng(21)
    components = []
    for i in range(10):
        item = {'name': f'c{i}', 'mass': float(rng.uniform(5, 60)),
                'radius': float(rng.uniform(0.2, 0.7)),
                'angle': float(rng.uniform(0, 2 * math.pi)),
                'z': float(rng.uniform(-0.3, 0.3)) if z_offsets else 0.0}
        if i % 3 == 1:
            item['shape'] = {'type': 'box', 'size': [0.3, 0.2, 0.25]}
        elif i % 3 == 2:
            item['shape'] = {'type': 'cylinder', 'radius': 0.1, 'length': 0.4,
                             'axis': 'tangential'}
        components.append(item)
    if product:
        components[0]['inertia'] = {'ixx': 2.0, 'iyy': 2.0, 'izz': 1.0, 'ixy': 0.0,
                                    'ixz': product, 'iyz': 0.0}
    g = 9.80665
    return parse_layout({'name': 'gantry', 'components': components, 'supports': SUPPORTS,
                         'gravity': [0.0, -g * math.cos(tilt), g * math.sin(tilt)]})


ENVELOPE = Envelope(omega_max=25.0, alpha_max=4.0)


@pytest.mark.parametrize('layout, tolerance, expected', [
    # Planar, untilted: no moment at all; the shapes' I_zz matters for the torque only.
    (gantry(), Tolerance(1.0, 1.0, 1.0), 'rigid bodies, planar'),
    (gantry(), Tolerance(1.0, 1.0), 'point masses, planar'),
    # Axial offsets make a moment; the shapes' products are zero: point masses if the
    # torque is not asked (forces never depend on own inertia: thesis Ch. 5).
    (gantry(z_offsets=True), Tolerance(1.0, 1.0), 'point masses'),
    (gantry(z_offsets=True), Tolerance(1.0, 1.0, 1.0), 'rigid bodies'),
    # A tilt alone makes a moment of gravity (S_xy g_z).
    (gantry(tilt=math.radians(15)), Tolerance(1.0, 1.0), 'point masses'),
    # A given tensor with an xz product: the moment needs own inertia.
    (gantry(product=0.05), Tolerance(1.0, 1.0), 'rigid bodies'),
    # A loose tolerance: the smallest model, wherever the scene.
    (gantry(z_offsets=True, tilt=0.3, product=0.05), Tolerance(1e5, 1e5, 1e5),
     'point masses, planar'),
])
def test_the_smallest_model_within_the_tolerance_is_taken(layout, tolerance, expected):
    choice = choose_model(layout, tolerance, ENVELOPE)
    assert choice.name == expected
    assert choice.name in choice.describe()


def envelope_samples(rng, envelope, n=64):
    """Motion samples over the envelope, its corners included."""
    q = rng.uniform(0, 2 * math.pi, n)
    omega = rng.uniform(-envelope.omega_max, envelope.omega_max, n)
    alpha = rng.uniform(-envelope.alpha_max, envelope.alpha_max, n)
    omega[:4] = [envelope.omega_max, -envelope.omega_max, envelope.omega_max, 0.0]
    alpha[:4] = [envelope.alpha_max, -envelope.alpha_max, -envelope.alpha_max, 0.0]
    return q, omega, alpha


@pytest.mark.parametrize('seed', range(12))
def test_chosen_model_stays_within_the_tolerance(seed):
    """Random layouts and tolerances: the chosen model against the 40-digit reference."""
    rng = np.random.default_rng(100 + seed)
    layout = parse_layout(random_layout(rng, n=6, supports=1 + seed % 2,
                                        tilt=bool(seed % 3), every_kind=seed % 4 == 0))
    envelope = Envelope(float(rng.uniform(1, 30)), float(rng.uniform(0, 5)))
    tolerance = Tolerance(*(10.0 ** rng.uniform(-1, 3, 3)))
    choice = choose_model(layout, tolerance, envelope)
    q, omega, alpha = envelope_samples(rng, envelope)
    force, moment, torque = exact_loads(layout, q, omega, alpha, layout.gravity)
    got = loads(choice.model, q, omega, alpha)
    full = loads(RotorModel.from_layout(layout), q, omega, alpha)
    deviation = choice.deviation
    # Float64 rounding against the reference: measured 1.9e-16 of this size at most.
    rounding = 2e-15 * (1.0 + np.abs(force).max() + np.abs(moment).max())
    assert np.abs(got.force_rotor - force).max() <= rounding
    assert np.linalg.norm(got.moment_rotor - moment, axis=1).max() <= \
        deviation.moment + rounding
    assert np.abs(got.drive_torque - torque).max() <= deviation.torque + rounding
    for name in got.support_force:
        change = np.linalg.norm(got.support_force[name] - full.support_force[name], axis=1)
        assert change.max() <= deviation.force + rounding
        change = np.linalg.norm(got.support_moment[name] - full.support_moment[name], axis=1)
        assert change.max() <= deviation.moment + rounding
    if choice.name != 'rigid bodies':
        assert (deviation.force <= tolerance.force and deviation.moment <= tolerance.moment
                and deviation.torque <= tolerance.torque)


def test_the_full_model_is_taken_when_nothing_can_be_dropped():
    layout = gantry(z_offsets=True, product=0.05)
    choice = choose_model(layout, Tolerance(1e-6, 1e-6, 1e-6), ENVELOPE)
    assert choice.name == 'rigid bodies'
    full = RotorModel.from_layout(layout)
    for field in ('mass', 's_x', 's_y', 's_z', 'p_xz', 'p_yz', 'i_zz'):
        assert getattr(choice.model, field) == getattr(full, field)


def test_solve_says_which_model_it_took(tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    layout_file = root / 'config' / 'ct_gantry.yaml'

    def solve(*tolerance):
        run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve',
                              str(layout_file), '--omega', '23.27', '--json',
                              '--tolerance', *tolerance], capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
        return json.loads(run.stdout)
    from cvc_balance.physics.layout_file import load_layout
    layout = load_layout(layout_file)
    for tolerance in (('1e9', 'inf', 'inf'), ('1', '1', '1')):
        summary = solve(*tolerance)
        choice = choose_model(layout, Tolerance(*map(float, tolerance)), Envelope(23.27))
        assert summary['model'] == choice.name
    assert solve('1e9', 'inf', 'inf')['model'] == 'point masses, planar'
    assert all(v == 0.0 for v in solve('1e9', 'inf', 'inf')['moment_rotor'])


def test_replay_takes_per_layout_the_smallest_model_within_the_tolerance():
    """The bundled tilted bag: every layout's model said; peaks within its deviation."""
    from pathlib import Path
    from cvc_balance.bag.replay import replay
    from cvc_balance.bag.run_summary import format_replay, replay_record
    bag = Path(__file__).resolve().parents[1] / 'bags' / 'tilted_shift.mcap'
    full = replay(bag)
    for tolerance, expected in ((Tolerance(1e9), 'point masses, planar'),
                                (Tolerance(100.0), 'point masses'),
                                (Tolerance(1.0, 1.0, 1.0), 'rigid bodies')):
        reduced = replay(bag, tolerance=tolerance)
        text = format_replay(replay_record(reduced))
        for segment, reference in zip(reduced.segments, full.segments):
            assert segment.choice.name == expected
            assert f'model: {expected} (' in text
            for name, peak in segment.peak_support.items():
                assert abs(peak - reference.peak_support[name]) <= \
                    segment.choice.deviation.force + 2e-15 * peak
