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
