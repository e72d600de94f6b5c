"""
The command line where people stumble: --help everywhere, the wrong file, nothing to play into.

Each answer is one clear line (exit code 2 for bad input, 1 when there is nothing to play
into) or the help text (exit code 0), never a traceback and never a node left running.
"""

import subprocess
import sys

import pytest

from ros_harness import ros_environment

COMMANDS = ['solve', 'simulate', 'replay', 'view', 'play', 'record', 'bench']


def run(args, timeout=60, **kwargs):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True,
                          timeout=timeout, **kwargs)


@pytest.mark.parametrize('command', [[]] + [[c] for c in COMMANDS])
def test_help_of_every_command(command):
    done = run(['-m', 'cvc_balance.cli', *command, '--help'])
    assert done.returncode == 0 and done.stdout.startswith('usage: cvc-balance')
    assert done.stderr == ''


@pytest.mark.parametrize('args', [['--help'], ['-h'], ['--ros-args', '--help']])
def test_node_help_prints_and_exits_without_starting_ros(args):
    """The help lists every parameter; a node would run until killed (the timeout)."""
    from cvc_balance.ros.balance_monitor import PARAMETERS
    done = run(['-m', 'cvc_balance.ros.balance_monitor', *args], timeout=30,
               env=ros_environment())
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith('usage: balance-monitor')
    for name, *_ in PARAMETERS:
        assert f'  {name} (default' in done.stdout
    assert '[INFO]' not in done.stdout + done.stderr


@pytest.mark.parametrize('args, words', [(['extra'], "unexpected argument 'extra'"),
                                         (['--ros-args', '--bogus'], 'bad ROS arguments')])
def test_node_bad_arguments_get_one_line_and_exit_code_2(args, words):
    done = run(['-m', 'cvc_balance.ros.balance_monitor', *args], timeout=30,
               env=ros_environment())
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and 'Traceback' not in done.stderr


def test_simulate_given_a_layout_says_it_is_a_layout(tmp_path):
    done = run(['-m', 'cvc_balance.cli', 'simulate', 'config/ct_gantry.yaml', '-o',
                str(tmp_path / 'x.mcap')])
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'is a layout file' in lines[0] and 'scenario' in lines[0]
    assert not (tmp_path / 'x.mcap').exists()


@pytest.mark.parametrize('record', [False, True])
def test_play_with_no_node_names_what_it_waits_for_and_gives_up(record, tmp_path):
    """On this run's own ROS domain nobody listens: play says so after the time it stated."""
    out = tmp_path / 'out.mcap'
    # A hang (the old play waited over 300 s with -o) fails here by the subprocess timeout.
    done = run(['-m', 'cvc_balance.cli', 'play', 'bags/spin_up_tube_swap.mcap', '--wait', '2']
               + (['-o', str(out)] if record else []), timeout=120, env=ros_environment())
    assert done.returncode == 1, done.stderr
    assert 'waiting up to 2 s for a node subscribed to /joint_states' in done.stdout
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'no node subscribed to /joint_states within 2 s' in lines[0]
    assert 'Traceback' not in done.stderr
    assert not out.exists()       # no recorder was started, no empty file left
