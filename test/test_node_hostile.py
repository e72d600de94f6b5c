"""
The live node under hostile and mistaken input: it never dies, never lies, keeps its state.

Each layout message a hostile tester sent used to kill the node (TypeError, IndexError,
ValueError, RecursionError, OverflowError, a ZeroDivisionError in the diagnostics timer),
and since the topic is latched a restarted node died again. One JointState stamped
2147483647 s made every later sample "not after the previous" while /diagnostics said OK.
A 10^5-component layout stalled the input for 1.7 s. Here: every such message is refused
with one short line, the previous layout stays in force (its digest in /diagnostics), the
node keeps publishing and diagnostics stay small. The floods and the big layouts, whose
timing is tested with no other test beside them, are in test/test_node_timing.py.
"""

import json
from pathlib import Path
import signal

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String
import yaml

from ros_harness import Probe
from test_balance_monitor import (diagnostic_values, joint_state, LAYOUT_A, start_node,
                                  wait_for_diagnostics, wait_until_connected)

ROOT = Path(__file__).resolve().parents[1]
BOMB = '\n'.join(['a0: &a0 [x, x, x, x, x, x, x, x, x]'] + [
    f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * 9) + ']' for k in range(1, 10)])
HOSTILE_LAYOUTS = {
    'shape type a list': yaml.safe_dump(LAYOUT_A).replace('type: cylinder', 'type: [cylinder]'),
    'empty !!int': yaml.safe_dump(LAYOUT_A).replace('mass: 60.0', 'mass: !!int'),
    '!!float heavy': yaml.safe_dump(LAYOUT_A).replace('mass: 60.0', 'mass: !!float heavy'),
    '10^5 nested lists': '[' * 100_000 + ']' * 100_000,
    '401-digit mass': yaml.safe_dump(LAYOUT_A).replace('mass: 60.0', 'mass: ' + '9' * 401),
    'alias bomb': BOMB,
    '10 MB name': yaml.safe_dump(LAYOUT_A).replace('name: layout_a', 'name: ' + 'x' * 10**7),
    'angle 1e18': yaml.safe_dump(LAYOUT_A).replace('angle_deg: 0.0', 'angle: 1.0e+18'),
    'not UTF-8': b'\x00\x01\x00\x00\x05\x00\x00\x00\xff\xfe\xfd\xfc\x00',   # raw CDR
    'duplicate keys': '{"name": "a", "name": "b"}',
}
ON_AXIS = {'name': 'on_axis', 'components': [{'name': 'hub', 'mass': 10.0, 'radius': 0.0,
                                              'angle': 0.0, 'z': 0.1}],
           'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.25,
                                                       'axial': True}]}


def big_layout(n):
    components = [{'name': f'c{i}', 'mass': 1.0 + i % 5, 'radius': 0.3 + (i % 7) * 0.05,
                   'angle': (i * 2.399963) % 6.283, 'z': (i % 11 - 5) * 0.01}
                  for i in range(n)]
    return json.dumps({'name': f'big_{n}', 'components': components,
                       'supports': LAYOUT_A['supports']})


def test_hostile_layouts_and_stamps_do_not_kill_or_fool_the_node(tmp_path):
    node = start_node(tmp_path, LAYOUT_A, params={'max_stamp_jump': 1.0})
    probe = Probe('hostile_probe')
    outputs = probe.record(WrenchStamped, 'bearing_load')
    probe.record(DiagnosticArray, '/diagnostics')
    try:
        layout_pub = probe.publisher(String, 'layout', latched=True)
        joints = probe.publisher(JointState, 'joint_states', sensor=True)
        wait_until_connected(probe, node, 'joint_states', 'layout')
        assert wait_for_diagnostics(probe, lambda s, v: v.get('layout') == 'layout_a')
        digest = diagnostic_values(probe)[1]['layout digest']
        ns = 10_000_000_000
        for name, text in HOSTILE_LAYOUTS.items():
            layout_pub.publish(text if isinstance(text, bytes) else String(data=text))
            assert wait_for_diagnostics(
                probe, lambda s, v: v.get('last rejected layout', '') not in ('', None)
                and v.get('layout digest') == digest, timeout=20.0), (name, node.log()[-2000:])
            status, values = diagnostic_values(probe)
            assert len(values['last rejected layout']) < 400, name
            # Samples still answered, with the layout in force.
            before = len(outputs)
            for _ in range(5):
                ns += 2_000_000
                joints.publish(joint_state(ns, 0.1, 10.0))
            assert probe.spin_until(lambda: len(outputs) >= before + 5, 5.0), name
            # A good layout clears the error, so that the next one is seen anew.
            layout_pub.publish(String(data=yaml.safe_dump(LAYOUT_A)))
            assert wait_for_diagnostics(probe, lambda s, v: v.get('last rejected layout') == '')
        # All components on the axis: no correction radius, no division by zero.
        layout_pub.publish(String(data=yaml.safe_dump(ON_AXIS)))
        assert wait_for_diagnostics(probe, lambda s, v: v.get('layout') == 'on_axis')
        assert 'none' in diagnostic_values(probe)[1].get('plane I correction mass [g]', 'none')
        layout_pub.publish(String(data=yaml.safe_dump(LAYOUT_A)))
        assert wait_for_diagnostics(probe, lambda s, v: v.get('layout') == 'layout_a')
        # Stamp poisoning: one sample stamped 2147483647 s, then valid ones.
        before = len(outputs)
        joints.publish(joint_state(2147483647 * 1_000_000_000, 0.1, 10.0))
        for _ in range(20):
            ns += 2_000_000
            joints.publish(joint_state(ns, 0.1, 10.0))
        assert probe.spin_until(lambda: len(outputs) >= before + 20, 5.0)
        assert all(o.header.stamp.sec < 2147483647 for o in outputs[before:])
        assert wait_for_diagnostics(probe, lambda s, v: 'jumps' in v['last rejected input'])
        # Every /diagnostics stayed small whatever was thrown at the node.
        sizes = [sum(len(kv.value) + len(kv.key) for s in a.status for kv in s.values)
                 + sum(len(s.message) for s in a.status)
                 for a in probe.received['/diagnostics']]
        assert max(sizes) < 20_000
        assert node.process.poll() is None          # alive
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
