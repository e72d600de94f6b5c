"""
One vocabulary across the commands (issue 27), checked on the parsers and on the outputs.

A topic is ``--NAME-topic TOPIC`` (``--layout-topic``, ``--speed-topic``; ``--joint-states``
and ``--keyphasor`` name their topic as the node's), a layout file ``--layout-file FILE``, a
speed ``--speed W`` in rad/s; the old ``--layout`` and ``--speed TOPIC`` are refused with
the new name. Angles for people are 0..360 everywhere: every ``*angle_deg`` of every JSON
output of the bundled runs is checked. A reader that goes away (``| head``) ends the
command quietly.
"""

import argparse
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from cvc_balance.cli import main, parser

ROOT = Path(__file__).resolve().parents[1]


def commands():
    sub = next(a for a in parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def options(command):
    return {o: a for a in command._actions for o in a.option_strings
            if a.help != argparse.SUPPRESS}


def test_every_option_means_one_thing_in_every_command():
    seen = {}
    for name, command in commands().items():
        for option, action in options(command).items():
            if option in ('--layout-file', '--layout-topic', '--speed-topic', '--speed',
                          '--joint-states', '--keyphasor'):
                seen.setdefault(option, set()).add(action.metavar)
        assert '--layout' not in options(command), name
        if '--layout-topic' in options(command):      # reads a bag's topics
            assert '--speed-topic' in options(command), name
    assert seen == {'--layout-file': {'FILE'}, '--layout-topic': {'TOPIC'},
                    '--speed-topic': {'TOPIC'}, '--speed': {'W'},
                    '--joint-states': {'TOPIC'}, '--keyphasor': {'TOPIC'}}


@pytest.mark.parametrize('args, instead', [
    (['replay', 'bags/loose_bracket.mcap', '--layout', 'layout'], '--layout-topic TOPIC'),
    (['identify', 'bags/loose_bracket.mcap', '--layout', 'x.yaml'], '--layout-file FILE'),
    (['view', 'bags/loose_bracket.mcap', '-o', 'x.rrd', '--speed', 'speed'],
     '--speed-topic TOPIC'),
    (['correct', 'bags/field_baseline.mcap', '--layout', 'config/ct_gantry_field.yaml'],
     '--layout-file FILE'),
])
def test_old_spellings_are_refused_with_the_new_name(args, instead, capsys):
    with pytest.raises(SystemExit) as stop:
        main(args)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and len(err.strip().splitlines()) == 1
    assert f'{args[args.index("--layout") if "--layout" in args else args.index("--speed")]}' \
        ' is no longer an option here: give ' in err and instead in err


def angles_of(data, where=''):
    """Yield (path, value) of every key ending in angle_deg (numbers and lists of them)."""
    if isinstance(data, dict):
        for key, value in data.items():
            if key.endswith('angle_deg') or key == 'angles_deg':
                for v in value if isinstance(value, list) else [value]:
                    if v is not None:
                        yield f'{where}.{key}', v
            else:
                yield from angles_of(value, f'{where}.{key}')
    elif isinstance(data, list):
        for k, item in enumerate(data):
            yield from angles_of(item, f'{where}[{k}]')


@pytest.mark.parametrize('args', [
    ['solve', 'config/ct_gantry.yaml', '--omega', '23.27', '--json'],
    ['replay', 'bags/loose_bracket.mcap', '--json'],
    ['identify', 'bags/loose_bracket.mcap', '--json'],
    ['correct', 'bags/field_baseline.mcap', '--json'],
])
def test_angles_for_people_are_0_to_360(args):
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *args], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    found = list(angles_of(json.loads(run.stdout)))
    assert len(found) >= 4, found
    outside = [(path, v) for path, v in found if not 0.0 <= v < 360.0]
    assert outside == []
    # Not all in one half: the check would pass on -180..180 data by luck otherwise.
    assert any(v > 180.0 for _, v in found), found


def test_view_of_a_bag_without_a_layout_takes_a_layout_file(tmp_path):
    from independent import ramp, write_input_bag
    stamps, angle, omega = ramp(5.0, 1.0, seconds=1.0)
    bag = write_input_bag(tmp_path / 'no_layout.mcap', stamps, angle, omega)
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'view', str(bag), '-o',
                          str(tmp_path / 'run.rrd'), '--layout-file',
                          str(ROOT / 'config' / 'ct_gantry.yaml')],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith(f'{tmp_path / "run.rrd"}: {len(stamps)} samples of ')


def test_a_reader_that_goes_away_ends_the_command_quietly():
    process = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'sensitivity',
                                'config/ct_gantry.yaml'], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    process.stdout.readline()
    process.stdout.close()            # as `| head -1` does
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) in (0, 141) and err == ''
    np.testing.assert_equal(err, '')
