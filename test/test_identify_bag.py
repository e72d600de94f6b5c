"""
``cvc-balance identify`` on the bundled bag whose real rotor is not its layout.

bags/loose_bracket.yaml hides from /layout a 0.3 kg bracket at R 0.5 m, 130 deg, z 0.12 m
and, after the tube swap at 7 s, 0.6 kg more tube at R 0.62 m, 0 deg, z 0.05 m than the
layout says. The residual each segment should show is worked out here by hand, with
ISO 21940-2's two-plane split U_I = sum U_i (z_II - z_i) / b, U_II = sum U_i (z_i - z_I) / b
(/work/shared/domain/FACTS.md), planes at z = -0.12 and 0.12 m.
"""

import cmath
import json
import math
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'loose_bracket.mcap'
Z_I, Z_II = -0.12, 0.12


def point(mass, radius, angle_deg, z):
    return mass * radius * cmath.exp(1j * math.radians(angle_deg)), z


BRACKET = point(0.3, 0.5, 130.0, 0.12)
TUBE = point(0.6, 0.62, 0.0, 0.05)


def by_hand(masses):
    """Return (static, plane I, plane II) of point masses, kg m, complex."""
    span = Z_II - Z_I
    static = sum(u for u, _ in masses)
    plane_i = sum(u * (Z_II - z) / span for u, z in masses)
    plane_ii = sum(u * (z - Z_I) / span for u, z in masses)
    return static, plane_i, plane_ii


def vector(entry, unit):
    return entry[unit] * cmath.exp(1j * math.radians(entry['angle_deg']))


def test_identify_finds_what_the_layout_does_not_know():
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'identify', str(BAG),
                          '--json'], capture_output=True, text=True, check=True)
    summary = json.loads(run.stdout)
    assert summary['problems'] == []
    first, second = summary['segments']
    assert second['from'] == pytest.approx(8.0, abs=0.01)      # the swap at 7 s after start 1
    for segment, hidden in ((first, [BRACKET]), (second, [BRACKET, TUBE])):
        static, plane_i, plane_ii = by_hand(hidden)
        residual = segment['residual']
        assert segment['identifiable'] and segment['dropped'] == 0
        got = vector(residual['static_unbalance'], 'kg_m')
        assert abs(got - static) <= residual['static_unbalance']['ci95_kg_m']
        for entry, want in zip(residual['planes'], (plane_i, plane_ii)):
            assert abs(vector(entry, 'g_mm') * 1e-6 - want) <= entry['ci95_g_mm'] * 1e-6
        # The intervals are informative: a few percent of the hidden static unbalance.
        assert residual['static_unbalance']['ci95_kg_m'] < 0.03 * abs(static)
        # The cells' noise is 15 N per component: the fit's sigma finds it.
        assert segment['fit']['sigma_N'] == pytest.approx(15.0, rel=0.05)


def test_identify_table_and_a_bag_without_cells():
    """With cells: the verdict of record leads; without: exit 1, the bag's topics named."""
    from mcap.reader import make_reader
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'identify', str(BAG)],
                         capture_output=True, text=True, check=True)
    assert 'residual' in run.stdout and 'static residual' in run.stdout
    lines = run.stdout.splitlines()
    assert lines[1].startswith('segment 1: layout ')
    assert lines[2].startswith('  verdict ') and lines[2].endswith('(measured by the load cells)')
    without = ROOT / 'bags' / 'spin_up_tube_swap.mcap'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'identify', str(without)],
                         capture_output=True, text=True)
    assert run.returncode == 1 and run.stdout == ''
    (line,) = run.stderr.splitlines()
    assert 'no load cells to identify from' in line
    with open(without, 'rb') as stream:       # the topics as the mcap library reads them
        summary = make_reader(stream).get_summary()
    schemas = summary.schemas
    for channel in summary.channels.values():
        assert f'{channel.topic} ({schemas[channel.schema_id].name})' in line
