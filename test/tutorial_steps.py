r"""
Run a page's shell session as written: the ``$ COMMAND`` lines of a Markdown page, in order.

A page (a tutorial, the README) shows what a person types after ``$ `` and, under it, lines
the command prints. Here each command is run in order in one folder, and each line shown
under it must be a line it printed (stdout or stderr, stripped; a ROS log line also without
its ``[LEVEL] [time] [node]: `` prefix). A line ``...`` stands for lines left out, and
``...`` within a line for any text (a path's start). A command ending in `` \`` goes on on
the next line; one ending in ``&`` runs in the background until the page is done (then
SIGINT, and it must exit 0); `` # `` starts a comment.

What is run, and how:

- ``cvc-balance ARGS``: in this process (``cvc_balance.cli.main``), but ``play`` and
  ``record``, which join the ROS graph: those as processes on the test run's own
  ROS_DOMAIN_ID (:mod:`ros_harness`);
- ``balance-monitor ARGS``: the node, as a process on that domain;
- ``./dev.sh run CMD``: CMD as above (the environment is this one);
- ``kill %N``: the shell's: SIGTERM to the page's N-th background command, which must then
  exit 0 and print what the page shows under the ``kill``;
- anything else is not runnable here: the page must not show it after ``$ ``.
"""

from dataclasses import dataclass, field
import contextlib
import io
import os
from pathlib import Path
import re
import shlex
import signal
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Step:
    """One command of a page and the lines the page shows it print."""

    line: int                   # 1-based line of the page where the command starts
    words: list                 # the command, split as a shell would (no ``$``, no ``&``)
    shown: list = field(default_factory=list)
    background: bool = False

    def __str__(self):
        """Return the command as the page shows it."""
        return shlex.join(self.words) + (' &' if self.background else '')


def steps(text):
    """Return the page's Steps in order."""
    found, lines = [], text.splitlines()
    k = 0
    while k < len(lines):
        line = lines[k]
        stripped = line.strip()
        k += 1
        if not stripped.startswith('$ '):
            continue
        start, indent, command = k, len(line) - len(line.lstrip()), stripped[2:]
        while command.endswith('\\') and k < len(lines):
            command = command[:-1] + ' ' + lines[k].strip()
            k += 1
        command = re.sub(r'\s#\s.*$', '', command).rstrip()
        background = command.endswith('&')
        words = shlex.split(command.rstrip('&'))
        shown = []
        while k < len(lines):
            following = lines[k]
            bare = following.strip()
            if not bare or bare.startswith('$ ') or bare.startswith('```') or \
                    len(following) - len(following.lstrip()) < indent:
                break
            if bare != '...':
                shown.append(bare)
            k += 1
        found.append(Step(start, words, shown, background))
    return found


ROS_COMMANDS = ('play', 'record')
"""cvc-balance commands that join the ROS graph: run as processes on the test's domain."""


def command_of(words):
    """Return (kind, args) of a command: kind 'cli' (in process), 'process' or None."""
    if words[:2] == ['./dev.sh', 'run']:
        words = words[2:]
    if words and words[0] == 'cvc-balance':
        args = words[1:]
        if args and args[0] in ROS_COMMANDS:
            return 'process', [sys.executable, '-m', 'cvc_balance.cli', *args]
        return 'cli', args
    if words and words[0] == 'balance-monitor':
        return 'process', [sys.executable, '-m', 'cvc_balance.ros.balance_monitor', *words[1:]]
    return None, words


def run_cli(args):
    """Run ``cvc-balance ARGS`` in this process; return (exit code, printed text)."""
    from cvc_balance.cli import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as stop:      # argparse's own exits (--help, a bad option)
            code = stop.code if isinstance(stop.code, int) else 2
    return code, out.getvalue() + err.getvalue()


class Session:
    """A folder where a page's commands run, with the checkout's bags/ and config/ beside."""

    def __init__(self, folder, timeout=300):
        """Prepare ``folder`` as a fresh clone's top would look to the commands."""
        self.folder = Path(folder)
        self.timeout = timeout
        self.background = []            # (Step, Popen, log path)
        for name in ('bags', 'config'):
            link = self.folder / name
            if not link.exists():
                link.symlink_to(ROOT / name)

    def run(self, step):
        """Run one step; return (exit code, printed text); background steps return (None, '')."""
        if step.words[:1] == ['kill'] and len(step.words) == 2 and \
                step.words[1].startswith('%'):
            return self.end(int(step.words[1][1:]), signal.SIGTERM)
        kind, args = command_of(step.words)
        assert kind, f'line {step.line}: `{step}` is not a command this test can run'
        if kind == 'cli':
            assert not step.background, f'line {step.line}: cvc-balance in the background'
            here = os.getcwd()
            os.chdir(self.folder)
            try:
                return run_cli(args)
            finally:
                os.chdir(here)
        from ros_harness import ros_environment
        if step.background:
            log = self.folder / f'.background_{len(self.background)}.log'
            with open(log, 'w') as stream:
                process = subprocess.Popen(args, cwd=self.folder, env=ros_environment(),
                                           stdout=stream, stderr=subprocess.STDOUT)
            self.background.append((step, process, log))
            return None, ''
        run = subprocess.run(args, cwd=self.folder, env=ros_environment(), text=True,
                             capture_output=True, timeout=self.timeout)
        return run.returncode, run.stdout + run.stderr

    def end(self, job, sig):
        """End background job ``job`` (1-based, as the shell counts); return (code, text)."""
        assert 0 < job <= len(self.background), f'no background job %{job}'
        _, process, log = self.background[job - 1]
        if process.poll() is None:
            process.send_signal(sig)
            try:
                process.wait(20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        return process.returncode, log.read_text(errors='replace')

    def stop(self):
        """Stop the background commands (SIGINT); return [(Step, exit code, printed text)]."""
        ended = [(step, *self.end(job, signal.SIGINT))
                 for job, (step, process, _) in enumerate(self.background, 1)
                 if process.returncode is None]
        self.background = []
        return ended


ROS_LOG_PREFIX = re.compile(r'^\[[A-Z]+\] \[[0-9.]+\] \[[^\]]*\]: ')
"""What rclpy's logger puts before a message: ``[INFO] [1700000000.123] [ns.node]: ``."""


def missing_lines(step, printed):
    """Return the lines the page shows under ``step`` that it did not print."""
    said = set()
    for line in printed.splitlines():
        said.update({line.strip(), ROS_LOG_PREFIX.sub('', line.strip())})
    missing = []
    for line in step.shown:
        if '...' in line:
            pattern = re.compile('.*'.join(map(re.escape, line.split('...'))))
            found = any(pattern.fullmatch(s) for s in said)
        else:
            found = line in said
        if not found:
            missing.append(line)
    return missing


def run_page(text, folder, timeout=300):
    """
    Run every step of a page in ``folder``; return [Step] done.

    Fails (AssertionError) at the first command that does not exit 0, or that does not print
    a line the page shows under it, naming the line of the page.
    """
    session = Session(folder, timeout)
    done = []
    try:
        for step in steps(text):
            code, printed = session.run(step)
            if not step.background:
                assert code == 0, f'line {step.line}: `{step}` exited {code}:\n{printed}'
                missing = missing_lines(step, printed)
                assert not missing, (f'line {step.line}: `{step}` did not print {missing}; '
                                     f'it printed:\n{printed}')
            done.append(step)
    finally:
        ended = session.stop()
    for step, code, printed in ended:
        assert code == 0, f'line {step.line}: `{step}` exited {code}:\n{printed}'
        missing = missing_lines(step, printed)
        assert not missing, f'line {step.line}: `{step}` did not print {missing}:\n{printed}'
    return done
