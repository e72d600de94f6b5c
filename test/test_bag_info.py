"""
``cvc-balance info BAG``: ros2 bag info's lines, the machine id and the layouts.

Every figure is checked against the ``mcap`` library's reading of the same file (counts,
first and last log times, the layout messages) and the scenario's own layouts; the dates
are written here with ``datetime`` in UTC (the command runs with TZ=UTC, as ros2 bag info
writes local time).
"""

from datetime import datetime, timezone
import json
import os
from pathlib import Path
import subprocess
import sys

from mcap.stream_reader import StreamReader
from mcap.records import Channel, Message
from mcap.writer import Writer
import pytest
import yaml

from cvc_balance.bag.scenario import load_scenario
from cvc_balance.physics.layout import parse_layout

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / 'bags' / 'spin_up_tube_swap.yaml'
MACHINE = 'site-a/gantry-17'


def info(*args):
    """Run cvc-balance info with TZ=UTC; return (exit code, stdout, stderr)."""
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'info', *map(str, args)],
                         capture_output=True, text=True, env={**os.environ, 'TZ': 'UTC'})
    return run.returncode, run.stdout, run.stderr


def when(ns):
    """Write ``ns`` as ros2 bag info writes a time, in UTC, here with datetime."""
    moment = datetime.fromtimestamp(ns // 10**9, tz=timezone.utc)
    return (f'{moment:%b} {moment.day:2d} {moment.year} {moment:%H:%M:%S}.{ns % 10**9:09d} '
            f'({ns // 10**9}.{ns % 10**9:09d})')


def library_reading(files):
    """{topic: (type, [log times])} and the layout texts, by the mcap library's stream reader."""
    topics, layouts, schemas, channels = {}, [], {}, {}
    for file in files:
        with open(file, 'rb') as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if type(record).__name__ == 'Schema':
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Message):
                        channel = channels[record.channel_id]
                        entry = topics.setdefault(channel.topic,
                                                  (schemas[channel.schema_id], []))
                        entry[1].append(record.log_time)
                        if channel.topic == '/layout':
                            length = int.from_bytes(record.data[4:8], 'little')
                            layouts.append((record.log_time,
                                            record.data[8:8 + length - 1].decode()))
            except Exception:     # a cut file: what was read before the tear
                pass
    return topics, layouts


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Simulate the tube-swap scenario with a machine id, as a file and as a directory."""
    base = tmp_path_factory.mktemp('info')
    for name in ('run.mcap', 'run'):
        run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'simulate', SCENARIO,
                              '-o', base / name, '--machine-id', MACHINE],
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
    return base


@pytest.mark.parametrize('name', ['run.mcap', 'run'])
def test_info_prints_what_ros2_bag_info_prints(bags, name):
    path = bags / name
    files = [path] if path.is_file() else [path / 'run_0.mcap']
    topics, layout_texts = library_reading(files)
    start = min(t for _, times in topics.values() for t in times)
    end = max(t for _, times in topics.values() for t in times)
    size = sum(f.stat().st_size for f in files)
    code, out, err = info(path)
    assert code == 0, err
    pad = ' ' * 19
    described = [f'Topic: {topic} | Type: {kind} | Count: {len(times)} | '
                 'Serialization Format: cdr' for topic, (kind, times) in topics.items()]
    scenario = load_scenario(SCENARIO)
    digests = [parse_layout(mapping).digest() for _, mapping in scenario.layouts]
    assert [yaml.safe_load(text) for _, text in layout_texts] == \
        [mapping for _, mapping in scenario.layouts]
    layouts = [f'ct_gantry_demo {digest} from {t // 10**9}.{t % 10**9:09d}'
               for digest, (t, _) in zip(digests, layout_texts)]
    assert out.splitlines() == [
        '',
        f'Files:             {files[0].name}',
        f'Bag size:          {size / 1024:.1f} KiB',
        'Storage id:        mcap',
        'ROS Distro:        jazzy',
        f'Duration:          {(end - start) // 10**9}.{(end - start) % 10**9:09d}s',
        f'Start:             {when(start)}',
        f'End:               {when(end)}',
        f'Messages:          {sum(len(times) for _, times in topics.values())}',
        'Topic information: ' + described[0], *[pad + line for line in described[1:]],
        'Service:           0',
        'Service information: ',
        f'Machine id:        {MACHINE}',
        'Run:               not labelled',
        'Layouts:           ' + layouts[0], *[pad + line for line in layouts[1:]]]
    assert len(layouts) == 2 and digests[0] != digests[1]     # the tube swap
    assert topics['/joint_states'][0] == 'sensor_msgs/msg/JointState'
    assert len(topics['/joint_states'][1]) == len(scenario.stamps_ns())


def test_info_json_gives_the_same_figures(bags):
    topics, layout_texts = library_reading([bags / 'run.mcap'])
    code, out, err = info(bags / 'run.mcap', '--json')
    assert code == 0, err
    found = json.loads(out)
    times = [t for _, stamps in topics.values() for t in stamps]
    assert (found['start_ns'], found['end_ns'], found['duration_ns']) == \
        (min(times), max(times), max(times) - min(times))
    assert found['message_count'] == len(times)
    assert found['topics'] == [{'name': topic, 'type': kind, 'count': len(stamps),
                                'serialization_format': 'cdr'}
                               for topic, (kind, stamps) in topics.items()]
    assert (found['machine_id'], found['ros_distro'], found['storage_identifier']) == \
        (MACHINE, 'jazzy', 'mcap')
    assert [(layout['log_time_ns'], layout['name']) for layout in found['layouts']] == \
        [(t, 'ct_gantry_demo') for t, _ in layout_texts]
    assert found['files'] == ['run.mcap'] and found['problems'] == []
    assert found['bag_size'] == (bags / 'run.mcap').stat().st_size


def test_info_of_a_cut_recording_and_of_a_foreign_bag(bags, tmp_path):
    """A killed recording: what can be read, its problem said. No rosbag2 record: unknown."""
    cut = tmp_path / 'cut.mcap'
    data = (bags / 'run.mcap').read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    topics, _ = library_reading([cut])
    code, out, err = info(cut, '--json')
    assert code == 0, err
    found = json.loads(out)
    assert {t['name']: t['count'] for t in found['topics']} == \
        {topic: len(stamps) for topic, (_, stamps) in topics.items()}
    assert 0 < found['message_count'] < 9000 and found['problems']
    assert found['machine_id'] == MACHINE                   # its record is at the start
    foreign = tmp_path / 'foreign.mcap'
    with open(foreign, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data\n')
        channel = writer.register_channel('/note', 'cdr', schema)
        writer.add_message(channel, 5 * 10**9, b'\x00\x01\x00\x00\x03\x00\x00\x00hi\x00', 0)
        writer.finish()
    code, out, err = info(foreign)
    assert code == 0, err
    assert 'ROS Distro:        unknown' in out.splitlines()
    assert 'Topic information: Topic: /note | Type: std_msgs/msg/String | Count: 1 | ' \
        'Serialization Format: cdr' in out.splitlines()
    assert f'Start:             {when(5 * 10**9)}' in out.splitlines()
    assert 'Machine id:        none' in out.splitlines()
    assert 'Layouts:           none' in out.splitlines()


def test_info_of_what_is_not_a_bag_is_one_line(tmp_path):
    (tmp_path / 'notes.txt').write_text('not a bag')
    for path in (tmp_path / 'missing.mcap', tmp_path / 'notes.txt', tmp_path):
        code, out, err = info(path)
        assert code == 2 and out == '', path
        assert len(err.splitlines()) == 1 and err.startswith(f'cvc-balance: error: {path}: ')


def test_info_of_rosbag2s_own_bag_as_rosbag2s_own_test_expects():
    """
    rosbag2's file (test/data/rosbag2), against rosbag2's end-to-end test of ros2 bag info.

    Its expectations (rosbag2_tests/test_rosbag2_info_end_to_end.cpp, branch jazzy): the
    regular expression below, and two services; service events are counted apart.
    """
    import re
    path = ROOT / 'test' / 'data' / 'rosbag2' / 'bag_with_topics_and_service_events.mcap'
    code, out, err = info(path)
    assert code == 0, err
    assert re.search(
        '\nFiles:             bag_with_topics_and_service_events.mcap'
        '\nBag size:          .*B'
        '\nStorage id:        mcap'
        '\nROS Distro:        unknown'
        '\nDuration:          0\\.0706.*s'
        '\nStart:             Nov  7 2023 .*:30:36\\..* \\(1699345836\\..*\\)'
        '\nEnd:               Nov  7 2023 .*:30:36\\..* \\(1699345836\\..*\\)'
        '\nMessages:          2'
        '\nTopic information: ', out), out
    assert 'Service:           2\n' in out
    lines = out.splitlines()
    assert 'Service information: Service: /test_service2 | Type: test_msgs/srv/BasicTypes | ' \
        'Event Count: 4 | Serialization Format: cdr' in lines
    assert ' ' * 21 + 'Service: /test_service1 | Type: test_msgs/srv/BasicTypes | ' \
        'Event Count: 4 | Serialization Format: cdr' in lines
    assert ' ' * 19 + 'Topic: /events/write_split | Type: rosbag2_interfaces/msg/' \
        'WriteSplitEvent | Count: 0 | Serialization Format: cdr' in lines
