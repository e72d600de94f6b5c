"""The layout's weight sites (balancing.sites): accepted, refused with one line, digests kept."""

from dataclasses import asdict
import hashlib
import json
import math
from pathlib import Path
import subprocess
import sys

import pytest
import yaml

from cvc_balance.physics.layout import LayoutError, parse_layout

ROOT = Path(__file__).resolve().parents[1]


def gantry():
    return yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())


def with_sites(sites):
    layout = gantry()
    layout['balancing']['sites'] = sites
    return layout


GOOD = {'I': {'angles_deg': [0, 90, 180, 270], 'radius': 0.68, 'masses': [0.1, 0.05],
              'stack': 2},
        'II': {'angles': [0.0, 2.0], 'radius': 0.5, 'masses': [0.2]}}


def test_sites_are_read():
    layout = parse_layout(with_sites(GOOD))
    first, second = layout.balancing.sites
    assert first.plane == 'I' and second.plane == 'II'
    assert [round(math.degrees(a), 12) for a in first.angles] == [0, 90, 180, 270]
    assert first.masses == (0.05, 0.1) and first.stack == 2 and first.radius == 0.68
    assert second.angles == (0.0, 2.0) and second.stack == 1
    assert layout.balancing.sites_of('II') is second
    assert parse_layout(gantry()).balancing.sites == ()


def test_layouts_without_sites_keep_their_digest():
    # The digest as it was before sites existed: SHA-256 of asdict's canonical JSON.
    layout = parse_layout(gantry())
    data = asdict(layout)
    del data['balancing']['sites']
    for support in data['supports']:       # nor bearings: a support without one leaves it out
        assert support.pop('bearing') is None
    text = json.dumps(data, sort_keys=True, separators=(',', ':'))
    assert layout.digest() == hashlib.sha256(text.encode()).hexdigest()[:12]
    assert parse_layout(with_sites(GOOD)).digest() != layout.digest()


BAD_SITES = {
    'plane III': ({'III': GOOD['I']}, 'unknown field', 'III'),
    'no angles': ({'I': {'radius': 0.5, 'masses': [0.1]}}, 'balancing.sites.I',
                  'exactly one of fields angles'),
    'both angles': ({'I': dict(GOOD['I'], angles=[0.0])}, 'exactly one'),
    'empty angles': ({'I': dict(GOOD['I'], angles_deg=[])}, 'angles_deg', '1 to 720'),
    'same angle twice': ({'I': dict(GOOD['I'], angles_deg=[0, 360])}, 'same angle'),
    'nan angle': ({'I': dict(GOOD['I'], angles_deg=[0, math.nan])}, 'angles_deg[1]',
                  'finite'),
    'text angle': ({'I': dict(GOOD['I'], angles_deg=[0, 'north'])}, 'angles_deg[1]',
                   'number'),
    'zero radius': ({'I': dict(GOOD['I'], radius=0.0)}, 'sites.I.radius',
                    'from 1e-06 to 1e+12 m', 'got 0 m'),
    'no masses': ({'I': dict(GOOD['I'], masses=[])}, 'masses', '1 to 20'),
    'negative mass': ({'I': dict(GOOD['I'], masses=[0.1, -0.2])}, 'masses[1]',
                      'from 1e-06 to 1e+12 kg', 'got -0.2 kg'),
    'same size twice': ({'I': dict(GOOD['I'], masses=[0.1, 0.1])}, 'each weight size once'),
    'fractional stack': ({'I': dict(GOOD['I'], stack=1.5)}, 'stack', 'whole number'),
    'boolean stack': ({'I': dict(GOOD['I'], stack=True)}, 'stack', 'whole number'),
    'huge stack': ({'I': dict(GOOD['I'], stack=10**6)}, 'stack', '1 to 20'),
    'unknown key': ({'I': dict(GOOD['I'], colour='red')}, 'unknown field', 'colour'),
    'too many sites': ({'I': dict(GOOD['I'], angles_deg=[k * 0.1 for k in range(3000)])},
                       '1 to 720'),
    'not a mapping': (['I'], 'balancing.sites', 'mapping'),
}


@pytest.mark.parametrize('case', sorted(BAD_SITES))
def test_bad_sites_are_named(case):
    sites, *needles = BAD_SITES[case]
    with pytest.raises(LayoutError) as error:
        parse_layout(with_sites(sites))
    message = str(error.value)
    assert '\n' not in message and len(message) < 300
    for needle in needles:
        assert needle in message, (needle, message)


def test_sites_need_two_planes():
    layout = with_sites(GOOD)
    layout['supports'] = [{'name': 'front', 'z': 0.0}]
    del layout['balancing']['planes']
    with pytest.raises(LayoutError, match='two correction planes'):
        parse_layout(layout)
    layout['balancing']['planes'] = [-0.1, 0.1]          # given planes: fine
    assert len(parse_layout(layout).balancing.sites) == 2


def test_bad_sites_on_the_command_line(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(with_sites({'I': dict(GOOD['I'], stack=0)})))
    done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'solve', str(path),
                           '--omega', '20'], capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == ''
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'balancing.sites.I.stack' in lines[0]


def refusal(sites):
    """Return the one line a layout with these weight sites is refused with."""
    with pytest.raises(LayoutError) as refused:
        parse_layout(with_sites(sites))
    return str(refused.value)


def test_the_sites_refusals_word_for_word():
    """Each refusal of balancing.sites in the exact words the user reads."""
    where = 'layout: field balancing.sites'
    one = GOOD['I']
    known = 'angles, angles_deg, radius, masses, stack, first_hole_angle_deg, numbering'
    cases = [
        ({'I': one, 'rotation': 'up'},
         f"{where}.rotation must be one of positive, negative, got 'up'"),
        ({'I': dict(one, first_hole_angle_deg=90, numbering='with_rotation')},
         f'{where}.I.numbering counts with or against the rotation: give {where}.rotation '
         '(positive: rotor X toward rotor Y)'),
        ({'I': dict(one, first_hole_angle_deg=90, numbering='sideways'), 'rotation': 'positive'},
         f"{where}.I.numbering must be one of with_rotation, against_rotation, got 'sideways'"),
        ({'I': dict(one, first_hole_angle_deg=7, numbering='with_rotation'),
          'rotation': 'positive'},
         f'{where}.I.first_hole_angle_deg: no site at 7 deg (hole 1 is one of the sites)'),
        ({'I': dict(one, first_hole_angle_deg='north', numbering='with_rotation'),
          'rotation': 'positive'},
         f"{where}.I.first_hole_angle_deg must be a number, got 'north'"),
        ({'I': dict(one, first_hole_angle_deg=1e11, numbering='with_rotation'),
          'rotation': 'positive'},
         f'{where}.I.first_hole_angle_deg must be within +-5.72958e+10 deg (the reduction to '
         'a turn stays exact), got 1e+11 deg'),
        ({'I': dict(one, numbering='with_rotation'), 'rotation': 'positive'},
         f'{where}.I: give both first_hole_angle_deg and numbering, or neither'),
        ({'I': dict(one, stack=21)}, f'{where}.I.stack must be a whole number from 1 to 20, '
         'got 21'),
        ({'I': {'angles': [0.0, 2.0], 'masses': [0.1]}}, f'{where}.I: missing field radius'),
        ({'I': {'angles': [0.0, 2.0], 'radius': 0.5}}, f'{where}.I: missing field masses'),
        ({'I': [1]}, f'{where}.I: expected a mapping of fields, got list'),
        ({'I': dict(one, colour='red')}, f"{where}.I: unknown field 'colour' (known: {known})"),
        ({'III': one}, f"{where}: unknown field 'III' (known: I, II, rotation)"),
        ({'I': {'angles': [0.0, 1e10], 'radius': 0.5, 'masses': [0.1]}},
         f'{where}.I.angles[1] must be within +-1e+09 rad (the reduction to a turn stays '
         'exact), got 1e+10 rad'),
        ({'I': {'angles': [0.0, 2 * math.pi - 1e-10], 'radius': 0.5, 'masses': [0.1]}},
         f'{where}.I.angles: two sites at the same angle'),          # across the turn
    ]
    for sites, said in cases:
        assert refusal(sites) == said, sites
    # Accepted at the edges: 20 stacked, hole 1 given a turn away from its site.
    layout = parse_layout(with_sites({'I': dict(one, stack=20, first_hole_angle_deg=360,
                                                numbering='with_rotation'),
                                      'rotation': 'positive'}))
    assert layout.balancing.sites[0].stack == 20 and layout.balancing.sites[0].first_hole == 0.0


def test_the_canonical_json_has_the_sites_numbering_only_when_given():
    """Fields added later (first_hole, numbering, rotation) are written only when given."""
    plain = json.loads(parse_layout(with_sites(GOOD)).canonical_json())
    fields = {'angles', 'masses', 'plane', 'radius', 'stack'}
    assert [set(s) for s in plain['balancing']['sites']] == [fields, fields]
    numbered = json.loads(parse_layout(with_sites({
        'I': dict(GOOD['I'], first_hole_angle_deg=90, numbering='against_rotation'),
        'rotation': 'negative'})).canonical_json())
    (sites,) = numbered['balancing']['sites']
    assert set(sites) == fields | {'first_hole', 'numbering', 'rotation'}
    assert (sites['first_hole'], sites['numbering'], sites['rotation']) == \
        (math.radians(90), 'against_rotation', 'negative')


def test_the_most_sites_and_sizes_are_read_and_none_is_refused_word_for_word():
    """720 sites and 20 weight sizes a plane are read; no site at all is refused."""
    most = {'I': {'angles_deg': [k * 0.5 for k in range(720)], 'radius': 0.5,
                  'masses': [0.01 * (k + 1) for k in range(20)]}}
    (sites,) = parse_layout(with_sites(most)).balancing.sites
    assert len(sites.angles) == 720 and len(sites.masses) == 20
    assert refusal({'I': dict(GOOD['I'], angles_deg=[])}) == (
        'layout: field balancing.sites.I.angles_deg must be a list of 1 to 720 numbers, got []')


def test_sites_with_the_supports_planes_and_a_long_description():
    """Sites need two planes: two supports give them; one support is refused word for word."""
    layout = with_sites(GOOD)
    del layout['balancing']['planes']                       # the two supports' planes
    assert len(parse_layout(layout).balancing.sites) == 2
    layout['supports'] = layout['supports'][:1]
    layout['supports'][0]['axial'] = True
    with pytest.raises(LayoutError) as refused:
        parse_layout(layout)
    assert str(refused.value) == (
        'layout: field balancing.sites: weight sites need two correction planes (give '
        'balancing.planes, or two supports)')
    layout = gantry()
    layout['description'] = 'd' * 20000
    assert len(parse_layout(layout).description) == 20000
    layout['description'] += 'd'
    with pytest.raises(LayoutError) as refused:
        parse_layout(layout)
    assert str(refused.value) == ('layout: field description: 20001 characters, over the '
                                  'limit of 20000')


def test_sites_angles_in_degrees_beyond_1e9_and_3e_9_rad_apart_are_read():
    """angles_deg are held to the degrees' limit (5.7e10), and sites 3e-9 rad apart differ."""
    sites = parse_layout(with_sites({'I': dict(GOOD['I'], angles_deg=[0, 2e9])})).balancing
    assert sites.sites[0].angles == (0.0, math.radians(2e9))
    near = {'I': {'angles': [0.0, 3e-9], 'radius': 0.5, 'masses': [0.1]}}
    assert parse_layout(with_sites(near)).balancing.sites[0].angles == (0.0, 3e-9)
