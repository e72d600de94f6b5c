"""
``cvc-balance reindex``: a killed recording read again by every reader.

A recording killed by SIGKILL or a power cut ends inside a chunk or its message indexes,
with no summary: rosbags and the ``mcap`` library's indexed reader then read nothing.
Cut at many places (inside a chunk, inside its message indexes, right after it), each
file is reindexed and read by the ``mcap`` library (CRCs checked), by rosbags and by this
project's reader: all see the messages the ``mcap`` library's stream reader finds in the
cut file before the tear (an independent count), with the same bytes.
"""

import itertools
import json
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Message
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as Rosbag2Reader
import yaml

from cvc_balance.bag.mcap_reader import Bag
from cvc_balance.bag.reindex import reindex
from in_process import cvc

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / 'bags' / 'loose_bracket.mcap'


def stream_messages(path):
    """Messages (channel, log time, data) of whole chunks, by mcap's stream reader."""
    found = []
    with open(path, 'rb') as stream:
        try:
            for record in StreamReader(stream, skip_magic=False, emit_chunks=False).records:
                if isinstance(record, Message):
                    found.append((record.channel_id, record.log_time, bytes(record.data)))
        except Exception:          # the tear: everything before it is what a reader can have
            pass
    return found


def chunk_edges(path):
    """Byte offsets where chunks start and end, for cutting inside and around them."""
    edges, position = [], 8
    data = Path(path).read_bytes()
    while position + 9 <= len(data):
        opcode, length = data[position], int.from_bytes(data[position + 1:position + 9], 'little')
        if opcode == 0x06:
            edges.append((position, position + 9 + length))
        if opcode == 0x0F:
            break
        position += 9 + length
    return edges


def cuts(path):
    edges = chunk_edges(path)
    middle = edges[len(edges) // 2]
    return sorted({middle[0] + 100, middle[1], middle[1] + 20, middle[1] + 40,
                   edges[-1][1] + 10, edges[1][0] - 3})


@pytest.mark.parametrize('cut', range(6))
def test_a_cut_recording_is_read_by_every_reader_after_reindex(cut, tmp_path):
    data = SOURCE.read_bytes()
    at = cuts(SOURCE)[cut]
    path = tmp_path / 'killed.mcap'
    path.write_bytes(data[:at])
    expected = stream_messages(path)
    assert expected
    with open(path, 'rb') as stream:       # before: the indexed reader finds no summary
        with pytest.raises(Exception):
            list(make_reader(stream).iter_messages())
    report, = reindex(path)
    assert not report.already_whole and report.messages == len(expected)
    assert path.read_bytes() == data[:at]                 # the bag itself is left as it was
    path = Path(report.output)
    assert path == tmp_path / 'killed.reindexed.mcap'
    with open(path, 'rb') as stream:
        got = [(c.id, m.log_time, bytes(m.data))
               for _, c, m in make_reader(stream, validate_crcs=True).iter_messages(
                   log_time_order=False)]
    assert sorted(got) == sorted(expected)
    with AnyReader([path]) as reader:
        assert sorted((c.topic, t, bytes(raw)) for c, t, raw in reader.messages()) == \
            sorted((next(ch.topic for ch in reader.connections if ch.id == cid), t, raw)
                   for cid, t, raw in expected)
    ours = Bag(path)
    assert not ours.problems
    assert sum(ours.message_count(c) for c in ours.channels.values()) == len(expected)


def test_a_whole_bag_is_left_alone(tmp_path):
    path = tmp_path / 'whole.mcap'
    shutil.copy(SOURCE, path)
    report, = reindex(path)
    assert report.already_whole and report.output == ''
    assert path.read_bytes() == SOURCE.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['whole.mcap']


def test_a_killed_directory_gets_its_metadata_back(tmp_path):
    directory = tmp_path / 'run'
    run = cvc('simulate', ROOT / 'bags' / 'loose_bracket.yaml', '-o', directory)
    assert run.returncode == 0, run.stderr
    inner = directory / 'run_0.mcap'
    data = inner.read_bytes()
    inner.write_bytes(data[:len(data) // 2])
    (directory / 'metadata.yaml').unlink()           # killed before rosbag2 wrote it
    expected = stream_messages(inner)
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'reindex', directory],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert f'{len(expected)} messages' in run.stdout
    assert f'written to {tmp_path / "run.reindexed" / "run_0.mcap"}' in run.stdout
    assert not (directory / 'metadata.yaml').exists()    # the bag itself is left as it was
    with Rosbag2Reader(tmp_path / 'run.reindexed') as reader:    # metadata.yaml, the file
        assert reader.message_count == len(expected)
        assert sum(1 for _ in reader.messages()) == len(expected)


def test_reindex_refuses_what_is_not_a_bag(tmp_path):
    text = tmp_path / 'notes.mcap'
    text.write_text('not a bag')
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'reindex', text],
                         capture_output=True, text=True)
    assert run.returncode == 2 and 'not an MCAP file' in run.stderr
    assert text.read_text() == 'not a bag'


# -- issue 24: a repair never shrinks a bag --------------------------------------------------

BASELINE = ROOT / 'bags' / 'field_baseline.mcap'


def mcap_messages(path):
    """(topic, log time, data) of every message the mcap library's indexed reader gives."""
    with open(path, 'rb') as stream:
        return sorted((c.topic, m.log_time, bytes(m.data)) for _, c, m in
                      make_reader(stream, validate_crcs=True).iter_messages(
                          log_time_order=False))


def rosbags_messages(path):
    with AnyReader([Path(path)]) as reader:
        return sorted((c.topic, t, bytes(raw)) for c, t, raw in reader.messages())


def records(path):
    """[(offset, opcode, length)] of the top-level records before DataEnd."""
    data, position, found = Path(path).read_bytes(), 8, []
    while True:
        opcode = data[position]
        length = int.from_bytes(data[position + 1:position + 9], 'little')
        found.append((position, opcode, length))
        if opcode == 0x0F:
            return found
        position += 9 + length


def flipped(tmp_path, where):
    """Copy the baseline bag with one byte of a record's length field flipped."""
    data = bytearray(BASELINE.read_bytes())
    if where == 'header length':
        at = 8 + 1 + 2           # the header's length field, third byte
    else:
        chunk = [(o, n) for o, op, n in records(BASELINE) if op == 0x06][2]
        # 'up': the length points past the file's end; 'down': inside, at a wrong place;
        # 'opcode': a kind no reader knows, skipped by its (right) length.
        at = chunk[0] + {'chunk length up': 3, 'chunk length down': 1, 'chunk opcode': 0}[where]
    data[at] ^= 0xFF
    path = tmp_path / 'damaged.mcap'
    path.write_bytes(bytes(data))
    return path


@pytest.fixture(scope='module')
def whole():
    """Read the undamaged bag with the mcap library (the figure of issue 24: 10,113)."""
    return mcap_messages(BASELINE)


@pytest.mark.parametrize('where', ['chunk length up', 'chunk length down', 'chunk opcode',
                                   'header length'])
def test_a_flipped_length_byte_costs_no_message(where, whole, tmp_path):
    """
    Issue 24: one byte of a length field flipped; the mcap library still reads all.

    Reindex took the bag for a truncated recording and rewrote it in place from 553,771
    to 30,599 bytes (591 of 10,113 messages; 0 for the header's length). Now the bag is
    left as it is and the result, beside it, holds every message; rosbags, which read
    the header's flip as a torn file, read the result whole too.
    """
    path = flipped(tmp_path, where)
    damaged = path.read_bytes()
    assert len(whole) == 10_113
    assert mcap_messages(path) == whole          # by the summary's indexes
    if where == 'header length':                # rosbags reads the header first: nothing
        with pytest.raises(Exception, match='Truncated record at offset 17'):
            rosbags_messages(path)
    else:
        assert rosbags_messages(path) == whole
    run = cvc('reindex', path)          # in this process; the command's own: above and below
    assert run.returncode == 0, run.stderr
    result = tmp_path / 'damaged.reindexed.mcap'
    assert run.stdout.startswith(f'{path}: 19 chunks, 10113 messages; written to {result}\n')
    assert '\n  problem: ' in run.stdout                # said, not hidden
    assert path.read_bytes() == damaged
    assert mcap_messages(result) == whole and rosbags_messages(result) == whole
    ours = Bag(result)
    assert ours.problems == []
    assert sum(len(ours.messages(c)) for c in ours.channels.values()) == len(whole)


def test_a_repair_keeping_less_than_a_standard_reader_is_refused(whole, tmp_path, monkeypatch):
    """
    Were the reader to stop at the damaged chunk again, reindex must refuse, saying why.

    The reader's recovery is switched off here (the issue's reader): it keeps the 591
    messages before the damaged chunk (mcap's stream reader finds them in the bag cut there).
    """
    from cvc_balance.bag import mcap_reader
    from cvc_balance.bag.reindex import RepairRefused
    monkeypatch.setattr(mcap_reader, '_derived_length', lambda data, offset: None)
    monkeypatch.setattr(mcap_reader.Bag, '_next_whole_record', lambda self, start: None)
    monkeypatch.setattr(mcap_reader.Bag, '_read_indexed', lambda self: None)
    path = flipped(tmp_path, 'chunk length up')
    damaged = path.read_bytes()
    cut = tmp_path / 'before.mcap'
    cut.write_bytes(damaged[:[o for o, op, _ in records(BASELINE) if op == 0x06][2]])
    assert len(stream_messages(cut)) == 591
    cut.unlink()
    with pytest.raises(RepairRefused) as refused:
        reindex(path)
    assert str(refused.value) == (
        f'{path}: not reindexed: the mcap library (CRCs checked) reads 10113 messages of it, '
        'the repair would keep 591 (/joint_states 5618 against 590, /supports/front/'
        'measured_load 2247 against 0, /supports/rear/measured_load 2247 against 0); the bag '
        'is left as it is (read it with that reader, or copy what it reads)')
    assert path.read_bytes() == damaged
    assert sorted(p.name for p in tmp_path.iterdir()) == ['damaged.mcap']


def test_reindex_writes_beside_the_bag_under_a_name_not_taken(tmp_path):
    data = SOURCE.read_bytes()
    path = tmp_path / 'killed.mcap'
    path.write_bytes(data[:len(data) // 2])
    expected = stream_messages(path)
    first, = reindex(path)
    second, = reindex(path)
    assert first.output == str(tmp_path / 'killed.reindexed.mcap')
    assert second.output == str(tmp_path / 'killed.reindexed-2.mcap')
    assert Path(first.output).read_bytes() == Path(second.output).read_bytes()
    assert path.read_bytes() == data[:len(data) // 2]
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'reindex', path,
                          '--in-place'], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert f'written to {path}' in run.stdout
    assert path.read_bytes() == Path(first.output).read_bytes()
    assert len(mcap_messages(path)) == len(expected)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        'killed.mcap', 'killed.reindexed-2.mcap', 'killed.reindexed.mcap']


# -- issue 28: the machine id survives reindex -----------------------------------------------

MACHINE = 'site_a/gantry-0042'


def machine_ids(bag, directory=None):
    """Return the machine id as three readers find it: ours, mcap, rosbags (directory)."""
    from cvc_balance.bag.machine import bag_custom_data, MACHINE_ID
    found = {'ours': bag_custom_data(directory or bag).get(MACHINE_ID)}
    with open(bag, 'rb') as stream:
        records = {m.name: m.metadata for m in
                   make_reader(stream, validate_crcs=True).iter_metadata()}
    found['mcap'] = records.get('cvc_balance', {}).get(MACHINE_ID)
    if directory is not None:
        with Rosbag2Reader(directory) as reader:
            found['rosbags'] = (reader.storage.metadata.custom or {}).get(MACHINE_ID)
    return found


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """Write a run with a machine id, as a file and as a rosbag2 directory."""
    from cvc_balance.bag.scenario import load_scenario, write_bag
    base = tmp_path_factory.mktemp('recorded')
    scenario = load_scenario(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    write_bag(scenario, base / 'run.mcap', machine_id=MACHINE)
    write_bag(scenario, base / 'run', machine_id=MACHINE)
    return base


def test_the_machine_id_survives_reindex_of_files_cut_anywhere(recorded, tmp_path):
    import random
    data = (recorded / 'run.mcap').read_bytes()
    heads = list(itertools.takewhile(lambda r: r[1] != 0x06, records(recorded / 'run.mcap')))
    metadata_end = max(o + 9 + n for o, op, n in heads if op == 0x0C)   # before the 1st chunk
    cuts = sorted(random.Random(28).sample(range(metadata_end, len(data)), 6))
    for at in cuts:
        path = tmp_path / f'cut_{at}.mcap'
        path.write_bytes(data[:at])
        report, = reindex(path)
        assert report.custom_data == {'machine_id': MACHINE}
        assert machine_ids(report.output) == {'ours': MACHINE, 'mcap': MACHINE}, at
        with open(report.output, 'rb') as stream:
            statistics = make_reader(stream).get_summary().statistics
        assert statistics.metadata_count == 2     # rosbag2's first record and ours
    # replay --json gives the id after reindex, as before
    run = cvc('replay', tmp_path / f'cut_{cuts[-1]}.reindexed.mcap', '--json')
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)['machine_id'] == MACHINE


def test_the_machine_id_survives_reindex_of_a_killed_directory(recorded, tmp_path):
    directory = tmp_path / 'run'
    shutil.copytree(recorded / 'run', directory)
    inner = directory / 'run_0.mcap'
    data = inner.read_bytes()
    inner.write_bytes(data[:len(data) * 2 // 3])
    (directory / 'metadata.yaml').unlink()             # killed before it was written
    report, = reindex(directory)
    out = tmp_path / 'run.reindexed'
    assert report.output == str(out / 'run_0.mcap')
    assert machine_ids(out / 'run_0.mcap', out) == \
        {'ours': MACHINE, 'mcap': MACHINE, 'rosbags': MACHINE}
    info = yaml.safe_load((out / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['custom_data'] == {'machine_id': MACHINE}


def test_the_machine_id_survives_reindex_of_recordings_killed_with_sigkill(tmp_path):
    """Three recorders with a machine id, killed with SIGKILL after 0, 0.3 and 0.8 s of data."""
    from sensor_msgs.msg import JointState
    from ros_harness import Probe, ros_environment
    from test_bags import publish_joint_states
    outputs = [tmp_path / 'early.mcap', tmp_path / 'middle.mcap', tmp_path / 'late']
    recorders = [subprocess.Popen(
        [sys.executable, '-m', 'cvc_balance.cli', 'record', '-o', str(path), '--chunk-kib', '4',
         '--machine-id', MACHINE, 'joint_states'], env=ros_environment(),
        stdout=subprocess.DEVNULL) for path in outputs]
    probe = Probe('machine_probe')
    try:
        publisher = probe.publisher(JointState, 'joint_states', sensor=True)
        assert probe.spin_until(lambda: publisher.get_subscription_count() >= 3, timeout=20)
        probe.spin_for(0.5)
        start, sent = time.monotonic(), 0
        for recorder, until in zip(recorders, (0.0, 0.3, 0.8)):
            sent = publish_joint_states(publisher, start, until, sent)
            recorder.send_signal(signal.SIGKILL)
            recorder.wait()
    finally:
        for recorder in recorders:
            recorder.kill()
        probe.close()
    counts = []
    for path in outputs:
        report, = reindex(path)
        counts.append(report.messages)
        if path.suffix == '.mcap':
            assert machine_ids(report.output) == {'ours': MACHINE, 'mcap': MACHINE}
        else:
            out = Path(report.output).parent
            assert machine_ids(report.output, out) == \
                {'ours': MACHINE, 'mcap': MACHINE, 'rosbags': MACHINE}
    assert counts[0] < counts[1] < counts[2] <= sent, (counts, sent)   # three kill points
