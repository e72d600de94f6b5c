"""
The rerun view of a bag, read back with rerun's own reader (rerun.chunk.RrdReader).

Entity paths for the 3D scene, plots, polar views and text exist; logged values equal
Pinocchio's (scenario_reference) at sampled times; the per-plane fractions, the support
loads' static and rotating parts and the verdict lanes equal what is computed here by
hand from the layout (ISO 21940-2's two-plane split, ISO 21940-11's U_per).
"""

import cmath
import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cvc_balance.bag.scenario import load_scenario
from cvc_balance.physics.frames import STANDARD_GRAVITY
from cvc_balance.physics.layout import parse_layout
from cvc_balance.physics.layout_file import load_layout
from scenario_reference import expected_outputs

ROOT = Path(__file__).resolve().parents[1]


def read_rrd(path):
    """{entity path: (times ns, values)} of scalar plots, and the set of all paths."""
    scalars, transforms, paths = {}, {}, set()
    for chunk in RrdReader(str(path)).stream():
        path_name = str(chunk.entity_path)
        paths.add(path_name)
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if 'time' not in names:
            continue
        times = batch.column('time').cast('int64').to_numpy()
        if 'Scalars:scalars' in names:
            values = np.array([v[0] for v in batch.column('Scalars:scalars').to_pylist()])
            scalars.setdefault(path_name, []).append((times, values))
        rotation = [n for n in names if 'quaternion' in n]
        if rotation:
            transforms.setdefault(path_name, []).append((times, batch.column(rotation[0])))
        state = [n for n in names if n.startswith('StateChange:')]
        if state:
            states = [v[0] if v else None for v in batch.column(state[0]).to_pylist()]
            scalars.setdefault(path_name, []).append((times, np.array(states, dtype=object)))
    joined = {p: (np.concatenate([t for t, _ in parts]), np.concatenate([v for _, v in parts]))
              for p, parts in scalars.items()}
    return joined, transforms, paths


@pytest.fixture(scope='module')
def rrd(tmp_path_factory):
    out = tmp_path_factory.mktemp('rrd') / 'run.rrd'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'view',
                          str(ROOT / 'bags' / 'spin_up_tube_swap.mcap'), '-o', str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return out


@pytest.fixture(scope='module')
def logged(rrd):
    return read_rrd(rrd)


def read_rows(path, entity, *columns):
    """Rows of one entity's logged component ``columns``, with both timelines (ns)."""
    rows = []
    for chunk in RrdReader(str(path)).stream():
        if str(chunk.entity_path) != entity:
            continue
        batch = chunk.to_record_batch()
        if not set(columns) <= set(batch.schema.names):
            continue
        since = batch.column('since start').cast('int64').to_pylist()
        stamps = batch.column('time').cast('int64').to_pylist()
        values = [batch.column(c).to_pylist() for c in columns]
        rows += [(a, b) + tuple(v) for a, b, *v in zip(since, stamps, *values)]
    return sorted(rows, key=lambda row: row[:2])


def test_times_are_seconds_since_the_first_sample(rrd):
    """
    The views' timeline counts from the run's first sample, the events say so in text.

    The bag's stamps start 1 s after the epoch (the date would read 1970-01-01); its
    layout changes at stamp 6 s, 5 s into the run (bags/spin_up_tube_swap.yaml).
    """
    first = min(expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')[0])
    assert first == 1_000_000_000
    rows = read_rows(rrd, '/events', 'TextLog:text')
    assert rows, 'no events'
    for since, stamp, (text,) in rows:
        assert since == stamp - first
        assert text.startswith(f'{since * 1e-9:6.2f} s  '), text
    layouts = [(since, text) for since, _, (text,) in rows if ' layout ' in f' {text}']
    assert [since for since, _ in layouts] == [0, 5_000_000_000], layouts
    assert layouts[1][1].startswith('  5.00 s  layout ct_gantry_demo ')


def test_the_limit_label_is_clear_of_its_circle(rrd):
    """The red circle is the limit (radius 1): its label in a row of its own, off the ring."""
    for key in ('plane_I', 'plane_II'):
        rows = read_rows(rrd, f'/polar/{key}/labels', 'Points2D:labels', 'Points2D:positions')
        assert rows
        for _, _, labels, positions in rows:
            (at,) = [p for text, p in zip(labels, positions) if text.startswith('limit ')]
            # Labels hang below their point by one text row (POLAR_LINE of the limit).
            top, bottom = math.hypot(*at), math.hypot(at[0], at[1] + 0.28)
            assert min(top, bottom) > 1.2 or max(top, bottom) < 0.8, (key, labels, at)


def test_entity_paths_of_every_view_exist(logged):
    _, _, paths = logged
    layout = load_layout(ROOT / 'config' / 'ct_gantry.yaml')
    wanted = {'/world', '/world/gravity', '/world/stator', '/world/stator/ring',
              '/world/stator/supports', '/world/stator/loads',
              '/world/stator/rotor/unbalance_force', '/world/stator/rotor',
              '/plots/speed/omega', '/plots/speed/alpha', '/plots/drive_torque',
              '/plots/unbalance/plane_I', '/plots/unbalance/plane_II', '/plots/unbalance/limit',
              '/polar/plane_I/vectors', '/polar/plane_I/grid', '/polar/plane_I/grid_labels',
              '/polar/plane_II/limit', '/polar/plane_II/labels', '/verdict', '/verdict_level',
              '/events', '/world/stator/rotor/correction/plane_II/mass'}
    wanted |= {f'/world/stator/rotor/components/{c.name}' for c in layout.components}
    for support in ('front', 'rear'):
        wanted |= {f'/plots/load_rotating/{support}', f'/plots/load_static/{support}'}
    assert wanted <= paths, wanted - paths


def test_logged_values_equal_the_engine_at_sampled_times(logged):
    scalars, _, _ = logged
    expected, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    stamps = sorted(expected)
    rng = np.random.default_rng(0)
    for ns in rng.choice(stamps, 40, replace=False).tolist():
        q, omega, alpha = motion[ns]
        values = {'/plots/speed/omega': omega, '/plots/speed/alpha': alpha,
                  '/plots/drive_torque': expected[ns]['/drive_torque'][5]}
        for path, value in values.items():
            times, logged_values = scalars[path]
            (at,) = np.nonzero(times == ns)
            assert len(at) == 1, path
            scale = np.abs(logged_values).max()
            # Measured, of each plot's peak: omega 0, support loads 8.3e-15 at most,
            # alpha and drive torque 1.5e-13 (two implementations of the estimator).
            bound = 1e-12 if path in ('/plots/speed/alpha', '/plots/drive_torque') else 4e-14
            assert abs(logged_values[at[0]] - value) <= bound * scale, path
    assert len(scalars['/plots/speed/omega'][0]) == len(stamps)   # every sample


def hand_layouts():
    """Return the bag's layouts from its scenario: [(first stamp ns, Layout)]."""
    scenario = load_scenario(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    return [(round((scenario.start + at - 0.5 / scenario.rate) * 1e9), parse_layout(mapping))
            for at, mapping in scenario.layouts]


def two_plane_split(layout, z_a, z_b):
    """ISO 21940-2: each m r e^{j theta} at z_i split into planes z_a, z_b (kg m, complex)."""
    u = [c.mass * c.radius * cmath.exp(1j * c.angle) for c in layout.components]
    span = z_b - z_a
    return (sum(v * (z_b - c.z) / span for v, c in zip(u, layout.components)),
            sum(v * (c.z - z_a) / span for v, c in zip(u, layout.components)))


def test_support_loads_are_the_static_weight_and_the_unbalance_turning(logged):
    """
    Static: the weight shared by the lever rule, m g (z_other - z_com) / span.

    Rotating: omega^2 U_s + alpha (U_s turned by -90 deg), U_s the two-plane split at the
    supports' planes, so |F_rot| = |U_s| sqrt(omega^4 + alpha^2). Each within 1e-9 of the
    series' peak (measured: 1e-13); the gantry's shapes have no own products of inertia.
    """
    scalars, _, _ = logged
    _, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    layouts = hand_layouts()
    for support in ('front', 'rear'):
        for part in ('static', 'rotating'):
            times, values = scalars[f'/plots/load_{part}/{support}']
            peak = np.abs(values).max()
            for k in np.linspace(0, len(times) - 1, 60).astype(int).tolist():
                ns = int(times[k])
                layout = [lay for t, lay in layouts if t <= ns][-1]
                front, rear = layout.supports
                mass = sum(c.mass for c in layout.components)
                z_com = sum(c.mass * c.z for c in layout.components) / mass
                span = rear.z - front.z
                if part == 'static':
                    lever = (rear.z - z_com) if support == 'front' else (z_com - front.z)
                    want = mass * STANDARD_GRAVITY * lever / span
                else:
                    _, omega, alpha = motion[ns]
                    u = two_plane_split(layout, front.z, rear.z)[support == 'rear']
                    want = abs(u) * math.hypot(omega * omega, alpha)
                assert abs(values[k] - want) <= 1e-9 * peak, (support, part, ns)


def test_unbalance_plot_is_each_plane_over_its_own_share_and_the_verdict_lanes(logged):
    """
    Plot each plane's |U_i| / (U_per share_i) and the verdict lanes as computed by hand.

    U_per = G m / Omega at the service speed (ISO 21940-11), share_i = lever of the other
    plane / span within 0.3-0.7; the lanes: OK until the tube swap (worst 0.40), ERROR
    after it (plane II 1.17), as the fractions say.
    """
    scalars, _, _ = logged
    layouts = hand_layouts()
    lanes_times, lanes = scalars['/verdict_level']
    for start_ns, layout in layouts:
        z_i, z_ii = layout.balancing.planes
        mass = sum(c.mass for c in layout.components)
        z_com = sum(c.mass * c.z for c in layout.components) / mass
        u_per = layout.balancing.grade * 1e-3 * mass / layout.balancing.service_speed
        levers = ((z_ii - z_com) / (z_ii - z_i), (z_com - z_i) / (z_ii - z_i))
        shares = [min(max(s, 0.3), 0.7) for s in levers]
        fractions = [abs(u) / (u_per * share)
                     for u, share in zip(two_plane_split(layout, z_i, z_ii), shares)]
        for key, want in zip(('plane_I', 'plane_II'), fractions):
            times, values = scalars[f'/plots/unbalance/{key}']
            mine = values[(times >= start_ns) & (times < start_ns + 2 * 10**9)]
            assert len(mine) > 100 and np.abs(mine - want).max() <= 1e-9 * want, key
        worst = max(fractions)
        want_lane = 'ERROR' if worst > 1.0 else 'WARN' if worst > 0.8 else 'OK'
        (at,) = np.nonzero(np.abs(lanes_times - start_ns) < 2_000_000)   # the first sample
        assert [lanes[k] for k in at] == [want_lane], (start_ns, worst)
    assert list(lanes) == ['OK', 'ERROR']
    times, limit = scalars['/plots/unbalance/limit']
    assert np.all(limit == 1.0)


def test_transform_turns_the_rotor_by_the_encoder_angle(logged):
    _, transforms, _ = logged
    times, column = transforms['/world/stator/rotor'][0]
    _, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    rows = column.to_pylist()
    for k in (0, 7, len(rows) - 1):
        x, y, z, w = rows[k][0] if isinstance(rows[k][0], list) else rows[k]
        q = motion[int(times[k])][0]
        # A turn by q about +Z is the quaternion (0, 0, sin q/2, cos q/2) (float32: 1e-7).
        assert [x, y, z, w] == pytest.approx([0.0, 0.0, math.sin(q / 2), math.cos(q / 2)],
                                             abs=2e-7)


def test_live_node_logs_the_same_view(tmp_path):
    """The node (rerun:=save, every 10th sample) fed a bag live: same paths, engine values."""
    import signal
    from ros_harness import NodeProcess, ros_environment

    out = tmp_path / 'live.rrd'
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', 'rerun:=save', '-p', f'rerun_target:={out}', '-p',
                        'rerun_every:=10'], tmp_path / 'node.log')
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play',
                          str(ROOT / 'bags' / 'spin_up_tube_swap.mcap'), '--wait', '60'],
                         env=ros_environment(), capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    assert node.stop(signal.SIGINT) == 0
    scalars, _, paths = read_rrd(out)
    assert {'/world/stator/rotor', '/world/stator/loads', '/plots/speed/omega', '/verdict',
            '/polar/plane_I/vectors', '/world/stator/rotor/components/xray_tube',
            '/verdict_level'} <= paths
    expected, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    times, omega = scalars['/plots/speed/omega']
    # Every 10th sample, and the first: the layout is drawn at the first sample's stamp.
    assert len(times) == len(expected) // 10 + 1 and times[0] == min(expected)
    for path, pick in (('/plots/speed/omega', lambda ns: motion[ns][1]),
                       ('/plots/drive_torque', lambda ns: expected[ns]['/drive_torque'][5])):
        times, values = scalars[path]
        reference = np.array([pick(int(ns)) for ns in times])
        # Measured: omega 0, drive torque 7.1e-14 of its peak.
        assert np.abs(values - reference).max() <= 1e-12 * np.abs(reference).max(), path


def test_shapes_below_the_view_resolution_are_drawn_as_points(tmp_path):
    """A 3 mm screw on a gantry is a point; a 30 cm box stays a box."""
    from cvc_balance.physics.engine import RotorModel
    from cvc_balance.physics.layout import parse_layout
    from cvc_balance.view.rerun_log import open_recording, RunLogger, view_resolution
    layout = parse_layout({
        'name': 'screws', 'supports': [{'name': 'a', 'z': -0.3},
                                       {'name': 'b', 'z': 0.3, 'axial': True}],
        'components': [
            {'name': 'screw', 'mass': 0.01, 'radius': 0.6, 'angle': 0.1,
             'shape': {'type': 'box', 'size': [0.002, 0.002, 0.003]}},
            {'name': 'pin', 'mass': 0.02, 'radius': 0.6, 'angle': 0.2,
             'shape': {'type': 'cylinder', 'radius': 0.002, 'length': 0.005}},
            {'name': 'tank', 'mass': 60.0, 'radius': 0.5, 'angle': 1.0,
             'shape': {'type': 'box', 'size': [0.3, 0.2, 0.25]}}]})
    assert 0.003 < view_resolution(layout) < 0.3
    path = tmp_path / 'screws.rrd'
    logger = RunLogger(open_recording('save', str(path)))
    logger.layout(0, RotorModel.from_layout(layout))
    logger.finish()
    columns = {}
    for chunk in RrdReader(str(path)).stream():
        columns.setdefault(str(chunk.entity_path), set()).update(
            chunk.to_record_batch().schema.names)
    for name in ('screw', 'pin'):
        drawn = columns[f'/world/stator/rotor/components/{name}']
        assert any(n.startswith('Points3D:positions') for n in drawn), drawn
        assert not any(n.startswith(('Boxes3D', 'Cylinders3D')) for n in drawn)
    assert any(n.startswith('Boxes3D:half_sizes')
               for n in columns['/world/stator/rotor/components/tank'])
