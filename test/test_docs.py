"""
The documentation site: built with warnings as errors, its reference made from the code.

``./dev.sh docs`` runs Sphinx on docs/ (MyST Markdown); the command and node reference pages
are generated at build time from the argparse parsers and the node's declarations. Here the
site is built into a temporary folder and the pages a person reads are checked against the
code itself: every command and option, every topic and parameter appears.
"""

import argparse
from html.parser import HTMLParser
from pathlib import Path
import re
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]


class Text(HTMLParser):
    """The visible text of an HTML page."""

    def __init__(self):
        """Start empty."""
        super().__init__()
        self.parts = []

    def handle_data(self, data):
        """Keep every text node."""
        self.parts.append(data)


def text_of(path):
    parser = Text()
    parser.feed(path.read_text(encoding='utf-8'))
    return ' '.join(' '.join(parser.parts).split())


@pytest.fixture(scope='module')
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp('site')
    run = subprocess.run([sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q', '-b',
                          'html', str(ROOT / 'docs'), str(out)], capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return out


def test_every_command_and_option_is_in_the_reference(site):
    from cvc_balance.cli import parser
    page = text_of(site / 'reference' / 'commands.html')
    sub = next(a for a in parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        assert f'cvc-balance {name}' in page, name
        for action in command._actions:
            if action.help == argparse.SUPPRESS:      # an old spelling, refused by name
                continue
            for option in action.option_strings:
                if option not in ('-h', '--help'):
                    assert option in page, (name, option)


def test_every_topic_and_parameter_of_the_node_is_in_the_reference(site):
    from cvc_balance.ros.balance_monitor import PARAMETERS, TOPICS
    page = text_of(site / 'reference' / 'node.html')
    for name, kind, _, _ in TOPICS:
        assert name in page and kind in page, name
    for name, default, _, _ in PARAMETERS:
        assert name in page and repr(default) in page, name


def test_no_help_text_says_a_doubled_percent_sign(site):
    """Descriptions are not %-formatted by argparse (help strings are): '%%' shows as typed."""
    page = text_of(site / 'reference' / 'commands.html')
    assert '%%' not in page, page[max(0, page.index('%%') - 80):page.index('%%') + 20]


def probe_known_fields(document, path):
    """Return the fields the layout reader lists when ``path`` of ``document`` has another."""
    import copy
    import json
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    document = copy.deepcopy(document)
    where = document
    for part in path:
        where = where[part]
    where['no_such_field'] = 1
    with pytest.raises(LayoutError) as refused:
        layout_from_text(json.dumps(document))
    return re.search(r'\(known: ([^)]*)\)', str(refused.value))[1].split(', ')


def test_the_layout_page_describes_every_field_the_reader_knows(site):
    layout = {'name': 'r', 'components': [{'name': 'c', 'mass': 1, 'radius': 0.5,
                                           'angle_deg': 0, 'inertia': {
                                               'ixx': 1, 'iyy': 1, 'izz': 1, 'ixy': 0,
                                               'ixz': 0, 'iyz': 0}}],
              'supports': [{'name': 'front', 'z': -0.1}, {'name': 'rear', 'z': 0.1,
                                                          'axial': True}],
              'balancing': {'sites': {'I': {'angles_deg': [0], 'radius': 0.5,
                                            'masses': [0.1]}}}}
    page = (site / 'reference' / 'layout_file.html').read_text(encoding='utf-8')
    terms = set(re.findall(r'<dt><code[^>]*><span class="pre">(\w+)</span>', page))
    for path in [(), ('components', 0), ('components', 0, 'inertia'), ('supports', 0),
                 ('balancing',), ('balancing', 'sites'), ('balancing', 'sites', 'I')]:
        known = probe_known_fields(layout, path)
        assert set(known) <= terms, (path, set(known) - terms)
    # Each field's refusal is the reader's own words: one of them, made here.
    import json
    from cvc_balance.physics.layout import LayoutError
    from cvc_balance.physics.layout_file import layout_from_text
    layout['components'][0]['mass'] = -1
    with pytest.raises(LayoutError) as refused:
        layout_from_text(json.dumps(layout))
    said = str(refused.value).replace("'r'", "'probe'")
    assert said.split(': ', 1)[1] in text_of(site / 'reference' / 'layout_file.html'), said


def test_the_json_page_shows_what_the_commands_print(site, tmp_path, capsys):
    import json
    import os
    from cvc_balance.cli import main
    from cvc_balance.fleet.rows import FAILURE_SCHEMA, RESULT_SCHEMA
    page = text_of(site / 'reference' / 'json_outputs.html')
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        assert main(['replay', 'bags/loose_bracket.mcap', '--json']) == 0
    finally:
        os.chdir(here)
    printed = json.loads(capsys.readouterr().out)
    for key in list(printed) + list(printed['segments'][0]) + \
            list(printed['segments'][0]['verdict']):
        assert re.search(rf'\b{key} :', page), key
    for column in list(RESULT_SCHEMA) + list(FAILURE_SCHEMA):
        assert column.name in page, column.name


def test_every_command_shown_on_the_other_pages_runs(tmp_path):
    """The tutorials run in test_tutorials.py; a ``$ `` command on any other page runs too."""
    from tutorial_steps import run_page, steps
    pages = [p for p in sorted((ROOT / 'docs').rglob('*.md'))
             if not {'_build', 'tutorials', 'reference'} & set(p.parts)]
    ran = 0
    for page in pages:
        text = page.read_text(encoding='utf-8')
        if steps(text):
            folder = tmp_path / page.stem
            folder.mkdir()
            ran += len(run_page(text, folder))
    assert ran >= 1


def test_the_ranges_page_has_every_limit_with_its_range(site):
    from cvc_balance.physics import limits
    page = text_of(site / 'reference' / 'limits.html')
    found = {name: value for name, value in vars(limits).items()
             if isinstance(value, limits.Limit)}
    assert len(found) > 30
    for name, limit in found.items():
        assert f'{name} :' in page or f'{name}:' in page, name
        assert limit.describe() in page, (name, limit.describe())
