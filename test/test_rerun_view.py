"""
The rerun view of a bag, read back with rerun's own reader (rerun.chunk.RrdReader).

Entity paths for the 3D scene, plots, polar views and text exist, and logged values equal
the engine's (scenario_reference) at sampled times.
"""

from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from rerun.chunk import RrdReader

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
        rotation = [n for n in names if 'rotation_axis_angle' in n]
        if rotation:
            transforms.setdefault(path_name, []).append((times, batch.column(rotation[0])))
    joined = {p: (np.concatenate([t for t, _ in parts]), np.concatenate([v for _, v in parts]))
              for p, parts in scalars.items()}
    return joined, transforms, paths


@pytest.fixture(scope='module')
def logged(tmp_path_factory):
    out = tmp_path_factory.mktemp('rrd') / 'run.rrd'
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'view',
                          str(ROOT / 'bags' / 'spin_up_tube_swap.mcap'), '-o', str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return read_rrd(out)


def test_entity_paths_of_every_view_exist(logged):
    _, _, paths = logged
    layout = load_layout(ROOT / 'config' / 'ct_gantry.yaml')
    wanted = {'/world/stator/ring', '/world/stator/supports', '/world/stator/loads',
              '/world/rotor/unbalance_force',
              '/world/rotor', '/plots/speed/omega', '/plots/speed/alpha',
              '/plots/drive_torque', '/plots/unbalance/plane_I',
              '/plots/unbalance/plane_I_limit', '/polar/plane_I/unbalance',
              '/polar/plane_II/tolerance', '/verdict', '/events',
              '/world/rotor/correction/plane_II/mass'}
    wanted |= {f'/world/rotor/components/{c.name}' for c in layout.components}
    for support in ('front', 'rear'):
        wanted |= {f'/plots/supports/{support}/{axis}' for axis in ('x', 'y', 'z', 'magnitude')}
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
        for support in ('front', 'rear'):
            force = expected[ns][f'/supports/{support}/load'][:3]
            values[f'/plots/supports/{support}/x'] = force[0]
            values[f'/plots/supports/{support}/magnitude'] = float(np.linalg.norm(force))
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


def test_transform_turns_the_rotor_by_the_encoder_angle(logged):
    _, transforms, _ = logged
    times, column = transforms['/world/rotor'][0]
    _, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    rows = column.to_pylist()
    for k in (0, 7, len(rows) - 1):
        row = rows[k][0] if isinstance(rows[k], list) else rows[k]
        angle = row['angle'] if 'angle' in row else row['radians']
        assert row['axis'] == pytest.approx([0.0, 0.0, 1.0])
        assert angle == pytest.approx(motion[int(times[k])][0], abs=1e-6)


def test_live_node_logs_the_same_view(tmp_path):
    """The node (rerun:=save, every 10th sample) fed a bag live: same paths, engine values."""
    import signal
    from ros_harness import NodeProcess, ros_environment

    out = tmp_path / 'live.rrd'
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', 'rerun:=save', '-p', f'rerun_target:={out}', '-p',
                        'rerun_every:=10'], tmp_path / 'node.log')
    run = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'play',
                          str(ROOT / 'bags' / 'spin_up_tube_swap.mcap')],
                         env=ros_environment(), capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert node.stop(signal.SIGINT) == 0
    scalars, _, paths = read_rrd(out)
    assert {'/world/rotor', '/world/stator/loads', '/plots/speed/omega', '/verdict',
            '/polar/plane_I/unbalance', '/world/rotor/components/xray_tube'} <= paths
    expected, motion = expected_outputs(ROOT / 'bags' / 'spin_up_tube_swap.yaml')
    times, omega = scalars['/plots/speed/omega']
    assert len(times) == len(expected) // 10
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
        drawn = columns[f'/world/rotor/components/{name}']
        assert any(n.startswith('Points3D:positions') for n in drawn), drawn
        assert not any(n.startswith(('Boxes3D', 'Cylinders3D')) for n in drawn)
    assert any(n.startswith('Boxes3D:half_sizes') for n in columns['/world/rotor/components/tank'])
