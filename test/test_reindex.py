"""
``cvc-balance reindex``: a killed recording read again by every reader.

A recording killed by SIGKILL or a power cut ends inside a chunk or its message indexes,
with no summary: rosbags and the ``mcap`` library's indexed reader then read nothing.
Cut at many places (inside a chunk, inside its message indexes, right after it), each
file is reindexed and read by the ``mcap`` library (CRCs checked), by rosbags and by this
project's reader: all see the messages the ``mcap`` library's stream reader finds in the
cut file before the tear (an independent count), with the same bytes.
"""

from pathlib import Path
import shutil
import subprocess
import sys

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Message
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as Rosbag2Reader

from cvc_balance.bag.mcap_reader import Bag
from cvc_balance.bag.reindex import reindex

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
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'simulate',
                          ROOT / 'bags' / 'loose_bracket.yaml', '-o', directory],
                         capture_output=True, text=True)
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
