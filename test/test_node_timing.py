"""
The live node's timing under floods and big layouts, each test with no other beside it.

Every test here is marked alone (test/alone_tests.txt): under ``./dev.sh test``'s workers
it runs with no other test beside it, after all the others (conftest.py), because what it
measures (samples answered at 1-5 kHz, a node's memory over a flood, messages that must
come within a parse's 2 s, a tach stamped on receipt) changes when another test loads the
two cores. A test waiting for that lock in the middle of a run waited 60-137 s while the
other workers took test after test. The hostile layouts and stamps themselves, which need
no such care, are in test/test_node_hostile.py.
"""

import json
import math
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String
import pytest
import yaml

from cvc_balance.bag.replay import replay
from cvc_balance.physics.layout import parse_layout
from ros_harness import Probe
import tach_bags
from test_balance_monitor import (joint_state, LAYOUT_A, start_node, wait_for_diagnostics,
                                  wait_until_connected)
from test_node_hostile import big_layout, ROOT
from test_tach_live import bearing_loads, play_into_the_node


def test_a_big_layout_is_swapped_in_without_losing_samples(tmp_path):
    # 10^5 components: parsed and aggregated on the node's layout thread while 1 kHz samples
    # keep coming; every sample is answered (with the old layout, then the new one) but for
    # what best-effort delivery loses on a starved machine (at most 0.5 %).
    node = start_node(tmp_path, LAYOUT_A)
    probe = Probe('swap_probe')
    outputs = probe.record(WrenchStamped, 'bearing_load', depth=100_000)
    probe.record(DiagnosticArray, '/diagnostics')
    try:
        layout_pub = probe.publisher(String, 'layout', latched=True)
        joints = probe.publisher(JointState, 'joint_states', sensor=True)
        wait_until_connected(probe, node, 'joint_states', 'layout')
        big = big_layout(100_000)
        expected_mass = parse_layout(json.loads(big)) and sum(1.0 + i % 5 for i in range(100_000))
        ns, sent = 20_000_000_000, 0
        layout_pub.publish(String(data=big))
        start = time.monotonic()
        for k in range(3000):            # 3 s at 1 kHz, spun as they go
            ns += 1_000_000
            joints.publish(joint_state(ns, 0.001 * k, 10.0))
            sent += 1
            # Paced by the clock: spin_for(0.001) took ~6 ms a round (170 Hz, 18 s).
            while (left := start + (k + 1) * 0.001 - time.monotonic()) > 0:
                probe.executor.spin_once(timeout_sec=left)
        paced = time.monotonic() - start
        # Best-effort samples: on an idle machine all 3000 are answered; with the machine's
        # two cores taken by two mutation runs beside the suite, 2999 once. A parse that
        # held the executor would lose hundreds (it lost 183-750 with an input depth of 200).
        # Waited for until all have come, or none for 2 s (a lost one never comes).
        heard = [len(outputs), time.monotonic()]

        def all_or_quiet():
            if len(outputs) != heard[0]:
                heard[:] = [len(outputs), time.monotonic()]
            return len(outputs) >= sent or time.monotonic() - heard[1] > 2.0
        probe.spin_until(all_or_quiet, 20.0)
        assert len(outputs) >= sent - 15, (len(outputs), sent)
        assert paced < 4.0, f'3000 samples took {paced:.1f} s'
        assert wait_for_diagnostics(probe, lambda s, v: v.get('layout') == 'big_100000', 30.0)
        log = node.log()
        assert f'{expected_mass:.3f} kg' in log
        assert len({o.header.stamp.nanosec + o.header.stamp.sec * 10**9 for o in outputs}) == \
            len(outputs)                                        # each answered once
        assert not math.isnan(outputs[-1].wrench.force.x)
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0


def rss_mb(pid):
    """Resident memory of process ``pid``, MB."""
    with open(f'/proc/{pid}/status') as status:
        for line in status:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    return math.nan


def test_rejected_samples_neither_flood_the_log_nor_grow_the_node(tmp_path):
    # 20,000 NaN samples as fast as the probe sends them (~5 kHz, 4 s). rclpy's own log
    # throttle walked the caller's frames on every call: the node grew 78 -> 88 MB in 30 s
    # at 5 kHz (0.3 MB/s) and answered fewer samples; with the node's clock check it grows
    # by 0.01 MB. Bound: 0.5 MB, under half of what 4 s cost before.
    node = start_node(tmp_path, LAYOUT_A)
    probe = Probe('nan_probe')
    try:
        joints = probe.publisher(JointState, 'joint_states', sensor=True)
        wait_until_connected(probe, node, 'joint_states')
        ns = 20_000_000_000

        def burst(count):
            nonlocal ns
            started = time.monotonic()
            for k in range(count):
                ns += 200_000
                joints.publish(joint_state(ns, 0.1, math.nan))
                if k % 50 == 49:
                    probe.spin_for(max(0.0, (k + 1) / 5000 - (time.monotonic() - started)))
        burst(5_000)                                    # warm up: the first allocations
        before = rss_mb(node.process.pid)
        burst(20_000)
        probe.spin_for(1.0)
        grown = rss_mb(node.process.pid) - before
        assert grown < 0.5, f'{grown:.2f} MB'
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
    rejected = [line for line in node.log().splitlines() if 'rejected motion sample' in line]
    assert 1 <= len(rejected) <= 9, len(rejected)       # once a second, not per sample
    import re
    counts = re.search(r'motion samples: (\d+) accepted, (\d+) rejected', node.log())
    assert counts and int(counts[1]) == 0 and 24_500 <= int(counts[2]) <= 25_000, counts


def test_layouts_that_come_during_a_long_parse_wait_and_only_the_newest_is_parsed(tmp_path):
    """
    One layout parsed at a time; of those that come meanwhile, the newest wins.

    A 30,000-component YAML layout (2.4 MB, about 2 s to parse here), then, once the node
    has it, four small ones 20 ms apart while it is parsed: the big one is put in force,
    the first three small ones are dropped unparsed (one log line each, naming their
    size), the fourth follows. Before, every layout queued behind a slow one was parsed
    and put in force in turn (a 36 MB YAML layout took 65 s, and the good layouts behind
    it waited for it all).
    """
    import re
    node = start_node(tmp_path, LAYOUT_A)
    probe = Probe('queue_probe')
    probe.record(DiagnosticArray, '/diagnostics')
    try:
        layout_pub = probe.publisher(String, 'layout', latched=True)
        wait_until_connected(probe, node, 'layout')
        smalls = [yaml.safe_dump(dict(LAYOUT_A, name=f'small_{k}')) for k in range(1, 5)]
        # libyaml's dumper writes the same text in 1.8 s where PyYAML's took 5.2 s, alone.
        big = yaml.dump(json.loads(big_layout(30_000)),
                        Dumper=getattr(yaml, 'CSafeDumper', yaml.SafeDumper))
        layout_pub.publish(String(data=big))
        # Not before the node has it: a latched writer keeps only its last message.
        assert probe.spin_until(lambda: f'layout received on the layout topic ({len(big)} '
                                'characters): parsing' in node.log(), 20.0), node.log()
        for text in smalls:
            probe.spin_for(0.02)
            layout_pub.publish(String(data=text))
        assert wait_for_diagnostics(probe, lambda s, v: v.get('layout') == 'small_4', 30.0), \
            node.log()[-3000:]
    finally:
        probe.close()
    assert node.stop(signal.SIGINT) == 0
    log = node.log()
    assert re.findall(r"layout '(\w+)' \(", log) == ['layout_a', 'big_30000', 'small_4'], log
    assert log.count('(544 characters): waits for the one being parsed') == 4
    dropped = re.findall(r'layout dropped unparsed \((\d+) characters from the layout topic\): '
                         r'a newer one came while another was being parsed; the newest wins',
                         log)
    assert dropped == [str(len(text)) for text in smalls[:3]] == ['544'] * 3


def test_a_load_cell_flood_costs_no_motion_samples():
    """
    16 kHz of load-cell readings (two cells at 8 kHz) beside 1 kHz motion for 3 s.

    The publisher is its own process (benchmarks/cell_flood.py). Reading each message's
    CDR bytes itself instead of rclpy's message objects (20 us a WrenchStamped) the node
    answered 98.4-100 % of the motion samples here and fitted 80-100 % of the readings
    (the lower figures at a load average of 5-6.6 on 2 cores); before, it answered 45-66 %
    (and 96.3 % at 4 kHz on a busier machine, the review's finding). Bounds: 95 % of the
    motion samples, half the readings (the node does read them).
    """
    import re
    import subprocess
    import sys
    run = subprocess.run([sys.executable, str(ROOT / 'benchmarks' / 'cell_flood.py'),
                          '--seconds', '3', '--cell-rate', '8000'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    found = re.search(r'this: motion 1000 Hz, cells 16000 Hz in all: (\d+) of (\d+) motion '
                      r'samples answered .* (\d+) cell readings sent, (\d+) taken by the fit',
                      run.stdout)
    assert found, run.stdout
    answered, sent, cells, taken = map(int, found.groups())
    assert sent >= 2900 and cells >= 16 * sent * 0.95
    assert answered >= 0.95 * sent, run.stdout
    assert taken >= 0.5 * cells, run.stdout


@pytest.fixture(scope='module')
def sampled_tach_run(tmp_path_factory):
    """Write the run of test/tach_bags.py with a sampled tach and its layout; replay it."""
    folder = tmp_path_factory.mktemp('sampled_tach')
    run, _, sampled = tach_bags.write_run(folder, ROOT)
    layout = folder / 'layout.yaml'
    layout.write_text(yaml.safe_dump(run.layouts[0][1]))
    replay(sampled, folder / 'offline.mcap')
    return run, layout, {'float64': sampled}, {'float64': bearing_loads(folder / 'offline.mcap')}


def test_play_a_sampled_tach_bag_into_the_node(sampled_tach_run, tmp_path):
    # Stamped on receipt: a node descheduled by another test sees its marks late.
    play_into_the_node(sampled_tach_run, 'float64', tmp_path)
