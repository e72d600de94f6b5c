"""
docs/guide/field_balancing.md works as written, on a fresh folder.

Every ``$ cvc-balance ...`` line of the guide is run in order in an empty folder (with the
checkout's bags/ and config/ beside it, as in a fresh clone); each must succeed, and each
output line the guide shows under a command must be a line the command printed. Every file
the guide names under bags/ or config/ must exist.
"""

import os
from pathlib import Path
import re
import shlex

import pytest

from cvc_balance.cli import main

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / 'docs' / 'guide' / 'field_balancing.md'


def steps():
    """Return [(command args, [lines the guide shows it print])] in the guide's order."""
    found, lines = [], GUIDE.read_text().splitlines()
    for k, line in enumerate(lines):
        stripped = line.strip()
        if not stripped.startswith('$ cvc-balance '):
            continue
        indent = len(line) - len(line.lstrip())
        shown = []
        for following in lines[k + 1:]:
            if not following.strip() or following.strip().startswith('$') or \
                    len(following) - len(following.lstrip()) <= indent:
                break
            shown.append(following.strip())
        found.append((shlex.split(stripped[2:])[1:], shown))
    return found


def test_every_file_the_guide_names_exists():
    named = set(re.findall(r'\b((?:bags|config)/[\w./-]+\.(?:yaml|mcap))', GUIDE.read_text()))
    assert named, 'the guide names no files'
    missing = [n for n in sorted(named) if not (ROOT / n).exists()]
    assert missing == []


def test_the_guide_runs_start_to_finish(tmp_path, capsys):
    for folder in ('bags', 'config'):
        (tmp_path / folder).symlink_to(ROOT / folder)
    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        done = []
        for args, shown in steps():
            code = main(args)
            out, err = capsys.readouterr()
            assert code == 0, (args, err)
            printed = {line.strip() for line in out.splitlines()}
            for line in shown:
                assert line in printed, (args, line, out)
            done.append(args[0])
    finally:
        os.chdir(here)
    assert done.count('simulate') == 4 and 'calibrate' in done and 'report' in done
    assert (tmp_path / 'report' / 'report.html').exists()
    assert (tmp_path / 'coefficients.yaml').exists()


@pytest.mark.parametrize('line', ['--trial I:200@0,0.68'])
def test_the_mistake_the_guide_shows_is_said_as_shown(tmp_path, capsys, line):
    text = ' '.join(GUIDE.read_text().split())
    said = re.search(r'gives `(\.\.\. likely the trial mass in g typed as kg.*?go on\))`',
                     text)
    assert said, 'the guide shows no refusal'
    for folder in ('bags', 'config'):
        (tmp_path / folder).symlink_to(ROOT / folder)
    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        for name in ('baseline', 'trial_I', 'trial_II'):
            assert main(['simulate', f'bags/field_{name}.yaml', '-o', f'{name}.mcap']) == 0
        capsys.readouterr()
        code = main(['calibrate', 'baseline.mcap', 'trial_I.mcap', 'trial_II.mcap',
                     *line.split(), '--trial', 'II:0.2@0,0.68'])
        _, err = capsys.readouterr()
    finally:
        os.chdir(here)
    assert code == 2 and err.strip().endswith(said[1][len('... '):]), err
