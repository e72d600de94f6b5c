"""
docs/tutorials/field_balancing.md: the mistake it shows is said as it shows it.

The tutorial itself is run, command by command, by test_tutorials.py (with every other
tutorial); here the refusal it quotes in its prose (a trial mass in g typed as kg) is
made and compared word for word.
"""

import os
from pathlib import Path
import re

import pytest

from cvc_balance.cli import main

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / 'docs' / 'tutorials' / 'field_balancing.md'


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
