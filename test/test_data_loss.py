"""
Never lose what the user had (issue 24): each finding of the hostile review, reproduced.

Recordings never overwrite a bag (``record -o``, the node's ``record_path``); outputs are
checked before any work (an unwritable folder, one path named twice, a directory where a
file is asked); two ``fleet`` runs on one table keep both runs' rows; a killed command's
staging folder is visible and removed by the next one; a hostile layout message costs
only itself in replay, identify, view and fleet; ``fleet`` never reads a FIFO or a device.
Each case: the figures a person reads (exit code, the one line, the table's rows), and
the user's files byte for byte as they were. The reindex findings are in test_reindex.py.
"""

import hashlib
import json
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest

from cvc_balance.bag.mcap_reader import Bag
from cvc_balance.bag.rosbag2 import open_writer
from cvc_balance.messages.cdr import string_message
from in_process import run_cli
from ros_harness import ros_environment

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / 'bags'
TILTED = BAGS / 'tilted_shift.mcap'
HOSTILE = 'a: &a [*a]'
"""The layout message of issue 24: a YAML alias that holds itself."""


def cli(*args, timeout=60):
    """Run the command line as its own process (ROS environment of this test run)."""
    return subprocess.run([sys.executable, '-m', 'cvc_balance.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=timeout,
                          env=ros_environment())


def digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def one_line(stderr, *needles):
    """Return the single line of ``stderr``, checked to hold each of ``needles``."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in stderr, stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def unwritable(tmp_path):
    """Make a directory no one may write into (immutable for root, mode 555 for others)."""
    folder = tmp_path / 'locked'
    folder.mkdir()
    if os.geteuid() == 0:
        made = subprocess.run(['chattr', '+i', folder], capture_output=True)
        if made.returncode:
            pytest.skip('chattr +i not available here')
    else:
        folder.chmod(0o555)
    try:
        (folder / 'probe').write_text('')
    except OSError:
        pass
    else:
        pytest.skip('no way to make a directory unwritable here')
    yield folder
    if os.geteuid() == 0:
        subprocess.run(['chattr', '-i', folder])
    folder.chmod(0o755)


# -- recordings never overwrite -------------------------------------------------------------

def test_record_refuses_an_existing_bag_a_link_to_one_and_a_bag_directory(
        tmp_path, monkeypatch):
    """
    ``record -o EXISTING.mcap`` truncated the bag at start (197,400 bytes -> 10,407).

    Refused now before ROS starts, in one line, for the bag, a hard link and a symbolic
    link to it, a dangling symbolic link and a rosbag2 directory: nothing changed. (Were
    the recorder started, this test stops it rather than spin for ever.)
    """
    from cvc_balance.ros import recorder

    def started(args):
        raise AssertionError(f'recording started over {args.output}')
    monkeypatch.setattr(recorder, 'record_main', started)
    bag = tmp_path / 'run.mcap'
    shutil.copy(BAGS / 'spin_up_tube_swap.mcap', bag)
    size = bag.stat().st_size
    os.link(bag, tmp_path / 'hard.mcap')
    (tmp_path / 'soft.mcap').symlink_to(bag)
    (tmp_path / 'dangling.mcap').symlink_to(tmp_path / 'nothing.mcap')
    shutil.copytree(BAGS, tmp_path / 'folder')
    before = digest(bag)
    for name in ('run.mcap', 'hard.mcap', 'soft.mcap', 'dangling.mcap', 'folder'):
        code, _, stderr = run_cli('record', '-o', tmp_path / name, '--machine-id', 'gantry-7')
        assert code == 2, (name, stderr)
        one_line(stderr, f'{tmp_path / name}: exists; a recording never replaces it')
    assert digest(bag) == before and bag.stat().st_size == size
    assert not (tmp_path / 'nothing.mcap').exists()
    assert sorted(p.name for p in (tmp_path / 'folder').iterdir()) == \
        sorted(p.name for p in BAGS.iterdir())


def test_a_recording_writer_creates_its_bag_exclusively(tmp_path):
    """What record, play -o and the node open: O_EXCL, never an existing name."""
    from cvc_balance.bag.mcap_reader import BagError
    bag = tmp_path / 'run.mcap'
    shutil.copy(TILTED, bag)
    (tmp_path / 'dangling.mcap').symlink_to(tmp_path / 'nothing.mcap')
    (tmp_path / 'dir').mkdir()
    before = digest(bag)
    for name in ('run.mcap', 'dangling.mcap', 'dir'):
        with pytest.raises(BagError, match='exists; a recording never replaces'):
            open_writer(tmp_path / name, exclusive=True)
    assert digest(bag) == before and not (tmp_path / 'nothing.mcap').exists()
    assert list((tmp_path / 'dir').iterdir()) == []
    writer = open_writer(tmp_path / 'new', exclusive=True)      # a new name: written
    writer.close()
    made = sorted(p.name for p in (tmp_path / 'new').iterdir())
    assert made == ['metadata.yaml', 'new_0.mcap']


def test_the_nodes_record_path_refuses_an_existing_bag(tmp_path):
    """The node's ``record_path:=EXISTING.mcap`` truncated it too: now exit 2, one line."""
    bag = tmp_path / 'run.mcap'
    shutil.copy(BAGS / 'spin_up_tube_swap.mcap', bag)
    os.link(bag, tmp_path / 'hard.mcap')
    before = digest(bag)
    for name in ('run.mcap', 'hard.mcap'):
        node = subprocess.run(
            [sys.executable, '-m', 'cvc_balance.ros.balance_monitor', '--ros-args', '-p',
             f'record_path:={tmp_path / name}'], capture_output=True, text=True, timeout=30,
            env=ros_environment())
        assert node.returncode == 2, node.stderr
        one_line(node.stderr, f'balance_monitor: error: {tmp_path / name}: exists; a '
                 'recording never replaces a file')
    assert digest(bag) == before


# -- outputs checked before any work ----------------------------------------------------------

def test_report_into_an_unwritable_folder_is_refused_before_reading_anything(unwritable,
                                                                             tmp_path):
    """
    ``report -o DIR`` into a folder that cannot be written failed after the work.

    The check comes first now: with coefficients that do not even exist, the refusal
    names the folder (the old order read the inputs first and named them).
    """
    run = run_cli('report', BAGS / 'field_baseline.mcap', '--coefficients',
                  tmp_path / 'missing.yaml', '-o', unwritable)
    assert run[0] == 2
    one_line(run[2], f'{unwritable}: directory cannot be written')


def test_fleet_into_a_read_only_folder_is_refused_before_finding_bags(unwritable, tmp_path):
    out = unwritable / 'fleet.parquet'
    run = run_cli('fleet', tmp_path / 'no_such_folder', '--out', out, '--engine', 'local')
    assert run[0] == 2
    one_line(run[2], f'{out}: folder {unwritable} cannot be written')


def test_replay_refuses_one_path_for_two_outputs(tmp_path):
    """``replay --rrd X -o X`` wrote one output over the other, exit 0."""
    out = tmp_path / 'out.mcap'
    code, stdout, stderr = run_cli('replay', TILTED, '--rrd', out, '-o', out)
    assert code == 2 and stdout == ''
    one_line(stderr, f'{out}: named twice as an output')
    assert sorted(tmp_path.iterdir()) == []


def test_view_and_calibrate_never_put_a_file_in_place_of_a_directory(tmp_path):
    """``view -o EMPTYDIR`` and ``calibrate -o EMPTYDIR`` replaced the directory by a file."""
    folder = tmp_path / 'empty'
    folder.mkdir()
    code, stdout, stderr = run_cli('view', TILTED, '-o', folder)
    assert code == 2 and stdout == ''
    one_line(stderr, f'{folder}: is a directory; give a file name')
    code, stdout, stderr = run_cli(
        'calibrate', *(BAGS / f'field_{r}.mcap' for r in ('baseline', 'trial_I', 'trial_II')),
        '--trial', 'I:0.2@0,0.68', '--trial', 'II:0.2@0,0.68', '-o', folder)
    assert code == 2 and stdout == ''
    one_line(stderr, f'{folder}: is a directory; give a file name')
    assert folder.is_dir() and list(folder.iterdir()) == []
    assert sorted(tmp_path.iterdir()) == [folder]


# -- two fleet runs on one table --------------------------------------------------------------

def test_two_fleet_runs_on_one_table_keep_both_runs_rows(tmp_path, monkeypatch):
    """
    Two ``fleet`` runs on one ``--out``: both said "analysed", the table held the second's.

    Made deterministic: while the first run finds its bags, a second run on other bags
    starts and finishes; the first then writes. Both runs' bags must be in the table.
    """
    from cvc_balance.fleet import engine
    first, second = tmp_path / 'first', tmp_path / 'second'
    first.mkdir()
    second.mkdir()
    shutil.copy(TILTED, first / 'a.mcap')
    shutil.copy(BAGS / 'spin_up_tube_swap.mcap', second / 'b.mcap')
    out = tmp_path / 'fleet.parquet'
    real = engine.find_bags
    reports = []

    def find_while_another_run_writes(paths):
        if not reports:
            monkeypatch.setattr(engine, 'find_bags', real)
            reports.append(engine.run_fleet([second], out, engine='local'))
        return real(paths)
    monkeypatch.setattr(engine, 'find_bags', find_while_another_run_writes)
    reports.append(engine.run_fleet([first], out, engine='local'))
    assert [(r.found, r.analysed, r.failed) for r in reports] == [(1, 1, 0), (1, 1, 0)]
    table = pq.read_table(out).to_pydict()
    assert sorted(set(Path(b).name for b in table['bag'])) == ['a.mcap', 'b.mcap']
    assert len(table['bag']) == reports[0].rows + reports[1].rows
    assert pq.read_table(tmp_path / 'fleet.failures.parquet').num_rows == 0


# -- a killed command's staging folder --------------------------------------------------------

def test_a_killed_replay_leaves_a_visible_folder_the_next_run_removes(tmp_path):
    """Killed ``replay -o`` left hidden ``.NAME.*.partial`` folders (one held 5.7 MB)."""
    out = tmp_path / 'out.mcap'
    replay = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'replay',
                               BAGS / 'loose_bracket.mcap', '-o', out],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    left = []
    while not left and replay.poll() is None and time.monotonic() < deadline:
        left = [p for p in tmp_path.iterdir() if p.name.endswith('.partial')]
        time.sleep(0.001)
    replay.send_signal(signal.SIGKILL)
    replay.wait()
    assert replay.returncode == -signal.SIGKILL and len(left) == 1, left
    staging, = left
    assert re.fullmatch(rf'out\.mcap\.{replay.pid}\.\w{{8}}\.partial', staging.name), \
        staging.name                         # seen by ls, its owner named
    assert not out.exists()
    code, stdout, stderr = run_cli('replay', TILTED, '-o', tmp_path / 'again.mcap')
    assert code == 0, stderr
    assert stderr.strip() == f'removed {staging}, left by a command that was stopped ' \
                             f'(process {replay.pid})'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['again.mcap']


def test_a_staging_folder_of_a_running_command_is_left_alone(tmp_path):
    from cvc_balance.files import stale_staging
    mine = tmp_path / f'out.mcap.{os.getpid()}.abcdefgh.partial'
    gone = tmp_path / 'out.mcap.999999999.abcdefgh.partial'      # no such process
    mine.mkdir()
    gone.mkdir()
    (gone / 'out.mcap').write_bytes(b'half')
    assert stale_staging(tmp_path) == [gone]
    assert sorted(tmp_path.iterdir()) == [mine]


# -- a recorded bad layout costs only itself --------------------------------------------------

def with_layout_message(source, target, log_time, text):
    """Copy bag ``source`` to ``target`` with one more /layout message at ``log_time``."""
    bag = Bag(source)
    writer = open_writer(target)
    messages = []
    layout_channel = None
    for channel in bag.channels.values():
        new = writer.add_channel(channel.topic, channel.msg_type,
                                 latched=channel.topic == '/layout')
        if channel.topic == '/layout':
            layout_channel = new
        messages += [(t, new, data) for t, data in bag.messages(channel)]
    messages.append((log_time, layout_channel, string_message(text)))
    for log_time, channel, data in sorted(messages, key=lambda m: m[0]):
        writer.write(channel, log_time, data)
    writer.close()


LOOSE = BAGS / 'loose_bracket.mcap'
"""Two layouts (at 1 s and 8 s) and load cells: replay, identify, view and fleet all read it."""


@pytest.fixture(scope='module')
def hostile_bag(tmp_path_factory):
    """loose_bracket with the hostile layout between its two good ones (at 3 s)."""
    path = tmp_path_factory.mktemp('hostile') / 'hostile.mcap'
    with_layout_message(LOOSE, path, 3_000_000_000, HOSTILE)
    return path


REJECTED = ('layout at 3.000 s rejected (previous stays in force): layout message: a YAML '
            'alias refers to a node that holds it (a recursive structure): refused')


def test_replay_goes_on_past_a_hostile_layout_message(hostile_bag):
    """It ended in "internal error: KeyError", exit 1; now that message alone is lost."""
    code, stdout, stderr = run_cli('replay', hostile_bag, '--json')
    assert code == 0, stderr
    hostile = json.loads(stdout)
    code, stdout, _ = run_cli('replay', LOOSE, '--json')
    clean = json.loads(stdout)
    assert REJECTED in hostile['problems'] and REJECTED not in clean['problems']
    segments = [(s['layout']['digest'], s['samples']) for s in hostile['segments']]
    assert segments == [(s['layout']['digest'], s['samples']) for s in clean['segments']]
    assert len(segments) == 2 and sum(n for _, n in segments) == clean['accepted'] == 7394
    code, stdout, _ = run_cli('replay', hostile_bag)
    assert f'  problem: {REJECTED}' in stdout.splitlines()


def test_identify_and_view_go_on_past_a_hostile_layout_message(hostile_bag, tmp_path):
    code, stdout, stderr = run_cli('identify', hostile_bag)
    assert code == 0, stderr
    code, clean, _ = run_cli('identify', LOOSE)
    hostile = stdout.replace(str(hostile_bag), str(LOOSE)).splitlines()
    assert f'  problem: {REJECTED}' in hostile        # said, and nothing else changed
    assert [line for line in hostile if REJECTED not in line] == clean.splitlines()
    code, stdout, stderr = run_cli('view', hostile_bag, '-o', tmp_path / 'run.rrd')
    assert code == 0, stderr
    assert stdout.splitlines()[:2] == [
        f'{tmp_path / "run.rrd"}: 7394 samples of {hostile_bag}, 2 layouts',
        f'  problem: {REJECTED}']


def test_fleet_analyses_a_bag_with_a_hostile_layout_message(hostile_bag, tmp_path):
    code, stdout, stderr = run_cli('fleet', hostile_bag, '--out', tmp_path / 'f.parquet',
                                   '--engine', 'local')
    assert code == 0, stderr
    assert stdout.startswith('1 bags found: 1 analysed (2 rows, 7394 samples)')
    assert pq.read_table(tmp_path / 'f.failures.parquet').num_rows == 0


def test_many_hostile_layouts_are_counted_not_listed(tmp_path):
    from cvc_balance.bag.replay import layout_events
    good = (ROOT / 'config' / 'ct_gantry.yaml').read_text()
    messages = [(k * 10**9, HOSTILE) for k in range(8)] + [(9 * 10**9, good)]
    events, problems = layout_events(Bag(TILTED), messages)
    assert [t for t, _ in events] == [9 * 10**9]
    assert len(problems) == 6 and problems[:5] == [
        REJECTED.replace('3.000', f'{k}.000') for k in range(5)]
    assert problems[5] == '8 layout messages rejected in all (the first 5 said above)'


# -- fleet and paths that are no bag files ----------------------------------------------------

def test_fleet_never_reads_a_fifo_or_a_device_and_names_a_broken_link(tmp_path):
    """A FIFO or a link to /dev/zero named *.mcap hung ``fleet DIR`` for ever."""
    folder = tmp_path / 'runs'
    folder.mkdir()
    shutil.copy(TILTED, folder / 'good.mcap')
    os.mkfifo(folder / 'fifo.mcap')
    (folder / 'zero.mcap').symlink_to('/dev/zero')
    (folder / 'broken.mcap').symlink_to(tmp_path / 'gone.mcap')
    run = cli('fleet', folder, '--out', tmp_path / 'f.parquet', '--engine', 'local',
              timeout=60)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0].startswith('4 bags found: 1 analysed (3 rows, 6001 samples)')
    assert lines[0].endswith(', 3 failed')
    assert lines[3:] == [
        f'  {folder / "broken.mcap"}: a symbolic link to {tmp_path / "gone.mcap"}, which does '
        'not exist (a broken link): not read',
        f'  {folder / "fifo.mcap"}: not a regular file (a FIFO): not read',
        f'  {folder / "zero.mcap"}: a symbolic link to /dev/zero, not a regular file (a '
        'character device): not read']
    failures = pq.read_table(tmp_path / 'f.failures.parquet').to_pydict()
    assert sorted(Path(b).name for b in failures['bag']) == \
        ['broken.mcap', 'fifo.mcap', 'zero.mcap']
