"""
No command writes over its input or leaves a half-written file under the final name.

``replay BAG -o BAG`` used to destroy its input, also through a symlink or a hard link;
``view BAG -o BAG`` overwrote a bag with an .rrd; an output into a missing folder gave a
traceback, after the work (``bench`` after 5 minutes). Each case here: exit code 2, one
line, the input byte for byte as it was, and nothing left behind.
"""

import hashlib
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from cvc_balance.files import check_output, OutputError, replaced_when_done
from in_process import cvc

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'tilted_shift.mcap'


def process(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=timeout)


def cli(*args, timeout=120):
    # In this process, but `record` (a ROS node) and the finished replay below: processes.
    return process(*args, timeout=timeout) if args[0] == 'record' else cvc(*args)


def digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def one_line_refusal(run, *needles):
    assert run.returncode == 2, (run.returncode, run.stderr)
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in run.stderr, run.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.fixture
def bag(tmp_path):
    copy = tmp_path / 'run.mcap'
    shutil.copy(BAG, copy)
    return copy


def test_replay_and_view_never_write_over_their_input(bag, tmp_path):
    before = digest(bag)
    (tmp_path / 'link.mcap').symlink_to(bag)
    os.link(bag, tmp_path / 'hard.mcap')
    for output in (bag, tmp_path / 'link.mcap', tmp_path / 'hard.mcap',
                   tmp_path / '.' / 'run.mcap'):
        one_line_refusal(cli('replay', bag, '-o', output), 'input')
        one_line_refusal(cli('replay', bag, '--rrd', output), 'input')
        one_line_refusal(cli('view', bag, '-o', output), 'input')
    assert digest(bag) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['hard.mcap', 'link.mcap', 'run.mcap']


def test_directories_in_or_around_the_input_are_refused(tmp_path):
    directory = tmp_path / 'bag_dir'
    assert cli('simulate', ROOT / 'bags' / 'tilted_shift.yaml', '-o', directory).returncode == 0
    one_line_refusal(cli('replay', directory, '-o', directory / 'out.mcap'), 'input')
    one_line_refusal(cli('replay', directory / 'bag_dir_0.mcap', '-o', directory), 'input')


def test_outputs_into_missing_folders_are_refused_before_any_work(bag, tmp_path):
    missing = tmp_path / 'no' / 'such'
    one_line_refusal(cli('replay', bag, '-o', missing / 'out.mcap'), 'does not exist')
    one_line_refusal(cli('replay', bag, '--rrd', missing / 'run.rrd'), 'does not exist')
    one_line_refusal(cli('view', bag, '-o', missing / 'run.rrd'), 'does not exist')
    one_line_refusal(cli('simulate', ROOT / 'bags' / 'tilted_shift.yaml', '-o',
                         missing / 'x.mcap'), 'does not exist')
    one_line_refusal(cli('record', '-o', missing / 'x.mcap'), 'does not exist')
    # bench takes minutes of work: its refusal must come at once (the timeout says so).
    one_line_refusal(cli('bench', '--csv', missing / 'b.csv', timeout=60), 'does not exist')
    one_line_refusal(cli('sweep', ROOT / 'config' / 'ct_gantry.yaml', '--component',
                         'xray_tube', '--parameter', 'mass', '--range', '59', '61', '-o',
                         missing / 's.png'), 'does not exist')


def test_a_finished_replay_leaves_its_output_and_nothing_else(bag, tmp_path):
    out = tmp_path / 'out.mcap'
    out.write_bytes(b'an older file of that name')
    run = process('replay', bag, '-o', out, '--rrd', tmp_path / 'run.rrd')
    assert run.returncode == 0, run.stderr
    assert out.read_bytes()[:8] == b'\x89MCAP0\r\n'          # replaced, a whole bag
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out.mcap', 'run.mcap', 'run.rrd']


def test_a_failed_write_leaves_the_old_file_and_no_partial(tmp_path):
    target = tmp_path / 'result.csv'
    target.write_text('old\n')
    with pytest.raises(RuntimeError):
        with replaced_when_done(target) as path:
            path.write_text('half')
            raise RuntimeError('stopped halfway')
    assert target.read_text() == 'old\n'
    assert [p.name for p in tmp_path.iterdir()] == ['result.csv']
    with replaced_when_done(target) as path:
        path.write_text('new\n')
    assert target.read_text() == 'new\n' and len(list(tmp_path.iterdir())) == 1


def test_check_output_cases(tmp_path):
    (tmp_path / 'in.txt').write_text('x')
    check_output(tmp_path / 'out.txt', [tmp_path / 'in.txt', None, tmp_path / 'absent'])
    with pytest.raises(OutputError, match='input'):
        check_output(tmp_path / 'in.txt', [tmp_path / 'in.txt'])
    with pytest.raises(OutputError, match='does not exist'):
        check_output(tmp_path / 'a' / 'b.txt')


def test_fleet_outputs_are_checked_before_the_work(tmp_path, monkeypatch, capsys):
    """
    ``trends -o`` and ``simulate-fleet -o``: a file, the results table, a missing folder.

    Before, they were found after the work ("[Errno 17] File exists: 'table.parquet'"), and
    ``trends -o /a/b/c`` made the folders. The work is replaced here by a stand-in that
    fails the test if reached.
    """
    from cvc_balance.cli import main
    from cvc_balance.fleet import simulate, trends

    def reached(*args, **kwargs):
        raise AssertionError('the work started before the output was checked')
    monkeypatch.setattr(trends, 'machine_trends', reached)
    monkeypatch.setattr(simulate, 'simulate_fleet', reached)
    table = tmp_path / 'table.parquet'
    table.write_bytes(b'PAR1 not really')
    (tmp_path / 'notes.txt').write_text('keep me')
    layout = ROOT / 'config' / 'ct_gantry.yaml'
    cases = [(['trends', table, '-o', table], f'{table}: exists and is not a directory'),
             (['trends', table, '-o', tmp_path / 'notes.txt'], 'exists and is not a directory'),
             (['trends', table, '-o', tmp_path / 'a' / 'b'],
              f'folder {tmp_path / "a"} does not exist'),
             (['simulate-fleet', layout, '-o', tmp_path / 'notes.txt'],
              'exists and is not a directory'),
             (['simulate-fleet', layout, '-o', tmp_path / 'x' / 'y'],
              f'folder {tmp_path / "x"} does not exist')]
    for argv, says in cases:
        assert main([str(a) for a in argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and says in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['notes.txt', 'table.parquet']
    assert (tmp_path / 'notes.txt').read_text() == 'keep me'
    assert table.read_bytes() == b'PAR1 not really'
