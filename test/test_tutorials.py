"""
Every tutorial works as written, on a fresh folder.

Each page of docs/tutorials/ is a command sequence a person types: every ``$ COMMAND`` line is
run in order in an empty folder with the checkout's bags/ and config/ beside it (as at the
top of a fresh clone), each must exit 0, and each line the page shows under a command must
be a line that command printed (test/tutorial_steps.py says how each kind of command is
run: the node and ``play`` as processes on this test run's own ROS domain). Every file a
page names under bags/ or config/ exists, every page is in the site's table of contents,
and after a page has run, what it says it made is there.
"""

from pathlib import Path
import re

import pytest

from tutorial_steps import run_page, Step, steps

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / 'docs' / 'tutorials'
PAGES = sorted(p.stem for p in TUTORIALS.glob('*.md'))

MADE = {
    'check_a_bag': ['replayed.mcap', 'loose_bracket.rrd', 'report/report.html',
                    'report/plane_I.png', 'report/plane_II.png'],
    'field_balancing': ['baseline.mcap', 'trial_I.mcap', 'trial_II.mcap', 'check.mcap',
                        'coefficients.yaml', 'report/report.html'],
    'design': ['counterweight.png'],
    'fleet': ['fleet/fleet_plan.yaml', 'fleet.parquet', 'charts/fleet.png',
              'charts/gantry-0001.png', 'charts/trends.csv'],
    'node_on_your_robot': ['live.mcap'],
}
"""What each tutorial makes, by its own account: there after it ran."""


def test_every_tutorial_is_listed_here_and_in_the_table_of_contents():
    assert PAGES and set(PAGES) == set(MADE)
    index = (ROOT / 'docs' / 'index.md').read_text()
    for page in PAGES:
        assert f'tutorials/{page}\n' in index, page


@pytest.mark.parametrize('page', PAGES)
def test_every_file_the_tutorial_names_exists(page):
    text = (TUTORIALS / f'{page}.md').read_text()
    named = set(re.findall(r'\b((?:bags|config)/[\w./-]+\.(?:yaml|mcap))', text))
    assert named, 'the tutorial names no bundled file'
    assert [n for n in sorted(named) if not (ROOT / n).exists()] == []


@pytest.mark.parametrize('page', PAGES)
def test_the_tutorial_runs_start_to_finish(page, tmp_path):
    done = run_page((TUTORIALS / f'{page}.md').read_text(), tmp_path)
    assert len(done) >= 3, 'a tutorial is a sequence of commands'
    missing = [name for name in MADE[page] if not (tmp_path / name).exists()]
    assert missing == [], f'{page} did not make {missing}'


def test_a_page_is_read_as_a_person_reads_it(tmp_path):
    """The reader of pages: commands, continuations, shown lines, ``...``, background."""
    text = '\n'.join([
        'Start:', '', '    $ cvc-balance solve config/ct_gantry.yaml \\', '          --omega 0',
        '    layout ct_gantry_demo (10 components, digest d3882a62afc9): mass 925.500 kg, '
        'centre of mass [-0.0001, 0.0001, 0.0253] m (rotor frame)', '    ...',
        'then', '', '```console', '$ balance-monitor --ros-args -p x:=1 &', '$ cvc-balance x',
        '```'])
    assert steps(text) == [
        Step(3, ['cvc-balance', 'solve', 'config/ct_gantry.yaml', '--omega', '0'],
             ['layout ct_gantry_demo (10 components, digest d3882a62afc9): mass 925.500 kg, '
              'centre of mass [-0.0001, 0.0001, 0.0253] m (rotor frame)']),
        Step(10, ['balance-monitor', '--ros-args', '-p', 'x:=1'], [], True),
        Step(11, ['cvc-balance', 'x'], [])]
    # The first step runs and prints its line; a line it does not print fails, named.
    assert len(run_page(text.split('then')[0], tmp_path)) == 1
    wrong = text.split('then')[0].replace('925.500 kg', '925.600 kg')
    with pytest.raises(AssertionError, match=r"line 3: .* did not print \['layout"):
        run_page(wrong, tmp_path)
    # A command that fails, and one this test cannot run, are named by their line.
    with pytest.raises(AssertionError, match='line 1: `cvc-balance solve nowhere.yaml --omega 1` '
                                             'exited 2'):
        run_page('$ cvc-balance solve nowhere.yaml --omega 1', tmp_path)
    with pytest.raises(AssertionError, match='line 1: `ros2 topic list` is not a command'):
        run_page('$ ros2 topic list', tmp_path)
