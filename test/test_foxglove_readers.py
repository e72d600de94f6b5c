"""
Every kind of bag the project writes, read by Foxglove's TypeScript readers under Node.js.

``test/js/read_bags.js`` runs ``@mcap/core`` (a stream reader walking every record and an
indexed reader going by the summary, both checking CRCs), ``@foxglove/rosmsg`` and
``@foxglove/rosmsg2-serialization`` (every message decoded with the definitions parsed
from the file's own schema text, none leaving bytes over) and ``@foxglove/rosbag2`` (the
channels' offered QoS, metadata.yaml and rosbag2's ``serialized_metadata``). Bags: the
bundled ones, simulated inputs and replay outputs in each compression as files and rosbag2
directories, a split directory and cut files mended by ``reindex``, and live recordings
(finished, and killed with SIGKILL then reindexed). Their counts must equal this project's
reader's, topic by topic. ``./dev.sh test`` installs Node.js and the packages
(``test/js/package-lock.json``); without Node.js the test is skipped, saying why, except
in CI, where it fails.
"""

import json
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

import pytest

from cvc_balance.bag.reindex import reindex
from cvc_balance.bag.rosbag2 import open_bag

ROOT = Path(__file__).resolve().parents[1]
JS = ROOT / 'test' / 'js'
SCENARIO = ROOT / 'bags' / 'tilted_shift.yaml'
RELIABLE, BEST_EFFORT = 1, 2            # rmw's enums, as Foxglove's QosProfile has them
TRANSIENT_LOCAL, VOLATILE = 1, 2
CLI = [sys.executable, '-m', 'cvc_balance.cli']


def unavailable(reason):
    """Skip, saying why, except in CI (which must run this test: .ci/run runs ./dev.sh test)."""
    if os.environ.get('CI'):
        pytest.fail(f'{reason} (CI must run the Foxglove readers: ./dev.sh test installs them)')
    pytest.skip(reason)


@pytest.fixture(scope='module')
def foxglove():
    """Return a function reading paths with read_bags.js: {path: what Foxglove read}."""
    node, npm = shutil.which('node'), shutil.which('npm')
    if node is None or npm is None:
        unavailable('Node.js or npm not installed (./dev.sh test installs nodejs and npm with '
                    'apt-get, as root)')
    version = subprocess.run([node, '--version'], capture_output=True, text=True).stdout
    if int(version.strip().lstrip('v').split('.')[0] or 0) < 20:
        unavailable(f'Node.js {version.strip()}: @foxglove/rosmsg2-serialization 3 needs 20 '
                    'or later')
    lock = JS / 'package-lock.json'
    installed = JS / 'node_modules' / '.package-lock.json'
    if not installed.is_file() or installed.stat().st_mtime < lock.stat().st_mtime:
        run = subprocess.run([npm, 'ci', '--no-audit', '--no-fund'], cwd=JS,
                             capture_output=True, text=True)
        if run.returncode != 0:
            unavailable('npm ci in test/js failed: ' +
                        (run.stderr.strip().splitlines() or ['no message'])[-1])

    def read(*paths):
        run = subprocess.run([node, str(JS / 'read_bags.js'), *map(str, paths)],
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        return json.loads(run.stdout)
    return read


def our_counts(path):
    """{topic: messages} this project's reader reads of a bag (file or directory)."""
    bag = open_bag(path)
    return {c.topic: sum(len(offsets) for _, offsets in bag.message_offsets(c))
            for c in bag.channels.values()}


def assert_read_whole(found, counts, qos=None):
    """Check what Foxglove read of one bag (read_bags.js's entry) against ``counts``."""
    stream, indexed = {}, {}
    for file in found['files']:
        assert file['errors'] == [], file['file']
        assert file['stream']['done'] and file['stream']['trailing'] == 0, file['file']
        assert file['stream']['decoded'] == sum(file['stream']['counts'].values())
        assert file['indexed']['decoded'] == sum(file['indexed']['counts'].values())
        assert file['indexed']['statistics']['channelMessageCounts'] == \
            file['indexed']['counts'], file['file']
        assert file['indexed']['rosbag2']['ros_distro'] == 'jazzy'
        assert {s[1] for s in file['stream']['schemas']} == {'ros2msg'}
        for topic, n in file['stream']['counts'].items():
            stream[topic] = stream.get(topic, 0) + n
        for topic, n in file['indexed']['counts'].items():
            indexed[topic] = indexed.get(topic, 0) + n
        for topic, (reliability, durability) in (qos or {}).items():
            if topic in file['stream']['qos']:
                assert file['stream']['qos'][topic] == [[reliability, durability, True]], topic
    assert stream == indexed == counts
    if 'yaml' in found:         # a rosbag2 directory's metadata.yaml, by Foxglove's YAML
        assert found['yaml']['counts'] == counts
        assert found['yaml']['message_count'] == sum(counts.values())
        assert found['yaml']['relative_file_paths'] == [f['file'] for f in found['files']]
        assert (found['yaml']['version'], found['yaml']['ros_distro']) == (9, 'jazzy')


QOS = {'/layout': (RELIABLE, TRANSIENT_LOCAL), '/joint_states': (BEST_EFFORT, VOLATILE),
       '/bearing_load': (RELIABLE, VOLATILE), '/unbalance': (RELIABLE, VOLATILE),
       '/drive_torque': (RELIABLE, VOLATILE), '/supports/front/load': (RELIABLE, VOLATILE),
       '/supports/front/measured_load': (BEST_EFFORT, VOLATILE)}


def test_bundled_simulated_and_replayed_bags(foxglove, tmp_path):
    """The bundled bags; a simulation and its replay in each compression, files and directories."""
    from cvc_balance.cli import main          # in this process: the bags, not the command
    made = sorted((ROOT / 'bags').glob('*.mcap'))
    for name in ('sim.mcap', 'sim'):
        assert main(['simulate', str(SCENARIO), '-o', str(tmp_path / name),
                     '--machine-id', 'site-a/gantry-17']) == 0
        made.append(tmp_path / name)
    for compression in ('zstd', 'lz4', 'none'):
        for name in (f'out_{compression}.mcap', f'out_{compression}'):
            assert main(['replay', str(tmp_path / 'sim'), '-o', str(tmp_path / name),
                         '--compression', compression]) == 0
            made.append(tmp_path / name)
    found = foxglove(*made)
    samples = 6001                  # tilted_shift: 6 s at 1 kHz, and the first
    for path in made:
        counts = our_counts(path)
        assert_read_whole(found[str(path)], counts, QOS)
        if path.parent == tmp_path:
            assert counts['/layout'] == 3 and samples in counts.values(), path.name
    assert found[str(tmp_path / 'sim')]['yaml']['custom_data'] == \
        {'machine_id': 'site-a/gantry-17'}
    outputs = found[str(tmp_path / 'out_lz4')]['files'][0]['stream']['counts']
    assert outputs['/bearing_load'] == samples and len(outputs) >= 6


def test_split_and_reindexed_bags(foxglove, tmp_path):
    """A killed split recording and cut files, each mended by reindex, then read by Foxglove."""
    whole = tmp_path / 'whole.mcap'
    run = subprocess.run(CLI + ['simulate', ROOT / 'bags' / 'loose_bracket.yaml', '-o', whole],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    data = whole.read_bytes()
    cut_paths = []
    for fraction in (0.3, 0.77):
        cut = tmp_path / f'cut_{int(fraction * 100)}.mcap'
        cut.write_bytes(data[:int(len(data) * fraction)])
        cut_paths.append(cut)
    # A split run killed in its second file: two files, no metadata.yaml.
    split = tmp_path / 'split'
    split.mkdir()
    shutil.copy(whole, split / 'split_0.mcap')
    (split / 'split_1.mcap').write_bytes(data[:len(data) // 2])
    expected = {path: our_counts(path) for path in (*cut_paths, split)}
    mended = []
    for path in (*cut_paths, split):
        reports = reindex(path)
        mended.append(Path(reports[0].output).parent if path.is_dir() else
                      Path(reports[0].output))
    assert [p.name for p in mended] == ['cut_30.reindexed.mcap', 'cut_77.reindexed.mcap',
                                        'split.reindexed']
    found = foxglove(*mended)
    for path, out in zip(expected, mended):
        assert our_counts(out) == expected[path]
        assert_read_whole(found[str(out)], expected[path], QOS)
    assert len(found[str(mended[2])]['files']) == 2
    assert expected[split]['/joint_states'] > our_counts(whole)['/joint_states']


def test_live_recordings_finished_and_killed(foxglove, tmp_path):
    """cvc-balance record: one stopped by SIGINT, one killed by SIGKILL and reindexed."""
    from sensor_msgs.msg import JointState
    from ros_harness import Probe, ros_environment
    from test_bags import publish_joint_states
    outputs = [tmp_path / 'finished.mcap', tmp_path / 'killed.mcap']
    recorders = [subprocess.Popen(
        CLI + ['record', '-o', str(path), '--chunk-kib', '4', 'joint_states'],
        env=ros_environment(), stdout=subprocess.DEVNULL) for path in outputs]
    probe = Probe('foxglove_probe')
    try:
        publisher = probe.publisher(JointState, 'joint_states', sensor=True)
        assert probe.spin_until(lambda: publisher.get_subscription_count() >= 2, timeout=20)
        probe.spin_for(0.5)
        publish_joint_states(publisher, time.monotonic(), 0.6)
        recorders[0].send_signal(signal.SIGINT)
        recorders[1].send_signal(signal.SIGKILL)
        for recorder in recorders:
            recorder.wait(timeout=20)
    finally:
        for recorder in recorders:
            recorder.kill()
        probe.close()
    killed_counts = our_counts(outputs[1])
    report, = reindex(outputs[1])
    found = foxglove(outputs[0], report.output)
    assert_read_whole(found[str(outputs[0])], our_counts(outputs[0]),
                      {'/joint_states': (BEST_EFFORT, VOLATILE)})
    assert_read_whole(found[report.output], killed_counts,
                      {'/joint_states': (BEST_EFFORT, VOLATILE)})
    assert our_counts(outputs[0])['/joint_states'] > 300
