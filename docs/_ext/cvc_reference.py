"""
Sphinx extension: write the reference pages from the code they describe.

At ``builder-inited`` it writes ``reference/commands.md`` (every ``cvc-balance`` command and
option, from the argparse parsers), ``reference/node.md`` (every topic and parameter of
the ``balance_monitor`` node, from its ``TOPICS`` and ``PARAMETERS`` declarations) and
``reference/modules.md`` (every package, its layer as test/test_architecture.py enforces
it, and every module with the first paragraph of its docstring). Nothing in them is typed
by hand, so the reference cannot drift from the code.
"""

import argparse
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _escape(text):
    """Return ``text`` safe inside a Markdown table cell."""
    return str(text).replace('|', '\\|').replace('\n', ' ')


def _option_rows(parser):
    rows = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)) or \
                action.help == argparse.SUPPRESS:     # an old spelling, refused
            continue
        if action.option_strings:
            name = ', '.join(f'`{o}`' for o in action.option_strings)
            if action.nargs != 0:
                metavar = action.metavar or action.dest.upper()
                metavar = ' '.join(metavar) if isinstance(metavar, tuple) else metavar
                name += f' `{metavar}`'
        else:
            name = f'`{action.metavar or action.dest}`'
        default = '' if action.default in (None, argparse.SUPPRESS, False) or \
            action.nargs == 0 and action.default is False else f'`{action.default!r}`'
        choices = f" (one of {', '.join(map(str, action.choices))})" if action.choices else ''
        meaning = action.help % vars(action) if action.help else ''
        rows.append(f'| {name} | {_escape(meaning)}{_escape(choices)} | {default} |')
    return rows


def commands_page():
    """Return the Markdown of every cvc-balance command, from the parsers."""
    from cvc_balance.cli import parser
    top = parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    lines = ['# Command reference', '',
             'Generated from the `cvc-balance` argument parsers at build time '
             '(`cvc_balance/cli/`). Exit codes: 0 done, 1 nothing to report or a failure '
             'that is not the input\'s, 2 bad input (one line on stderr naming what is '
             'wrong).', '']
    helps = {a.dest: a.help for a in sub._choices_actions}
    for name, command in sub.choices.items():
        lines += [f'## `cvc-balance {name}`', '', _escape(helps.get(name) or ''), '',
                  command.description or '', '', '```text', command.format_usage().strip(),
                  '```', '', '| argument | meaning | default |', '|---|---|---|']
        lines += _option_rows(command)
        lines.append('')
    return '\n'.join(lines)


def node_page():
    """Return the Markdown of the node's topics and parameters, from its declarations."""
    from cvc_balance.ros.balance_monitor import PARAMETERS, TOPICS
    lines = ['# Node reference: `balance_monitor`', '',
             'Generated from the node\'s `TOPICS` and `PARAMETERS` declarations at build time '
             '(`cvc_balance/ros/balance_monitor.py`), the same ones `balance-monitor --help` '
             'prints. Topic names are relative: `-r __ns:=/gantry1` puts them under '
             '`/gantry1`; `<name>` is each support of the layout in force.', '']
    for direction, heading in (('in', 'Subscriptions'), ('out', 'Publications')):
        lines += [f'## {heading}', '', '| topic | type | what it carries |', '|---|---|---|']
        lines += [f'| `{name}` | `{kind}` | {_escape(text)} |'
                  for name, kind, way, text in TOPICS if way == direction]
        lines.append('')
    lines += ['## Parameters', '',
              'Given as `-p NAME:=VALUE` after `--ros-args`, or in a parameters file '
              '(`config/balance_monitor.yaml`, keyed `/**` so it applies under any name and '
              'namespace).', '', '| parameter | default | range | meaning |',
              '|---|---|---|---|']
    for name, default, description, bounds in PARAMETERS:
        limits = f'{bounds[0]:g} to {bounds[1]:g}' if bounds else ''
        lines.append(f'| `{name}` | `{default!r}` | {limits} | {_escape(description)} |')
    return '\n'.join(lines) + '\n'


def _layers():
    """Return {package: (layer, what)} from test/test_architecture.py's LAYERS and comments."""
    source = (ROOT / 'test' / 'test_architecture.py').read_text(encoding='utf-8')
    tree = ast.parse(source)
    lines = source.splitlines()
    layers = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and [getattr(t, 'id', None) for t in node.targets] \
                == ['LAYERS']:
            for key, value in zip(node.value.keys, node.value.values):
                comment = lines[key.lineno - 1].partition('#')[2].strip()
                layers[key.value] = (value.value, comment)
    return layers


def _first_paragraph(path):
    doc = ast.get_docstring(ast.parse(path.read_text(encoding='utf-8'))) or ''
    return ' '.join(doc.strip().split('\n\n')[0].split())


def modules_page():
    """Return the Markdown of the package's layers and modules, from the code."""
    package = ROOT / 'cvc_balance'
    layers = _layers()
    lines = ['# Modules', '',
             '`cvc_balance/` is one subpackage per concern, each a layer that imports only '
             'the layers below it: `test/test_architecture.py` reads every import (those '
             'inside functions too) and fails on an upward, sideways or circular one. This '
             'page is written at build time from that test\'s table of layers and from each '
             'module\'s own docstring. Each package\'s `__init__.py` names its public API '
             '(`from cvc_balance.physics import RotorModel, loads`).', '']
    folders = sorted((p for p in package.iterdir() if (p / '__init__.py').exists()),
                     key=lambda p: (layers.get(p.name, (99, ''))[0], p.name))
    for folder in folders:
        layer, what = layers.get(folder.name, ('?', ''))
        lines += [f'## `{folder.name}/` (layer {layer})', '', what + ('.' if what else ''),
                  '', '| module | what it is |', '|---|---|']
        for module in sorted(folder.glob('*.py')):
            lines.append(f'| `{module.stem}` | {_escape(_first_paragraph(module))} |')
        lines.append('')
    return '\n'.join(lines)


def tests_page():
    """Return the Markdown of every test file, its test functions and what it checks."""
    lines = ['# Test catalogue', '',
             'Every file of `test/`, written at build time from the files themselves: the '
             'number of test functions in it (parametrised ones run more cases) and the first '
             'paragraph of its docstring. What the tests compare against, by subject: '
             '[the tests](../validation/tests.md). Run one file with `./dev.sh run python -m '
             'pytest test/FILE -q`; all of them with `./dev.sh test`.', '',
             '| file | tests | what it checks |', '|---|---|---|']
    for path in sorted((ROOT / 'test').glob('test_*.py')):
        tree = ast.parse(path.read_text(encoding='utf-8'))
        count = sum(isinstance(node, ast.FunctionDef) and node.name.startswith('test_')
                    for node in ast.walk(tree))
        lines.append(f'| `{path.name}` | {count} | {_escape(_first_paragraph(path))} |')
    return '\n'.join(lines) + '\n'


def write_generated(srcdir, pages):
    """Write {name: Markdown} into ``srcdir``/reference (ignored by git), where it changed."""
    folder = Path(srcdir) / 'reference'
    folder.mkdir(exist_ok=True)
    for name, text in pages.items():
        path = folder / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)


def write_pages(app):
    """Write the generated pages into the source folder (ignored by git)."""
    write_generated(app.srcdir, {'commands.md': commands_page(), 'node.md': node_page(),
                                 'modules.md': modules_page(), 'tests.md': tests_page()})


def setup(app):
    """Register the page writer."""
    app.connect('builder-inited', write_pages)
    return {'version': '1', 'parallel_read_safe': True}
