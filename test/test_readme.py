"""
The README is short and every command it shows works as it shows.

It is at most 200 lines; its first lines are the two commands that work on a fresh machine
(``./dev.sh demo``, ``./dev.sh test``); each ``$ COMMAND`` it shows is run as the tutorials
are (test/tutorial_steps.py), each line shown under it printed, except the long-running
ones, each run here its own way or named with the test that covers it. Every file and page
it links to exists.
"""

import os
from pathlib import Path
import re
import signal
import subprocess
import time

import pytest

from ros_harness import ros_environment
from tutorial_steps import command_of, missing_lines, run_page, steps

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'

NODE = './dev.sh run balance-monitor --ros-args'
LONG_RUNNING = {
    './dev.sh demo': 'test_the_demo_prints_what_the_readme_shows, here',
    './dev.sh test': 'the suite itself (.ci/run runs it in CI)',
    './dev.sh docs': 'test_docs.py builds the site with warnings as errors',
    NODE: 'test_the_node_starts_as_the_readme_shows, here (it runs until Ctrl-C)',
}
"""Commands the README shows that run long or for ever, and what tests each."""


def shown_steps():
    return steps(README.read_text(encoding='utf-8'))


def long_running(step):
    """Return the LONG_RUNNING key of a step, or None."""
    text = str(step)
    return next((key for key in LONG_RUNNING if text == key or text.startswith(key + ' ')),
                None)


def test_the_readme_is_short():
    lines = README.read_text(encoding='utf-8').splitlines()
    assert len(lines) <= 200, len(lines)


def test_its_first_lines_are_the_two_commands():
    lines = README.read_text(encoding='utf-8').splitlines()
    assert lines[0].startswith('# ')
    assert lines[2].split('#')[0].split() == ['./dev.sh', 'demo'], lines[2]
    assert lines[3].split('#')[0].split() == ['./dev.sh', 'test'], lines[3]
    assert {long_running(s) for s in shown_steps()} >= {'./dev.sh demo', './dev.sh docs'}


def test_every_command_it_shows_runs_or_is_tested_elsewhere(tmp_path):
    found = shown_steps()
    assert len(found) >= 6
    runnable = []
    for step in found:
        if long_running(step):
            continue
        kind, _ = command_of(step.words)
        assert kind, f'README line {step.line}: `{step}` is neither run here nor long-running'
        runnable.append(step)
    assert len(runnable) >= 3
    # Run them in order, as a page: each line the README shows under one must be printed.
    page = '\n'.join(f'$ {s}\n' + '\n'.join(f'  {line}' for line in s.shown) + '\n'
                     for s in runnable)
    run_page(page, tmp_path)


def test_every_link_and_picture_exists():
    """In the checkout as cloned: docs/reference/ is written by the build, so never linked."""
    text = README.read_text(encoding='utf-8')
    targets = re.findall(r'\]\(([^)\s#]+)(?:#[^)]*)?\)', text)
    assert len(targets) > 20
    assert [t for t in targets if t.startswith('docs/reference/')] == []
    missing = [t for t in targets if not t.startswith('http') and not (ROOT / t).exists()]
    assert missing == []


def sandbox(tmp_path):
    """Return a folder that looks to dev.sh like the checkout (its .venv, bags, config)."""
    for name in ('dev.sh', '.venv', 'requirements.txt', 'requirements-test.txt', 'setup.py',
                 'bags', 'config'):
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def test_the_demo_prints_what_the_readme_shows(tmp_path):
    (step,) = [s for s in shown_steps() if long_running(s) == './dev.sh demo']
    assert step.shown, 'the README shows none of what the demo prints'
    folder = sandbox(tmp_path)
    run = subprocess.run(['./dev.sh', 'demo'], cwd=folder, env=ros_environment(), text=True,
                         capture_output=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert missing_lines(step, run.stdout) == [], run.stdout
    for made in ('spin_up_tube_swap_live.mcap', 'spin_up_tube_swap_live.rrd'):
        assert (folder / 'runs' / made).stat().st_size > 10_000, made


def test_the_node_starts_as_the_readme_shows(tmp_path):
    """It comes up with the shown layout, runs until SIGINT, and then exits 0."""
    (step,) = [s for s in shown_steps() if long_running(s) == NODE]
    assert step.shown
    _, args = command_of(step.words)
    log = tmp_path / 'node.log'
    sandbox(tmp_path)
    with open(log, 'w') as stream:
        node = subprocess.Popen(args, cwd=tmp_path, env=ros_environment(), stdout=stream,
                                stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while missing_lines(step, log.read_text()) and time.monotonic() < deadline:
            assert node.poll() is None, log.read_text()
            time.sleep(0.2)
        assert missing_lines(step, log.read_text()) == [], log.read_text()
        time.sleep(1.0)
        assert node.poll() is None, 'the node ended by itself'
    finally:
        node.send_signal(signal.SIGINT)
        code = node.wait(20)
    assert code == 0, log.read_text()


@pytest.mark.skipif(not os.access(ROOT / 'dev.sh', os.X_OK), reason='dev.sh not executable')
def test_dev_sh_lists_the_jobs_the_readme_names():
    run = subprocess.run([str(ROOT / 'dev.sh')], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    jobs = set(re.findall(r'^#?\s*\./dev\.sh (\w+)', run.stderr, re.M))
    named = set(re.findall(r'`(\w+)`', re.search(r'lists its jobs: (.*?)\. ',
                                                 README.read_text(), re.S)[1]))
    assert named <= jobs and {'demo', 'test', 'docs', 'pictures', 'bags'} <= named, (named, jobs)
