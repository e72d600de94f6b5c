"""
``cvc-balance ARGS`` run in the test's own process, its result read as a finished process's.

A new process pays Python, numpy, rclpy and the readers' imports (1-2 s each time on the
2-core machine); where the command line's words and exit code are what is tested, not the
process, this gives the same exit code and the same text on stdout and stderr. Each command is
still run as its own process by some test (``test/test_command_line_edges.py``: every
command's help; the live tests: play and record; the others where a file keeps one).
"""

import contextlib
import io
import subprocess

from cvc_balance.cli import main


def cvc(*args):
    """Run the command line here: a CompletedProcess (returncode, stdout, stderr: text)."""
    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as stop:          # argparse: --help, or a bad command line
            code = stop.code if isinstance(stop.code, int) else int(stop.code is not None)
    return subprocess.CompletedProcess(['cvc-balance', *argv], code, out.getvalue(),
                                       err.getvalue())


def run_cli(*args):
    """Run the command line here: (exit code, stdout, stderr)."""
    done = cvc(*args)
    return done.returncode, done.stdout, done.stderr
