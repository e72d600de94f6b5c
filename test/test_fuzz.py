"""
Hypothesis over every entry point that takes input: the node's callbacks and the bag reader.

The node runs in this process (its timers never fire: nothing spins it), and each drawn
message goes straight into its callback, not through the guard that would catch what
escapes. Asserted after every message:
- no exception left the callback, and the guard counted no internal error;
- what was published is finite: every wrench decoded by rclpy's own deserialiser;
- a layout is in force exactly when the text was a valid layout (judged by
  layout_from_text, the commands' reader); otherwise the previous one, its digest
  unchanged, and the refusal is one short line;
- the diagnostics built after it are one status of short values.
For bags: bytes changed, overwritten, inserted and cut out, by hypothesis, in the
project's own bag, a bag of the ``mcap`` library and a rosbags rosbag2 directory, then
replayed in full: a one-line BagError, or a replay whose figures are finite.

``CVC_FUZZ_EXAMPLES`` sets the examples per test (default 150: CI stays within a minute);
``./dev.sh run python benchmarks/fuzz.py`` is the longer run.
"""

from collections import Counter
import math
from pathlib import Path
import shutil
from unittest import mock

from geometry_msgs.msg import WrenchStamped
from hypothesis import given, HealthCheck, settings, strategies as st
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
import yaml

from cvc_balance.bag.mcap_reader import BagError
from cvc_balance.bag.replay import replay
from cvc_balance.bag.scenario import load_scenario, write_bag
from cvc_balance.physics import assessment
from cvc_balance.physics.layout import LayoutError
from cvc_balance.physics.layout_file import layout_from_text
from cvc_balance.ros.balance_monitor import BalanceMonitor
from fuzzing import fuzz_examples
from ros_harness import DOMAIN_ID
from test_balance_monitor import LAYOUT_A, LAYOUT_B

EXAMPLES = fuzz_examples(150)
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=EXAMPLES <= 150,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
ROOT = Path(__file__).resolve().parents[1]
MAX_LINE = 300
OUTCOMES = Counter()
"""What the drawn inputs came to, per test: the fuzzing must reach both sides."""
JOINT = 'gantry_joint'


class Captured:
    """Everything the node publishes: (topic, message or CDR bytes)."""

    def __init__(self):
        """Start empty."""
        self.messages = []

    def publish(self, publisher, msg):
        """Publisher.publish in the test: keep the message."""
        self.messages.append((publisher.topic_name, msg))


@pytest.fixture(scope='module')
def node(tmp_path_factory):
    folder = tmp_path_factory.mktemp('fuzz_node')
    layout_file = folder / 'layout.yaml'
    layout_file.write_text(yaml.safe_dump(LAYOUT_A))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    captured = Captured()
    with mock.patch.object(Publisher, 'publish', lambda self, msg: captured.publish(self, msg)):
        monitor = BalanceMonitor(context=context, parameter_overrides=[
            Parameter('layout_file', value=str(layout_file)),
            Parameter('joint_name', value='spin'), Parameter('stator_frame', value='base')])
        monitor.captured = captured
        monitor.clock_s = 1.0          # the drawn samples' time line, advanced as they come
        yield monitor
        monitor.destroy_node()
    rclpy.try_shutdown(context=context)


def check_after(node, digest_before=None):
    """Assert what must hold after every message; return the digest in force."""
    assert node._internal_errors == 0, node._last_rejection
    for topic, msg in node.captured.messages:
        if isinstance(msg, bytes):
            wrench = deserialize_message(msg, WrenchStamped)
            values = [getattr(getattr(wrench.wrench, part), axis) for part in
                      ('force', 'torque') for axis in 'xyz']
            assert all(math.isfinite(v) for v in values), (topic, values)
            assert wrench.header.frame_id in (node.params['stator_frame'],
                                              node.params['rotor_frame']), topic
    node.captured.messages.clear()
    node._publish_diagnostics()
    (array,) = [msg for topic, msg in node.captured.messages if topic == '/diagnostics']
    for status in array.status:
        assert '\n' not in status.message and len(status.message) <= 2 * MAX_LINE
        assert all(len(v.value) <= MAX_LINE for v in status.values), status.values
    node.captured.messages.clear()
    return node._active.digest


TIMES = st.sampled_from([1e-3, 1e-3, 1e-3, 0.0, -1e-3, 0.5, 2.0, 1e9, -1e9])
FLOATS = st.floats(-50.0, 50.0) | st.floats() | st.sampled_from([0.0, math.nan, math.inf])


@st.composite
def joint_state_fields(draw):
    """Draw a JointState's fields: a plausible sample of joint 'spin', or a mistaken one."""
    return {'dt': draw(TIMES),
            'sec': draw(st.none() | st.integers(-2**31, 2**31 - 1)),
            'nanosec': draw(st.none() | st.integers(0, 2**32 - 1)),
            'name': draw(st.lists(st.sampled_from(['spin', 'other', '']) | st.text(max_size=5),
                                  max_size=3)),
            'position': draw(st.lists(FLOATS, max_size=4)),
            'velocity': draw(st.lists(FLOATS, max_size=4)),
            'effort': draw(st.lists(FLOATS, max_size=2))}


def joint_state(node, fields):
    """Return the JointState of ``fields`` (CDR bytes), on the node's time line unless stamped."""
    node.clock_s = min(max(node.clock_s + fields['dt'], 0.0), 2.0e9)
    whole = math.floor(node.clock_s)
    msg = JointState(name=fields['name'], position=fields['position'],
                     velocity=fields['velocity'], effort=fields['effort'])
    msg.header.stamp.sec = int(whole) if fields['sec'] is None else fields['sec']
    msg.header.stamp.nanosec = (int((node.clock_s - whole) * 1e9) if fields['nanosec'] is None
                                else fields['nanosec'])
    return serialize_message(msg)


@FUZZ
@given(st.data())
def test_any_joint_state_or_speed_is_taken_or_refused(node, data):
    digest = check_after(node)
    counts = dict(node._counts)
    for _ in range(data.draw(st.integers(1, 20))):
        if data.draw(st.booleans()):
            node._on_joint_states(joint_state(node, data.draw(joint_state_fields())))
        else:
            node._on_speed(serialize_message(Float64(data=data.draw(FLOATS))))
    assert check_after(node) == digest
    for name in ('accepted', 'rejected'):
        OUTCOMES['samples', name] += node._counts[name] - counts[name]


TEXTS = (st.sampled_from([yaml.safe_dump(LAYOUT_A), yaml.safe_dump(LAYOUT_B)])
         .flatmap(lambda text: st.tuples(st.just(text), st.integers(0, len(text)),
                                         st.integers(0, 8), st.text(max_size=8)))
         .map(lambda cut: cut[0][:cut[1]] + cut[3] + cut[0][cut[1] + cut[2]:])
         | st.text(max_size=300))


@FUZZ
@given(st.data())
def test_any_layout_text_is_put_in_force_or_refused(node, data):
    before = check_after(node)
    text = data.draw(TEXTS | st.sampled_from([yaml.safe_dump(LAYOUT_A),
                                              yaml.safe_dump(LAYOUT_B)]))
    try:
        expected = layout_from_text(text, source='layout topic').digest()
    except LayoutError:
        expected = None
    node._layout_error = ''
    node._on_layout(String(data=text))
    node._preparing.result(timeout=30)
    node._take_prepared()
    after = check_after(node)
    OUTCOMES['layout', 'refused' if expected is None else 'in force'] += 1
    if expected is None:
        assert after == before
        assert node._layout_error and '\n' not in node._layout_error
        assert len(node._layout_error) <= MAX_LINE
    else:
        assert after == expected and not node._layout_error
    # And the node still computes: one good sample after it is answered.
    node.clock_s += 1e-3
    whole = math.floor(node.clock_s)
    msg = JointState(name=['spin'], position=[0.5], velocity=[3.0])
    msg.header.stamp.sec, msg.header.stamp.nanosec = whole, int((node.clock_s - whole) * 1e9)
    accepted = node._counts['accepted']
    node._on_joint_states(serialize_message(msg))
    wrenches = [m for _, m in node.captured.messages if isinstance(m, bytes)]
    if node._counts['accepted'] == accepted + 1:
        assert len(wrenches) >= 3 + len(node._active.supports)
    check_after(node)


@FUZZ
@given(st.data())
def test_any_load_cell_reading_is_taken_or_dropped(node, data):
    check_after(node)
    cells = node._active.cells
    readings, dropped = sum(cells.readings.values()), cells.fit.dropped
    for _ in range(data.draw(st.integers(1, 20))):
        if data.draw(st.booleans()):                     # a plausible motion sample
            node._on_joint_states(joint_state(node, {
                'dt': 1e-3, 'sec': None, 'nanosec': None, 'name': ['spin'],
                'position': [data.draw(st.floats(-7.0, 7.0))],
                'velocity': [data.draw(st.floats(-30.0, 30.0))], 'effort': []}))
        msg = WrenchStamped()
        stamp = node.clock_s + data.draw(st.floats(-0.05, 0.05))
        msg.header.stamp.sec = data.draw(st.just(int(stamp)) | st.integers(0, 2**31 - 1))
        msg.header.stamp.nanosec = data.draw(st.just(int(stamp % 1.0 * 1e9))
                                             | st.integers(0, 10**9 - 1))
        for part in (msg.wrench.force, msg.wrench.torque):
            part.x, part.y, part.z = (data.draw(FLOATS) for _ in range(3))
        cells._on_reading(data.draw(st.sampled_from(list(cells.readings))),
                          serialize_message(msg))
        if data.draw(st.booleans()):
            node._on_joint_states(joint_state(node, data.draw(joint_state_fields())))
    check_after(node)
    if cells is node._active.cells:
        OUTCOMES['cells', 'taken'] += sum(cells.readings.values()) - readings
        OUTCOMES['cells', 'dropped'] += cells.fit.dropped - dropped


def test_the_load_cells_verdict_may_change_level_any_way(node):
    # Found by the fuzzing above: the node logged each change of the cells' verdict from
    # one line of code at the verdict's severity, and rclpy's logger raises ValueError
    # when one line logs at a second severity: the diagnostics of that period were lost.
    check_after(node)
    levels = [assessment.WARN, assessment.ERROR, assessment.OK, assessment.ERROR,
              assessment.NOT_JUDGED, assessment.WARN, assessment.OK]
    published = []
    with mock.patch.object(type(node._active.cells), 'diagnose',
                           side_effect=[(level, f'cells {level}', {}) for level in levels]):
        for _ in levels:
            node._publish_diagnostics()
            published += [msg for topic, msg in node.captured.messages
                          if topic == '/diagnostics']
            node.captured.messages.clear()
    assert node._internal_errors == 0
    messages = [status.message for array in published for status in array.status
                if status.name.endswith('measured unbalance')]
    assert messages == [f'cells {level}' for level in levels]


def test_every_kind_of_trouble_is_logged_without_raising(node):
    # Found on review: the throttled log was one line of code for a rejected sample
    # (WARN) and for an internal error (ERROR), so rclpy's logger raised ValueError on
    # the second severity, out of the guard itself: the first bug after a bad sample
    # would have ended the node.
    def failing(msg):
        raise KeyError('a bug the checks missed')
    for _ in range(2):                       # each kind twice, in both orders
        node._last_logged.clear()            # past the throttle: every call logs
        node._reject('a bad sample')
        node._guarded(failing)(None)
        node.lost_message(RuntimeError('not convertible'))
        node._last_logged.clear()
        node.lost_message(RuntimeError('not convertible'))
        node._guarded(failing)(None)
        node._reject('a bad sample')
    assert node._internal_errors == 8        # 4 bugs caught by the guard, 4 lost messages
    assert node._last_rejection == 'a bad sample'
    node._internal_errors = 0              # the other tests count from here


# -- bags -------------------------------------------------------------------------------


@pytest.fixture(scope='module')
def bag_sources(tmp_path_factory):
    """Bytes of a small own bag, one of the mcap library, and a rosbags rosbag2 folder."""
    from rosbags.rosbag2 import StoragePlugin
    from test_foreign_bags import make_run, Run, write_mcap, write_rosbag2
    folder = tmp_path_factory.mktemp('fuzz_bags')
    full = make_run(names=('a', 'gantry_joint'))
    run = Run(full.stamps[:200], full.angle[:200], full.omega[:200],
              [e for e in full.events if e[0] <= full.stamps[199]])
    write_mcap(folder / 'library.mcap', run, chunk_size=2048)
    write_rosbag2(folder / 'rosbag2', run.events, StoragePlugin.MCAP)
    # The bundled tube-swap scenario in 1.6 s (782 samples, 2 layouts, 10 chunks as the bag
    # has): what the project writes, at a sixth of the 10 s bag's replay per example.
    scenario = yaml.safe_load((ROOT / 'bags' / 'spin_up_tube_swap.yaml').read_text())
    scenario.update(layout=str(ROOT / 'config' / 'ct_gantry.yaml'),
                    profile=[{'type': 'spin_up', 'to': 23.27, 'alpha': 40.0},
                             {'type': 'steady', 'duration': 0.4},
                             {'type': 'coast_down', 'to': 0.0, 'alpha': -40.0}],
                    events=[dict(scenario['events'][0], at=0.8)])
    (folder / 'own.yaml').write_text(yaml.safe_dump(scenario))
    write_bag(load_scenario(folder / 'own.yaml'), folder / 'own.mcap', chunk_bytes=10000)
    (rosbag2_file,) = sorted((folder / 'rosbag2').glob('*.mcap'))
    return {'own': (folder / 'own.mcap').read_bytes(),
            'library': (folder / 'library.mcap').read_bytes(),
            'rosbag2': (folder / 'rosbag2', rosbag2_file.name, rosbag2_file.read_bytes())}


@st.composite
def damage(draw, size):
    """Draw (kind, offset, bytes or length) changes for a file of ``size`` bytes."""
    changes = []
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(['set', 'overwrite', 'insert', 'delete', 'truncate']))
        offset = draw(st.integers(0, max(size - 1, 0)))
        changes.append((kind, offset, draw(st.binary(min_size=1, max_size=16))
                        if kind in ('set', 'overwrite', 'insert')
                        else draw(st.integers(1, 64))))
    return changes


def damaged(data, changes):
    """Return ``data`` with ``changes`` applied."""
    data = bytearray(data)
    for kind, offset, value in changes:
        offset = min(offset, len(data))
        if kind == 'set':
            data[offset:offset + 1] = value[:1]
        elif kind == 'overwrite':
            data[offset:offset + len(value)] = value
        elif kind == 'insert':
            data[offset:offset] = value
        elif kind == 'delete':
            del data[offset:offset + value]
        else:
            del data[offset:]
    return bytes(data)


def replayed_or_refused(path, tmp_path):
    """
    Replay ``path`` in full: 'refused' (one-line BagError) or 'read'.

    Read: the summary's figures finite, and every wrench of the output bag too (read by
    the ``mcap`` library with CRCs checked, decoded by rosbags).
    """
    from mcap.reader import make_reader
    from test_foreign_bags import STORE
    output = tmp_path / 'out.mcap'
    try:
        summary = replay(path, output, joint_name=JOINT)
    except BagError as error:
        assert '\n' not in str(error) and len(str(error)) <= 2 * MAX_LINE
        return 'refused'
    for segment in summary.segments:
        assert math.isfinite(segment.peak_total)
    with open(output, 'rb') as stream:
        for schema, channel, message in make_reader(stream, validate_crcs=True) \
                .iter_messages():
            if schema.name == 'geometry_msgs/msg/WrenchStamped':
                wrench = STORE.deserialize_cdr(message.data, schema.name).wrench
                values = [wrench.force.x, wrench.force.y, wrench.force.z, wrench.torque.x,
                          wrench.torque.y, wrench.torque.z]
                assert all(map(math.isfinite, values)), (channel.topic, values)
    return 'read'


@FUZZ
@given(st.data())
def test_any_damaged_bag_replays_or_is_refused_in_one_line(bag_sources, tmp_path_factory,
                                                           data):
    kind = data.draw(st.sampled_from(['own', 'library', 'rosbag2']))
    folder = tmp_path_factory.mktemp('damaged')
    if kind == 'rosbag2':
        source, name, content = bag_sources['rosbag2']
        path = folder / 'rosbag2'
        shutil.copytree(source, path)
        (path / name).write_bytes(damaged(content, data.draw(damage(len(content)))))
    else:
        content = bag_sources[kind]
        path = folder / f'{kind}.mcap'
        path.write_bytes(damaged(content, data.draw(damage(len(content)))))
    OUTCOMES['bags', replayed_or_refused(path, folder)] += 1
    shutil.rmtree(folder)


def test_the_fuzzing_reached_both_sides_of_every_entry_point():
    # Run after the fuzz tests above (pytest keeps the file's order); alone, nothing to see.
    if not OUTCOMES:
        pytest.skip('run with the fuzz tests above')
    print(dict(OUTCOMES))
    for entry, sides in (('samples', ('accepted', 'rejected')),
                         ('layout', ('in force', 'refused')),
                         ('cells', ('taken', 'dropped')), ('bags', ('read', 'refused'))):
        for side in sides:
            assert OUTCOMES[entry, side] >= 5, (entry, side, dict(OUTCOMES))
