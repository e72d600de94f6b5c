"""
Scenarios against hand calculations, exact fractions, Pinocchio and rosbags (issue 29).

* the exact motion of piecewise constant accelerations, against ``Fraction`` arithmetic;
* what a scenario file gives (defaults, events, hidden changes, a tilt, load cells) and
  every refusal's words;
* the load cells' readings: Pinocchio's RNEA of the true rotor at the exact motion, split
  over the supports by statics, plus each cell's bias (no noise);
* the bag ``write_bag`` writes, decoded by rosbags: layouts, joint states, cells.

Small scenarios (a few hundred samples): milliseconds each.
"""

from fractions import Fraction
import math

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from cvc_balance.bag.scenario import exact_motion, load_scenario, ScenarioError, write_bag
from independent import PinocchioRotor

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
G = 9.80665
LAYOUT = {
    'name': 'drum', 'gravity': [0.0, -G, 0.0],
    'components': [
        {'name': 'drum', 'mass': 300.0, 'radius': 0.0, 'angle': 0.0,
         'shape': {'type': 'tube', 'inner_radius': 0.6, 'outer_radius': 0.7, 'length': 0.4}},
        {'name': 'tube', 'mass': 40.0, 'radius': 0.55, 'angle_deg': 20.0, 'z': 0.08},
        {'name': 'lump', 'mass': 2.0, 'radius': 0.6, 'angle': 1.0, 'z': -0.1}],
    'supports': [{'name': 'front', 'z': -0.3}, {'name': 'rear', 'z': 0.3, 'axial': True}]}


def write_scenario(folder, **fields):
    """Write a scenario (the drum inline, 100 samples/s, 5 s) with ``fields``; return its path."""
    spec = {'layout': LAYOUT, 'rate': 100,
            'profile': [{'type': 'spin_up', 'to': 10.0, 'alpha': 5.0},
                        {'type': 'steady', 'duration': 1.0},
                        {'type': 'coast_down', 'to': 4.0, 'alpha': -3.0}]}
    spec.update(fields)
    path = folder / 'run.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


def exact(pieces, t):
    """(angle, omega, alpha) at ``t`` by exact fractions: piece by piece from rest."""
    t, angle, omega, start = Fraction(t), Fraction(0), Fraction(0), Fraction(0)
    for duration, alpha in pieces:
        duration, alpha = Fraction(duration), Fraction(alpha)
        if t <= start + duration:
            dt = t - start
            return angle + omega * dt + alpha * dt * dt / 2, omega + alpha * dt, alpha
        angle += omega * duration + alpha * duration * duration / 2
        omega += alpha * duration
        start += duration
    raise AssertionError('after the profile')


def test_the_exact_motion_is_fractions_of_its_pieces():
    """Angle, speed and acceleration of three pieces at their ends and inside (1e-15)."""
    pieces = [(2.0, 3.0), (1.5, 0.0), (0.75, -2.0)]
    times = [0.0, 0.5, 2.0, 2.25, 3.5, 3.75, 4.25]
    angle, omega, alpha = exact_motion(pieces, np.array(times))
    later = {2.0: 0.0, 3.5: -2.0}       # a boundary takes the next piece's acceleration
    for k, t in enumerate(times):
        q, w, a = exact(pieces, t)
        assert angle[k] == pytest.approx(float(q), rel=1e-15, abs=1e-15), t
        assert omega[k] == pytest.approx(float(w), rel=1e-15, abs=1e-15), t
        assert alpha[k] == later.get(t, float(a)), t
    # By hand: 6 rad at 6 rad/s after the first piece, 9 rad more at 6 rad/s, then
    # 6 * 0.75 - 0.75^2 = 3.9375 rad to 4.5 rad/s.
    assert (angle[-1], omega[-1]) == (pytest.approx(18.9375, rel=1e-15), 4.5)


def test_a_scenario_file_with_its_defaults(tmp_path):
    """
    Samples every 1/rate s over the profile's length; the motion exact; defaults by hand.

    Name: the file's stem; joint gantry_joint; start 1 s; seed 0; no noise; no events
    (one layout from 0 s, the true rotor the same); no load cells.
    """
    path = write_scenario(tmp_path)
    run = load_scenario(path)
    assert (run.name, run.joint_name, run.rate, run.start, run.seed) == \
        ('run', 'gantry_joint', 100.0, 1.0, 0)
    assert (run.noise_angle, run.noise_speed, run.cells) == (0.0, 0.0, None)
    assert len(run.time) == 501 and run.time[0] == 0.0 and run.time[-1] == 5.0
    assert run.pieces == [(2.0, 5.0), (1.0, 0.0), (2.0, -3.0)]
    pieces = [(2, 5), (1, 0), (2, -3)]
    for k in (0, 1, 150, 200, 250, 300, 301, 499, 500):
        q, w, _ = exact(pieces, Fraction(k, 100))
        assert run.angle[k] == pytest.approx(float(q), rel=1e-14, abs=1e-14), k
        assert run.omega[k] == pytest.approx(float(w), rel=1e-14, abs=1e-14), k
    assert run.layouts == [(0.0, LAYOUT)] and run.truths == [(0.0, LAYOUT)]
    assert np.array_equal(run.stamps_ns(), 1_000_000_000 + 10_000_000 * np.arange(501))
    angle, omega = run.measured()           # no noise: the motion, the angle wrapped
    assert np.array_equal(omega, run.omega)
    assert np.abs(np.exp(1j * angle) - np.exp(1j * run.angle)).max() < 1e-12
    assert angle.min() >= -math.pi and angle.max() <= math.pi
    named = load_scenario(write_scenario(tmp_path, name='named', joint_name='j', start=2.5,
                                         seed=7))
    assert (named.name, named.joint_name, named.start, named.seed) == ('named', 'j', 2.5, 7)
    assert named.stamps_ns()[0] == 2_500_000_000
    spec = yaml.safe_load(write_scenario(tmp_path).read_text())
    del spec['rate']
    (tmp_path / 'rate.yaml').write_text(yaml.safe_dump(spec))
    default_rate = load_scenario(tmp_path / 'rate.yaml')
    assert default_rate.rate == 500.0 and len(default_rate.time) == 5 * 500 + 1
    cells = load_scenario(write_scenario(tmp_path, load_cells={})).cells
    assert cells == {'rate': 250.0, 'noise': 0.0,
                     'bias': {'front': [0.0, 0.0, 0.0], 'rear': [0.0, 0.0, 0.0]}}


def test_the_encoders_noise_is_seeded(tmp_path):
    """measured(): the angle's then the speed's normal draws of the seed's generator."""
    run = load_scenario(write_scenario(tmp_path, seed=11, noise={'angle': 0.01, 'speed': 0.2}))
    rng = np.random.default_rng(11)
    angle = run.angle + rng.normal(0.0, 0.01, 501)
    omega = run.omega + rng.normal(0.0, 0.2, 501)
    got_angle, got_omega = run.measured()
    assert np.array_equal(got_omega, omega)
    assert np.abs(got_angle - (np.mod(angle + math.pi, 2 * math.pi) - math.pi)).max() < 1e-12
    assert (run.noise_angle, run.noise_speed) == (0.01, 0.2)


def test_events_and_hidden_changes_in_time_order(tmp_path):
    """
    Declared events (published) and hidden ones (the true rotor only), by hand.

    A mass set at 1 s; at 2 s an angle in degrees replacing one in radians and, at the same
    time, a tilt of 30 deg (gravity (0, -g cos, g sin)): one layout from 2 s; a hidden lump
    added at 0 s (the true rotor from the start) and a hidden mass at 2 s, after the
    declared events of that time.
    """
    events = [{'at': 2.0, 'set': {'component': 'lump', 'angle_deg': 45.0}},
              {'at': 1.0, 'set': {'component': 'tube', 'mass': 41.0}},
              {'at': 2.0, 'tilt_deg': 30.0}]
    hidden = [{'at': 2.0, 'set': {'component': 'tube', 'mass': 43.0}},
              {'add': {'name': 'bracket', 'mass': 0.3, 'radius': 0.5, 'angle_deg': 130.0}}]
    run = load_scenario(write_scenario(tmp_path, events=events, hidden=hidden))
    tilted = [0.0, -G * math.cos(math.pi / 6), G * math.sin(math.pi / 6)]
    one = {**LAYOUT, 'components': [LAYOUT['components'][0],
                                    {**LAYOUT['components'][1], 'mass': 41.0},
                                    LAYOUT['components'][2]]}
    lump = {k: v for k, v in LAYOUT['components'][2].items() if k != 'angle'}
    two = {**one, 'gravity': tilted,
           'components': one['components'][:2] + [{**lump, 'angle_deg': 45.0}]}
    assert [at for at, _ in run.layouts] == [0.0, 1.0, 2.0]
    assert run.layouts[0][1] == LAYOUT and run.layouts[1][1] == one
    assert run.layouts[2][1]['gravity'] == pytest.approx(tilted, rel=1e-15)
    assert {**run.layouts[2][1], 'gravity': tilted} == two
    bracket = hidden[1]['add']
    assert [at for at, _ in run.truths] == [0.0, 1.0, 2.0]
    assert run.truths[0][1]['components'] == LAYOUT['components'] + [bracket]
    assert run.truths[1][1]['components'] == one['components'] + [bracket]
    assert run.truths[2][1]['components'] == \
        [one['components'][0], {**one['components'][1], 'mass': 43.0},
         two['components'][2], bracket]
    # The radians replacing degrees the other way round.
    back = load_scenario(write_scenario(tmp_path, events=[
        {'at': 1.0, 'set': {'component': 'tube', 'angle': 0.5}}]))
    tube = back.layouts[1][1]['components'][1]
    assert tube['angle'] == 0.5 and 'angle_deg' not in tube


def test_load_cells_read_pinocchios_support_loads_of_the_true_rotor(tmp_path):
    """
    Each cell: Pinocchio's RNEA of the true rotor at the exact motion, split by statics.

    No noise: the reading is the support's load plus the cell's bias (the rear's not given:
    zero). Cell k reads at (k + 1) / (3 rate) + j / rate s from the start; the true rotor
    changes at 2 s (a hidden mass). Held to 1e-9 of the largest force (measured 1e-15).
    """
    hidden = [{'at': 2.0, 'set': {'component': 'tube', 'mass': 45.0}}]
    run = load_scenario(write_scenario(
        tmp_path, hidden=hidden, load_cells={'rate': 40, 'bias': {'front': [5.0, -7.0, 0.5]}},
        profile=[{'type': 'spin_up', 'to': 6.0, 'alpha': 2.0},
                 {'type': 'steady', 'duration': 0.5}]))
    assert run.cells == {'rate': 40.0, 'noise': 0.0,
                         'bias': {'front': [5.0, -7.0, 0.5], 'rear': [0.0, 0.0, 0.0]}}
    readings = run.cell_readings()
    assert list(readings) == ['front', 'rear']
    before = PinocchioRotor(LAYOUT)
    after = PinocchioRotor(run.truths[1][1])
    pieces = [(3, 2), (Fraction(1, 2), 0)]
    for k, name in enumerate(('front', 'rear')):
        stamps, force, torque = readings[name]
        times = [Fraction(k + 1, 120) + Fraction(j, 40) for j in range(len(stamps))]
        assert len(stamps) == 140 and times[-1] < Fraction(7, 2) <= times[-1] + Fraction(1, 40)
        assert stamps.tolist() == [round((1 + t) * 10**9) for t in times]
        bias = np.array(run.cells['bias'][name])
        for j, t in enumerate(times):
            q, w, a = (float(v) for v in exact(pieces, t))
            rotor = before if t < 2 else after
            expected, moment = rotor.loads(q, w, a)['supports'][name]
            scale = 1e-9 * max(1.0, np.abs(expected).max())
            assert np.abs(force[j] - bias - expected).max() <= scale, (name, j)
            assert np.abs(torque[j] - moment).max() <= scale, (name, j)


def test_the_written_bag_read_by_rosbags(tmp_path):
    """
    write_bag: /layout at each layout's time less half a sample, /joint_states, the cells.

    Decoded by rosbags from the mcap library's reading: every layout text (YAML of the
    mapping), every sample's stamp, joint name, angle and speed as measured(), every
    cell's stamp and wrench in the stator frame; the machine id in the bag's custom data.
    """
    events = [{'at': 1.5, 'set': {'component': 'tube', 'mass': 41.0}}]
    run = load_scenario(write_scenario(
        tmp_path, events=events, seed=3, noise={'angle': 0.001, 'speed': 0.01}, rate=50,
        joint_name='spin', load_cells={'rate': 20, 'noise': 2.0, 'bias': {'rear': [1, 2, 3]}}))
    path = tmp_path / 'run.mcap'
    from cvc_balance.bag.run_label import run_label
    assert write_bag(run, path, compression='lz4', machine_id='g-7',
                     label=run_label('baseline')) == 251
    got = {}
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            got.setdefault(channel.topic, []).append((message.log_time, TYPESTORE.deserialize_cdr(
                message.data, reader.get_summary().schemas[channel.schema_id].name)))
        custom = [m.metadata for m in reader.iter_metadata() if m.name == 'cvc_balance']
        qos = {c.topic: yaml.safe_load(c.metadata['offered_qos_profiles'])[0]
               for c in reader.get_summary().channels.values()}
    assert custom == [{'machine_id': 'g-7', 'run': 'baseline'}]
    # (reliability, durability): 1 reliable, 2 best effort; 1 transient local, 2 volatile
    assert {t: (q['reliability'], q['durability']) for t, q in qos.items()} == {
        '/layout': (1, 1), '/joint_states': (2, 2), '/supports/front/measured_load': (2, 2),
        '/supports/rear/measured_load': (2, 2)}
    assert {m.header.frame_id for _, m in got['/joint_states']} == {''}
    assert sorted(got) == ['/joint_states', '/layout', '/supports/front/measured_load',
                           '/supports/rear/measured_load']
    assert [(t, yaml.safe_load(m.data)) for t, m in got['/layout']] == \
        [(990_000_000, LAYOUT), (2_490_000_000, run.layouts[1][1])]
    angle, omega = run.measured()
    stamps = 1_000_000_000 + 20_000_000 * np.arange(251)
    assert [(t, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, list(m.name),
             m.position.tolist(), m.velocity.tolist()) for t, m in got['/joint_states']] == \
        [(int(s), int(s), ['spin'], [q], [w]) for s, q, w in zip(stamps, angle, omega)]
    for name, (cell_stamps, force, torque) in run.cell_readings().items():
        messages = got[f'/supports/{name}/measured_load']
        assert [t for t, _ in messages] == cell_stamps.tolist()
        assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in messages] == \
            cell_stamps.tolist()
        assert {m.header.frame_id for _, m in messages} == {'stator'}
        wrenches = [[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x,
                     m.wrench.torque.y, m.wrench.torque.z] for _, m in messages]
        assert wrenches == np.hstack([force, torque]).tolist()


@pytest.mark.parametrize('change, said', [
    ({'profile': [{'type': 'spin_up', 'to': 10.0, 'alpha': -5.0}]},
     'profile step 1 (spin_up): alpha -5.0 does not take 0.0 rad/s to 10.0 rad/s'),
    ({'profile': [{'type': 'spin_up', 'to': 10.0, 'alpha': 0}]},
     'profile step 1 (spin_up): alpha 0.0 does not take 0.0 rad/s to 10.0 rad/s'),
    ({'profile': [{'type': 'steady', 'duration': 1.0},
                  {'type': 'ramp', 'to': 0.0, 'alpha': 1.0}]},
     'profile step 2 (ramp): alpha 1.0 does not take 0.0 rad/s to 0.0 rad/s'),
    ({'profile': [{'type': 'steady', 'duration': 0.0}]},
     'profile step 1 (steady): field duration must be > 0 s, got 0'),
    ({'profile': [{'type': 'spin', 'to': 1.0}]},
     "profile step 1: type must be spin_up, steady, coast_down or ramp, got 'spin'"),
    ({'profile': ['steady']},
     'profile step 1: type must be spin_up, steady, coast_down or ramp, got None'),
    ({'profile': []}, 'field profile: needs at least one step'),
    ({'profile': {'type': 'steady'}}, 'field profile: give a list of steps'),
    ({'layout': 7}, 'field layout: give a layout file path or mapping'),
    ({'events': [{'at': 0.0, 'tilt_deg': 5.0}]}, 'event 1: field at must be a time > 0 s'),
    ({'events': [{'tilt_deg': 5.0}]}, 'event 1: field at must be a time > 0 s'),
    ({'events': ['tilt']}, 'event 1: field at must be a time > 0 s'),
    ({'hidden': [{'at': -1.0, 'add': {'name': 'x', 'mass': 1.0}}]},
     'hidden change 1: field at must be a time > 0 s'),
    ({'events': [{'at': 1.0, 'add': {'name': 'x', 'mass': 1.0}}]},
     'event 1: add is for hidden changes (a layout change would be published)'),
    ({'events': [{'at': 1.0, 'set': {'component': 'nothing', 'mass': 1.0}}]},
     "event 1: no component 'nothing'"),
    ({'hidden': [{'at': 1.0, 'set': {'component': 'tube', 'mass': -1.0}}]},
     'hidden change 1 makes a bad layout: '),
    ({'load_cells': [250]}, 'field load_cells: give rate, noise and bias'),
    ({'load_cells': {'bias': {'middle': [0, 0, 0]}}},
     "field load_cells.bias: give [x, y, z] N for supports of the layout (front, rear), got "
     "'middle'"),
    ({'load_cells': {'bias': {'front': [0, 0]}}},
     "field load_cells.bias: give [x, y, z] N for supports of the layout (front, rear), got "
     "'front'"),
    ({'load_cells': {'rate': 'fast'}}, "field load_cells: field rate must be a number, got "
     "'fast'"),
    ({'load_cells': {'noise': 'loud'}}, "field load_cells: field noise must be a number, got "
     "'loud'"),
    ({'rate': 'fast'}, "field rate must be a number, got 'fast'"),
    ({'rate': 10**400}, 'field rate must be finite, got inf'),
    ({'rate': 0.5}, 'field rate must be from 1 to 100000 Hz (an encoder or a load cell: every '
     'sample is held in memory), got 0.5 Hz'),
    ({'start': 'soon'}, "field start must be a number, got 'soon'"),
    ({'noise': [0.1]}, 'field noise: field angle must be a number, got None'),
    ({'noise': {'speed': float('inf')}}, 'field noise: field speed must be finite, got inf'),
    ({'profile': [{'type': 'spin_up', 'to': 'fast', 'alpha': 1.0}]},
     "profile step 1 (spin_up): field to must be a number, got 'fast'"),
    ({'profile': [{'type': 'spin_up', 'to': 1.0, 'alpha': 'x'}]},
     "profile step 1 (spin_up): field alpha must be a number, got 'x'"),
    ({'profile': [{'type': 'steady', 'duration': 'long'}]},
     "profile step 1 (steady): field duration must be a number, got 'long'"),
    ({'profile': [{'type': 'spin_up', 'to': 2e5, 'alpha': 1.0}]},
     'profile step 1 (spin_up): field to (its size) must be from 0.001 to 100000 rad/s (a turn '
     'in 100 minutes to 955 000 rpm: slower is no balancing speed, faster no rotor), got '
     '200000 rad/s'),
    ({'profile': [{'type': 'steady', 'duration': 1e12}]},
     'the profile (1e+12 s at 100 samples/s) must be from 1 to 50000000 samples (about 3 GB '
     'of arrays), got 100000000000001.0 samples'),
    ({'hidden': ['x']}, 'hidden change 1: field at must be a time > 0 s'),
    ({'events': [{'at': 1.0, 'set': {'mass': 1.0}}]}, 'event 1: no component None'),
    ({'rate': True}, 'field rate must be a number, got True'),
    ({'noise': {'angle': float('inf')}}, 'field noise: field angle must be finite, got inf'),
])
def test_a_scenario_that_cannot_be_simulated_is_refused_with_its_reason(change, said, tmp_path):
    path = write_scenario(tmp_path, **change)
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value).startswith(f'{path}: {said}')
    if not said.endswith(': '):
        assert str(refused.value) == f'{path}: {said}'


def test_files_that_are_no_scenario(tmp_path):
    """A list, a layout file, an unknown field (the known ones in order), a missing layout."""
    path = tmp_path / 'run.yaml'
    path.write_text('- 1\n')
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == f'{path}: a scenario is a mapping'
    path.write_text(yaml.safe_dump(LAYOUT))
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f'{path}: this is a layout file (it has components), not a '
                                  'scenario; a scenario names a layout (layout: FILE) and '
                                  'gives a speed profile, e.g. bags/spin_up_tube_swap.yaml')
    path = write_scenario(tmp_path, speed=3)
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f"{path}: unknown field 'speed' (known: events, hidden, "
                                  'joint_name, layout, load_cells, name, noise, profile, '
                                  'rate, seed, start)')
    path = write_scenario(tmp_path, layout='missing.yaml')
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == (f'{path}: field layout: {tmp_path / "missing.yaml"}: cannot '
                                  'read layout: No such file or directory')
    path.write_text(yaml.safe_dump({**LAYOUT, 'layout': LAYOUT, 'profile': []}))
    with pytest.raises(ScenarioError) as refused:       # a profile: no layout file
        load_scenario(path)
    assert str(refused.value) == (f"{path}: unknown field 'components' (known: events, "
                                  'hidden, joint_name, layout, load_cells, name, noise, '
                                  'profile, rate, seed, start)')
    path.write_text(yaml.safe_dump({'layout': LAYOUT}))
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    assert str(refused.value) == f'{path}: field profile: needs at least one step'
    for missing, said in ((tmp_path / 'none.yaml', 'cannot read scenario: No such file or '
                           'directory'), (tmp_path, 'a directory, not a regular file: refused')):
        with pytest.raises(ScenarioError) as refused:
            load_scenario(missing)
        assert str(refused.value) == f'{missing}: {said}'
    path = write_scenario(tmp_path, rate='x' * 400)
    with pytest.raises(ScenarioError) as refused:
        load_scenario(path)
    said = f"{path}: field rate must be a number, got '{'x' * 400}'"
    assert str(refused.value) == said[:300] and len(said) > 400
    (tmp_path / 'drum.yaml').write_text(yaml.safe_dump(LAYOUT))
    assert load_scenario(write_scenario(tmp_path, layout='drum.yaml')).layouts == \
        [(0.0, LAYOUT)]


def test_the_bag_by_default_and_the_cells_noise(tmp_path):
    """
    The bag by default and the cells noise.

    By default zstd chunks of at most 64 KiB; the cells' noise: the normal draws of the
    seed + 1 generator, per support its forces' (std: noise) then its torques' (a tenth).
    """
    run = load_scenario(write_scenario(
        tmp_path, rate=500, seed=4, load_cells={'rate': 50, 'noise': 3.0,
                                                'bias': {'front': [1.0, 2.0, 3.0]}}))
    path = tmp_path / 'default.mcap'
    write_bag(run, path)
    with open(path, 'rb') as stream:
        indexes = make_reader(stream, validate_crcs=True).get_summary().chunk_indexes
    assert {i.compression for i in indexes} == {'zstd'} and len(indexes) >= 4
    assert max(i.uncompressed_size for i in indexes) <= 1 << 16
    assert run.stamps_ns().dtype == np.int64
    noisy = run.cell_readings()
    quiet = load_scenario(write_scenario(
        tmp_path, rate=500, seed=4, load_cells={'rate': 50, 'noise': 0.0,
                                                'bias': {'front': [1.0, 2.0, 3.0]}}))
    rng = np.random.default_rng(5)
    for name, (stamps, force, torque) in quiet.cell_readings().items():
        assert stamps.dtype == np.int64 and np.array_equal(noisy[name][0], stamps)
        force_noise = rng.normal(0.0, 3.0, force.shape)
        torque_noise = rng.normal(0.0, 0.3, torque.shape)
        assert np.abs(noisy[name][1] - (force + force_noise)).max() < 1e-9
        assert np.abs(noisy[name][2] - (torque + torque_noise)).max() < 1e-9


def test_a_cell_reading_at_the_time_of_a_change_reads_the_changed_rotor(tmp_path):
    """
    Read the rotor as changed at a change's own time.

    Cells at 128/3 readings/s: the front cell reads at (1 + 3 j) / 128 s, exact binary
    fractions, and a hidden change at 31/128 s (its eleventh reading). That reading is
    Pinocchio's support load of the changed rotor at the exact motion, the one before it
    the rotor's before (no noise, no bias; held to 1e-9 of the load).
    """
    rate = 128 / 3
    assert 3.0 * rate == 128.0 and 1.0 / rate == 3 / 128
    hidden = [{'at': 31 / 128, 'set': {'component': 'tube', 'mass': 80.0}}]
    run = load_scenario(write_scenario(
        tmp_path, hidden=hidden, load_cells={'rate': rate},
        profile=[{'type': 'spin_up', 'to': 6.0, 'alpha': 2.0}]))
    stamps, force, _ = run.cell_readings()['front']
    assert stamps[10] == 1_000_000_000 + round(Fraction(31, 128) * 10**9)
    for j, rotor in ((9, PinocchioRotor(LAYOUT)), (10, PinocchioRotor(run.truths[1][1]))):
        q, w, a = (float(v) for v in exact([(3, 2)], Fraction(1 + 3 * j, 128)))
        expected = rotor.loads(q, w, a)['supports']['front'][0]
        assert np.abs(force[j] - expected).max() <= 1e-9 * np.abs(expected).max(), j
    assert abs(force[10][1] - force[9][1]) > 100.0


def test_steps_shorter_than_a_second_and_the_fastest_speed(tmp_path):
    """
    Take a step of a quarter second, and a spin to the fastest speed a scenario may reach.

    Spin up at 4 rad/s^2 to 1 rad/s (0.25 s), then steady 0.5 s: 76 samples at 100/s,
    the pieces by hand. To 10^5 rad/s (the limit, included) at 10^5 rad/s^2: 1 s.
    """
    run = load_scenario(write_scenario(tmp_path, profile=[
        {'type': 'spin_up', 'to': 1.0, 'alpha': 4.0}, {'type': 'steady', 'duration': 0.5}]))
    assert run.pieces == [(0.25, 4.0), (0.5, 0.0)] and len(run.time) == 76
    fastest = load_scenario(write_scenario(tmp_path, profile=[
        {'type': 'spin_up', 'to': 1e5, 'alpha': 1e5}]))
    assert fastest.pieces == [(1.0, 1e5)] and fastest.omega[-1] == 1e5


def test_an_angle_set_in_the_unit_the_component_already_has(tmp_path):
    """Replace degrees by degrees and radians by radians: the other unit was never there."""
    run = load_scenario(write_scenario(tmp_path, events=[
        {'at': 1.0, 'set': {'component': 'tube', 'angle_deg': 50.0}},
        {'at': 2.0, 'set': {'component': 'lump', 'angle': 2.0}}]))
    tube, lump = run.layouts[2][1]['components'][1:]
    assert tube == {**LAYOUT['components'][1], 'angle_deg': 50.0}
    assert lump == {**LAYOUT['components'][2], 'angle': 2.0}
