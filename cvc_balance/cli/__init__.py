"""
The ``cvc-balance`` command line: thin adapters around the engine, one module per group.

Each module of this package adds its commands with ``register(commands)`` (an argparse
sub-parser group) and gives each a ``run(args)`` that returns the exit code. SI units;
degrees only where people read or type angles. Exit codes: 0 done, 2 bad input (one line
on stderr naming what is wrong).
"""

import argparse
import importlib
import os
import sys

from cvc_balance.cli.arguments import EXIT_BAD_INPUT, EXIT_FAILURE
from cvc_balance.physics.layout import LayoutError, one_line

EXIT_BROKEN_PIPE = 141
"""Exit code when the reader of stdout went away (128 + SIGPIPE, as the shell reports it)."""
COMMAND_MODULES = ('solve', 'design', 'bags', 'reindex', 'identify', 'life', 'field',
                   'readings', 'fleet', 'bench')
"""Modules of this package that add commands, in the order ``--help`` lists them."""


def main(argv=None):
    """Run the command line; returns the exit code."""
    args = parser().parse_args(argv)
    try:
        return args.run(args)
    except BrokenPipeError:
        # The reader went away (`cvc-balance ... | head`): stop quietly, as a POSIX tool
        # killed by SIGPIPE does; stdout goes to /dev/null so the exit flush cannot fail.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except (LayoutError, ValueError, OSError) as error:
        print(f'cvc-balance: error: {one_line(error, 2000)}', file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print('cvc-balance: interrupted', file=sys.stderr)
        return 130
    except Exception as error:  # a bug, not the input's fault: one line, never a traceback
        print(f'cvc-balance: internal error: {type(error).__name__}: {one_line(error, 300)} '
              '(please report it with the command that gave it)', file=sys.stderr)
        return EXIT_FAILURE


class Parser(argparse.ArgumentParser):
    """argparse, with a bad command line said in one line (no usage block) and exit code 2."""

    def error(self, message):
        """Print ``message`` on one line and exit with EXIT_BAD_INPUT."""
        self.exit(EXIT_BAD_INPUT, f'{self.prog}: error: {one_line(message, 500)} '
                  '(see --help)\n')


def parser():
    """Return the argument parser of every command."""
    top = Parser(
        prog='cvc-balance', description='Bearing loads, drive torque and unbalance of a '
        'rotor from its component layout (cylindrical vector components).')
    commands = top.add_subparsers(dest='command', required=True, metavar='COMMAND',
                                  parser_class=Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(f'cvc_balance.cli.{name}').register(commands)
    return top
