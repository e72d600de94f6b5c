"""
The node identifies the real rotor from its load cells, live, and says when it is not its layout.

bags/loose_bracket.mcap (a 0.3 kg bracket the layout does not list, at R 0.5 m, 130 deg,
z 0.12 m: 150 000 g mm in plane II; after 7 s a tube 0.6 kg heavier than declared) is
played into the node with its cells. The node's ``identified_unbalance`` and
``unbalance_residual`` (rotor frame: force U omega^2) are checked against the hidden
change worked out by hand, within the node's own 95 % radius from its diagnostics; the
diagnostics must say the rotor is not what its layout says; and the node's recording must
replay without --layout-file (it carries the layout in force from layout_file).
"""

import cmath
import math
from pathlib import Path
import signal
import subprocess
import sys

from rosbags.highlevel import AnyReader

from cvc_balance.bag.replay import replay
from ros_harness import NodeProcess, ros_environment

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'loose_bracket.mcap'
BRACKET = 0.3 * 0.5 * cmath.exp(1j * math.radians(130.0))          # kg m, by hand
TUBE = 0.6 * 0.62                                                    # kg m at 0 deg


def read(path):
    """Return {topic: [(stamp s or None, message)]} read by rosbags."""
    out = {}
    with AnyReader([Path(path)]) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            header = getattr(msg, 'header', None)
            stamp = header.stamp.sec + header.stamp.nanosec * 1e-9 if header else None
            out.setdefault(connection.topic, []).append((stamp, msg))
    return out


def test_node_identifies_the_hidden_bracket_and_warns(tmp_path):
    record = tmp_path / 'node.mcap'
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', f'layout_file:={ROOT / "config" / "ct_gantry.yaml"}',
                        '-p', f'record_path:={record}', '-p', 'identify_window_revs:=8'],
                       tmp_path / 'node.log')
    live = tmp_path / 'live.mcap'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play', str(BAG), '-o',
                          str(live), '--wait', '60'], env=ros_environment(),
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    assert node.stop(signal.SIGINT) == 0
    got = read(live)
    residual = got['/unbalance_residual']
    identified = got['/identified_unbalance']
    assert len(residual) == len(identified) > 10
    # Rotor-frame vectors, stamped so (the node's default rotor_frame).
    assert {msg.header.frame_id for _, msg in residual + identified} == {'rotor'}
    # Diagnostics: the measured status, with the node's radius for the static residual.
    # Each measured status with the digest of the layout in force (the main status's).
    measured = [({kv.key: kv.value for kv in msg.status[0].values}['layout digest'], s)
                for _, msg in got['/diagnostics'] for s in msg.status[1:]
                if s.name.endswith('measured unbalance')]
    digests = list(dict.fromkeys(d for d, _ in measured))
    assert len(digests) == 2                       # before and after the declared swap
    assert measured
    levels = [bytes(s.level)[0] if isinstance(s.level, bytes) else s.level
              for _, s in measured]
    assert max(levels) >= 1                        # WARN (or worse) at some point
    messages = ' '.join(s.message for _, s in measured)
    assert 'not what its layout says' in messages
    swap = 1.0 + 7.0                              # the tube swap, bag time
    for before, want in ((True, BRACKET), (False, BRACKET + TUBE)):
        # The last residual of each layout (force = U omega^2 at its sample's speed) and the
        # node's 95 % radius of the static unbalance at that time.
        stamp, msg = [(t, m) for t, m in residual if (t < swap - 0.5) == before][-1]
        found = complex(msg.wrench.force.x, msg.wrench.force.y) / _omega2_at(stamp)
        status = [s for d, s in measured if d == digests[0 if before else 1]][-1]
        radius = float({kv.key: kv.value for kv in status.values}[
            'measured static 95% radius [g mm]']) * 1e-6
        assert abs(found - want) <= radius, (before, found, want, radius)
        assert radius < 0.05 * abs(want)             # and it is informative
    # The node's own recording carries the layout it loaded from layout_file: it replays
    # without --layout-file.
    summary = replay(record)
    assert summary.segments and summary.segments[0].layout.name == 'ct_gantry_demo'
    topics = read(record)
    assert '/identified_unbalance' in topics and '/supports/front/measured_load' in topics


def _omega2_at(stamp):
    """omega^2 of the bundled run at bag time ``stamp`` (its exact speed profile)."""
    t = stamp - 1.0                 # the scenario's start
    spin_up = 23.27 / 6.0
    omega = 6.0 * t if t < spin_up else (23.27 if t < spin_up + 8.0
                                         else 23.27 - 8.0 * (t - spin_up - 8.0))
    return omega ** 2
