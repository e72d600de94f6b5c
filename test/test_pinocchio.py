"""
The engine and ``cvc-balance solve`` against Pinocchio's rigid-body dynamics.

Random layouts (all shapes, given inertias, z offsets, one and two supports),
tilted gravity, alpha != 0: the loads must agree with Pinocchio's RNEA (relative error
of each vector; measured per test below). Supports are checked by statics here (they
must carry the total load Pinocchio transmits through the joint) and each on its own
in test_edge_cases.py.
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from cvc_balance.physics.engine import loads, RotorModel, sample_loads
from cvc_balance.physics.layout import parse_layout
from reference import pinocchio_loads, random_layout, relative_error

TOLERANCE = 1e-13
"""Relative error of each vector, one sample: measured 1.3e-14 at most over the 40 layouts."""
VECTORISED = 1e-12
"""The same per sample of the vectorised path with per-sample gravity: measured 1.6e-13
(a vector ~100 times smaller than its terms, e.g. a moment at a near-balanced instant)."""
COMMAND_LINE = 2e-14
"""``cvc-balance solve --json`` (printed with repr, read back exactly): measured 2.5e-15."""


def _support_resultant(supports, per_support):
    """Total force and moment about O of the per-support loads (stator frame)."""
    force, moment = np.zeros(3), np.zeros(3)
    for support in supports:
        f, m = (np.asarray(v, float) for v in per_support[support['name']])
        force += f
        moment += m + np.cross([0.0, 0.0, support['z']], f)
    return force, moment


@pytest.mark.parametrize('seed', range(40))
def test_sample_loads_match_pinocchio(seed):
    rng = np.random.default_rng(seed)
    layout = random_layout(rng, n=int(rng.integers(1, 15)), supports=1 + seed % 2)
    model = RotorModel.from_layout(parse_layout(layout))
    q, omega, alpha = rng.uniform(-7, 7), rng.uniform(-40, 40), rng.uniform(-30, 30)
    ref = pinocchio_loads(layout, q, omega, alpha, layout['gravity'])
    got = sample_loads(model, q, omega, alpha)
    for key in ('force_rotor', 'moment_rotor', 'force_stator', 'moment_stator'):
        assert relative_error(getattr(got, key), ref[key]) < TOLERANCE, key
    assert relative_error(got.drive_torque, ref['drive_torque']) < TOLERANCE
    assert got.moment_stator[2] == 0.0
    assert relative_error(model.mass, ref['mass']) < TOLERANCE
    assert relative_error(model.body.com, ref['com']) < TOLERANCE
    # About the centre of mass is a difference of terms of the size of the inertia about O
    # (and zero for a lone point mass): that is its scale.
    difference = np.linalg.norm(model.body.inertia_about_com() - ref['inertia_about_com'])
    assert difference < TOLERANCE * np.linalg.norm(model.body.inertia)
    per_support = {name: load for name, load in got.supports.items()}
    force, moment = _support_resultant(layout['supports'], per_support)
    assert relative_error(force, ref['force_stator']) < TOLERANCE
    assert relative_error(moment, ref['moment_stator']) < TOLERANCE


@pytest.mark.parametrize('seed', range(4))
def test_vectorised_loads_match_pinocchio_per_sample(seed):
    rng = np.random.default_rng(100 + seed)
    layout = random_layout(rng, n=10, supports=1 + seed % 2)
    model = RotorModel.from_layout(parse_layout(layout))
    n = 25
    q, omega, alpha = rng.uniform(-7, 7, n), rng.uniform(-40, 40, n), rng.uniform(-30, 30, n)
    tilt = rng.uniform(-0.5, 0.5, n)
    gravity = np.stack([np.zeros(n), -9.81 * np.cos(tilt), 9.81 * np.sin(tilt)], axis=1)
    result = loads(model, q, omega, alpha, gravity)
    assert len(result) == n
    for i in range(n):
        ref = pinocchio_loads(layout, q[i], omega[i], alpha[i], gravity[i])
        for key in ('force_rotor', 'moment_rotor', 'force_stator', 'moment_stator'):
            assert relative_error(getattr(result, key)[i], ref[key]) < VECTORISED, key
        assert relative_error(result.drive_torque[i], ref['drive_torque']) < VECTORISED
        per_support = {s['name']: (result.support_force[s['name']][i],
                                   result.support_moment[s['name']][i])
                       for s in layout['supports']}
        force, moment = _support_resultant(layout['supports'], per_support)
        assert relative_error(force, ref['force_stator']) < VECTORISED
        assert relative_error(moment, ref['moment_stator']) < VECTORISED


def test_vectorised_path_spans_several_chunks():
    """Samples across block boundaries equal the one-sample path (scalar floats)."""
    rng = np.random.default_rng(7)
    model = RotorModel.from_layout(parse_layout(random_layout(rng, n=6)))
    n = 70_001
    q, omega, alpha = rng.uniform(-7, 7, n), rng.uniform(-40, 40, n), rng.uniform(-9, 9, n)
    result = loads(model, q, omega, alpha)
    # The last sample of the first block (65535) and the first of the second; measured:
    # equal to the last bit (every sample of three blocks: test_edge_cases.py).
    for i in (0, 32_767, 32_768, 65_535, 65_536, n - 1):
        one = sample_loads(model, q[i], omega[i], alpha[i])
        np.testing.assert_allclose(result.force_stator[i], one.force_stator, rtol=1e-14)
        np.testing.assert_allclose(result.moment_rotor[i], one.moment_rotor, rtol=1e-14,
                                   atol=1e-12)


@pytest.mark.parametrize('seed', range(8))
def test_solve_json_matches_pinocchio_on_unseen_layouts(seed, tmp_path):
    """The command line, on layout files it has never seen, against Pinocchio."""
    rng = np.random.default_rng(10_000 + seed)
    layout = random_layout(rng, n=int(rng.integers(0, 6)), supports=1 + seed % 2,
                           every_kind=True)
    path = tmp_path / ('layout.json' if seed % 3 == 0 else 'layout.yaml')
    path.write_text(json.dumps(layout) if seed % 3 == 0 else yaml.safe_dump(layout))
    omega, alpha, angle_deg = rng.uniform(-40, 40), rng.uniform(-20, 20), rng.uniform(-360, 360)
    tilt = rng.uniform(-0.5, 0.5)
    gravity = [0.3, -9.80665 * math.cos(tilt), 9.80665 * math.sin(tilt)]
    # repr() round-trips the floats exactly, so both sides see the same inputs.
    run = subprocess.run(
        [sys.executable, '-m', 'cvc_balance.cli', 'solve', str(path), '--omega', repr(omega),
         '--alpha', repr(alpha), '--angle-deg', repr(angle_deg), '--gravity',
         *map(repr, gravity), '--json'], capture_output=True, text=True, check=True)
    got = json.loads(run.stdout)
    ref = pinocchio_loads(layout, math.radians(angle_deg), omega, alpha, gravity)
    for key in ('force_rotor', 'moment_rotor', 'force_stator', 'moment_stator'):
        assert relative_error(got[key], ref[key]) < COMMAND_LINE, key
    assert relative_error(got['drive_torque'], ref['drive_torque']) < COMMAND_LINE
    assert relative_error(got['mass'], ref['mass']) < COMMAND_LINE
    assert relative_error(got['com'], ref['com']) < COMMAND_LINE
    per_support = {name: (s['force'], s['moment']) for name, s in got['supports'].items()}
    force, moment = _support_resultant(layout['supports'], per_support)
    assert relative_error(force, ref['force_stator']) < COMMAND_LINE
    assert relative_error(moment, ref['moment_stator']) < COMMAND_LINE
