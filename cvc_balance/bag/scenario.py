"""
Scenarios: a speed profile, encoder noise and layout changes, turned into an input bag.

A scenario file (YAML) names a layout (a path relative to the scenario file,
or an inline mapping), a sample rate, noise, a speed profile and events::

    name: spin_up_tube_swap
    layout: ../config/ct_gantry.yaml
    joint_name: gantry_joint
    rate: 500                          # samples/s
    seed: 1
    noise: {angle: 1.0e-4, speed: 0.005}   # std of the encoder's angle (rad), speed (rad/s)
    profile:                           # from rest at angle 0, one after the other
      - {type: spin_up, to: 23.27, alpha: 4.0}     # rad/s, rad/s^2
      - {type: steady, duration: 2.0}              # s
      - {type: coast_down, to: 0.0, alpha: -3.0}
    events:                            # layout changes, published on /layout at their time
      - {at: 2.0, set: {component: xray_tube, mass: 64.0}}                  # a tube swap
      - {at: 4.0, set: {component: counterweight_rear, angle_deg: 275.0}}   # a shift
      - {at: 5.0, tilt_deg: 20.0}      # gantry tilt: gravity (0, -g cos, g sin)
    hidden:                            # the real rotor's differences from its layout: they
      - {at: 0.0, add: {name: loose_bracket, mass: 0.3, radius: 0.5, angle_deg: 30.0}}
      - {at: 6.0, set: {component: xray_tube, mass: 61.0}}   # move the loads, not /layout
    load_cells:                        # a cell under each support: supports/<name>/measured_load
      rate: 250                        # readings/s per cell (default 250)
      noise: 15.0                      # N, std of each force component (and 0.1 N m/N torque)
      bias: {front: [120.0, -340.0, 5.0], rear: [-80.0, 55.0, -3.0]}   # N, each cell's zero

The motion is exact (piecewise constant alpha); the bag's samples are that
motion plus Gaussian noise. Times in the bag start at ``start`` (s, default 1). The cells
read the TRUE rotor (layout, events and hidden changes) at the exact motion, plus their
bias and noise; the bag's /layout stays the declared one.
"""

import copy
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

from cvc_balance.bag.machine import custom_data
from cvc_balance.bag.mcap_writer import MessageBlock
from cvc_balance.bag.rosbag2 import open_writer
from cvc_balance.messages import topics
from cvc_balance.messages.cdr import joint_state_layout, string_message, wrench_stamped_layout
from cvc_balance.physics import limits
from cvc_balance.physics.documents import DocumentError, dump_document, read_document
from cvc_balance.physics.engine import loads, RotorModel
from cvc_balance.physics.frames import radians, STANDARD_GRAVITY, STATOR_FRAME, wrap_angle
from cvc_balance.physics.layout import LayoutError, parse_layout
from cvc_balance.physics.layout_file import MAX_TEXT_BYTES


class ScenarioError(ValueError):
    """A scenario that cannot be simulated; ``str()`` names what is wrong."""


@dataclass
class Scenario:
    """A parsed scenario: layouts in force from given times, and the exact motion."""

    name: str
    joint_name: str
    rate: float
    start: float
    time: np.ndarray       # s from the start
    angle: np.ndarray      # rad, exact
    omega: np.ndarray      # rad/s, exact
    layouts: list          # [(time s, layout mapping)]
    noise_angle: float
    noise_speed: float
    seed: int
    truths: list = None    # [(time s, layout mapping)]: the real rotor, hidden changes in
    cells: dict = None     # load cells: {'rate': Hz, 'noise': N, 'bias': {support: [3]}}
    pieces: list = None    # [(duration s, alpha rad/s^2)]: the speed profile

    def cell_readings(self):
        """
        Return {support: (stamps ns, force (n, 3) N, torque (n, 3) N m)} of the load cells.

        The TRUE rotor (``truths``) at the exact motion, stator frame, plus each cell's bias
        and Gaussian noise (seeded: seed + 1); each cell reads at ``rate``, offset by a
        fraction of a period from the encoder and from the other cells.
        """
        rng = np.random.default_rng(self.seed + 1)
        rate, noise = self.cells['rate'], self.cells['noise']
        models = [(at, RotorModel.from_layout(parse_layout(m))) for at, m in self.truths]
        supports = models[0][1].supports
        out = {}
        for k, support in enumerate(supports):
            time = np.arange((k + 1) / (3.0 * rate), self.time[-1], 1.0 / rate)
            angle, omega, alpha = exact_motion(self.pieces, time)
            force, torque = np.zeros((len(time), 3)), np.zeros((len(time), 3))
            bounds = [at for at, _ in models[1:]] + [np.inf]
            for (at, model), end in zip(models, bounds):
                part = (time >= at) & (time < end)
                result = loads(model, angle[part], omega[part], alpha[part])
                force[part] = result.support_force[support.name]
                torque[part] = result.support_moment[support.name]
            force += np.asarray(self.cells['bias'][support.name]) \
                + rng.normal(0.0, noise, force.shape)
            torque += rng.normal(0.0, 0.1 * noise, torque.shape)
            stamps = np.round((self.start + time) * 1e9).astype(np.int64)
            out[support.name] = (stamps, force, torque)
        return out

    def measured(self):
        """Return the encoder's angle (wrapped to [-pi, pi]) and speed: motion plus noise."""
        rng = np.random.default_rng(self.seed)
        angle = self.angle + rng.normal(0.0, self.noise_angle, len(self.time))
        omega = self.omega + rng.normal(0.0, self.noise_speed, len(self.time))
        return wrap_angle(angle), omega

    def stamps_ns(self):
        """Sample stamps, ns."""
        return np.round((self.start + self.time) * 1e9).astype(np.int64)


def _document(path, what):
    """Read the YAML 1.2 or JSON document at ``path`` (a regular file) for a scenario."""
    try:
        return read_document(path, MAX_TEXT_BYTES)
    except OSError as error:
        raise ScenarioError(f'{path}: cannot read {what}: {error.strerror}') from None
    except DocumentError as error:
        message = str(error)
        raise ScenarioError(message if message.startswith(str(path)) else f'{path}: {message}') \
            from None


def _number(spec, key, default, where, limit):
    """Return ``spec[key]`` (or ``default``) as a float within ``limit``, or refuse it."""
    value = spec.get(key, default) if isinstance(spec, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f'{where}: field {key} must be a number, got {value!r}'[:300])
    try:
        value = float(value)
    except OverflowError:
        value = math.inf
    if not math.isfinite(value):
        raise ScenarioError(f'{where}: field {key} must be finite, got {value}')
    return limits.check(value, limit, f'{where}: field {key}', ScenarioError)


def load_scenario(path):
    """Read and check a scenario file; raises :class:`ScenarioError`."""
    path = Path(path)
    spec = _document(path, 'scenario')
    if not isinstance(spec, dict):
        raise ScenarioError(f'{path}: a scenario is a mapping')
    if 'components' in spec and 'profile' not in spec:
        raise ScenarioError(f'{path}: this is a layout file (it has components), not a '
                            'scenario; a scenario names a layout (layout: FILE) and gives a '
                            'speed profile, e.g. bags/spin_up_tube_swap.yaml')
    known = {'name', 'layout', 'joint_name', 'rate', 'seed', 'noise', 'profile', 'events',
             'start', 'hidden', 'load_cells'}
    for key in spec:
        if key not in known:
            raise ScenarioError(f'{path}: unknown field {key!r} '
                                f'(known: {", ".join(sorted(known))})')
    layout = spec.get('layout')
    if isinstance(layout, str):
        try:
            layout = _document(path.parent / layout, 'layout')
        except ScenarioError as error:
            raise ScenarioError(f'{path}: field layout: {error}') from None
    if not isinstance(layout, dict):
        raise ScenarioError(f'{path}: field layout: give a layout file path or mapping')
    rate = _number(spec, 'rate', 500.0, str(path), limits.SAMPLE_RATE)
    _number(spec, 'start', 1.0, str(path), limits.START)
    for key in ('angle', 'speed'):
        _number(spec.get('noise') or {}, key, 0.0, f'{path}: field noise', limits.NOISE)
    time, angle, omega, pieces = _motion(spec.get('profile') or [], rate, path)
    events = spec.get('events') or []
    layouts = _layouts(layout, events, path)
    truths = _layouts(layout, events, path, hidden=spec.get('hidden') or [])
    cells = _load_cells(spec.get('load_cells'), parse_layout(layout), path)
    noise = spec.get('noise') or {}
    return Scenario(str(spec.get('name', path.stem)), str(spec.get('joint_name', 'gantry_joint')),
                    rate, float(spec.get('start', 1.0)), time, angle, omega, layouts,
                    float(noise.get('angle', 0.0)), float(noise.get('speed', 0.0)),
                    int(spec.get('seed', 0)), truths, cells, pieces)


def _motion(profile, rate, path):
    """Exact motion: piecewise constant alpha segments from rest."""
    pieces, omega = [], 0.0
    if not isinstance(profile, list):
        raise ScenarioError(f'{path}: field profile: give a list of steps')
    for i, step in enumerate(profile):
        kind = step.get('type') if isinstance(step, dict) else None
        where = f'{path}: profile step {i + 1} ({kind})'
        if kind in ('spin_up', 'coast_down', 'ramp'):
            alpha = _number(step, 'alpha', None, where, limits.POSITION)
            target = _number(step, 'to', None, where, limits.POSITION)
            if abs(target) > limits.SPEED.high:
                raise ScenarioError(limits.SPEED.message(f'{where}: field to (its size)', target))
            duration = (target - omega) / alpha if alpha else -1.0
            if not duration > 0:
                raise ScenarioError(f'{path}: profile step {i + 1} ({kind}): alpha {alpha} '
                                    f'does not take {omega} rad/s to {target} rad/s')
        elif kind == 'steady':
            alpha = 0.0
            duration = _number(step, 'duration', None, where, limits.POSITION)
            if not duration > 0:
                raise ScenarioError(f'{where}: field duration must be > 0 s, got {duration:g}')
        else:
            raise ScenarioError(f'{path}: profile step {i + 1}: type must be spin_up, steady, '
                                f'coast_down or ramp, got {kind!r}')
        pieces.append((duration, alpha))
        omega += alpha * duration
    if not pieces:
        raise ScenarioError(f'{path}: field profile: needs at least one step')
    total = sum(d for d, _ in pieces)
    samples = total * rate + 1
    if not samples <= limits.SAMPLES.high:             # inf too
        raise ScenarioError(limits.SAMPLES.message(
            f'{path}: the profile ({total:g} s at {rate:g} samples/s)', samples))
    time = np.arange(int(total * rate) + 1) / rate
    return (time, *exact_motion(pieces, time)[:2], pieces)


def exact_motion(pieces, time):
    """Angle (rad, unwrapped), omega and alpha at ``time`` (s) of piecewise constant alpha."""
    angle, omega, alpha_t = np.zeros_like(time), np.zeros_like(time), np.zeros_like(time)
    t0 = q0 = w0 = 0.0
    for duration, alpha in pieces:
        inside = (time >= t0) & (time <= t0 + duration)
        dt = time[inside] - t0
        angle[inside] = q0 + w0 * dt + 0.5 * alpha * dt * dt
        omega[inside] = w0 + alpha * dt
        alpha_t[inside] = alpha
        q0 += w0 * duration + 0.5 * alpha * duration * duration
        w0 += alpha * duration
        t0 += duration
    return angle, omega, alpha_t


def _layouts(layout, events, path, hidden=()):
    """
    Return the layout mapping in force from each event's time (validated).

    With ``hidden`` events too (``set`` or ``add``), the real rotor's: the declared
    layout's changes and the hidden ones, in time order.
    """
    timeline = [(float(e.get('at', -1.0)) if isinstance(e, dict) else -1.0, i, e, False)
                for i, e in enumerate(events)]
    timeline += [(float(e.get('at', 0.0)) if isinstance(e, dict) else -1.0, i, e, True)
                 for i, e in enumerate(hidden)]
    current = copy.deepcopy(layout)
    out = [(0.0, copy.deepcopy(current))]
    for at, i, event, is_hidden in sorted(timeline, key=lambda e: (e[0], e[3], e[1])):
        what = f'hidden change {i + 1}' if is_hidden else f'event {i + 1}'
        if not (at > 0 or (is_hidden and at == 0.0)):
            raise ScenarioError(f'{path}: {what}: field at must be a time > 0 s')
        if 'set' in event:
            change = dict(event['set'])
            name = change.pop('component', None)
            matches = [c for c in current['components'] if c.get('name') == name]
            if not matches:
                raise ScenarioError(f'{path}: {what}: no component {name!r}')
            if 'angle_deg' in change:
                matches[0].pop('angle', None)
            if 'angle' in change:
                matches[0].pop('angle_deg', None)
            matches[0].update(change)
        if 'add' in event:
            if not is_hidden:
                raise ScenarioError(f'{path}: {what}: add is for hidden changes (a layout '
                                    'change would be published)')
            current['components'].append(dict(event['add']))
        if 'tilt_deg' in event:
            tilt = radians(float(event['tilt_deg']))
            current['gravity'] = [0.0, -STANDARD_GRAVITY * math.cos(tilt),
                                  STANDARD_GRAVITY * math.sin(tilt)]
        try:
            parse_layout(current)
        except LayoutError as error:
            raise ScenarioError(f'{path}: {what} makes a bad layout: {error}') from None
        if out[-1][0] == at:
            out[-1] = (at, copy.deepcopy(current))
        else:
            out.append((at, copy.deepcopy(current)))
    return out


def _load_cells(spec, layout, path):
    if spec is None:
        return None
    if not isinstance(spec, dict):
        raise ScenarioError(f'{path}: field load_cells: give rate, noise and bias')
    rate = _number(spec, 'rate', 250.0, f'{path}: field load_cells', limits.SAMPLE_RATE)
    _number(spec, 'noise', 0.0, f'{path}: field load_cells', limits.NOISE)
    bias = spec.get('bias') or {}
    names = [s.name for s in layout.supports]
    for name, value in bias.items():
        if name not in names or not isinstance(value, list) or len(value) != 3:
            raise ScenarioError(f'{path}: field load_cells.bias: give [x, y, z] N for '
                                f'supports of the layout ({", ".join(names)}), got {name!r}')
    return {'rate': rate, 'noise': float(spec.get('noise', 0.0)),
            'bias': {name: [float(v) for v in bias.get(name, (0.0, 0.0, 0.0))]
                     for name in names}}


def write_bag(scenario, output, compression='zstd', chunk_bytes=1 << 16, machine_id=None,
              label=None):
    """
    Write the scenario's input bag (.mcap file or rosbag2 directory): /layout, /joint_states.

    ``machine_id``: the machine the run is recorded on, ``label``: what run it is in a
    field-balancing visit (:mod:`cvc_balance.bag.run_label`), both written into the bag
    (:mod:`cvc_balance.bag.machine`).
    """
    stamps = scenario.stamps_ns()
    angle, omega = scenario.measured()
    with open_writer(output, compression=compression, chunk_bytes=chunk_bytes,
                     custom_data=custom_data(machine_id, label)) as writer:
        layout_channel = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        joint_channel = writer.add_channel('/joint_states', 'sensor_msgs/msg/JointState',
                                           best_effort=True)
        for at, mapping in scenario.layouts:
            # A layout change goes out half a sample before the sample it first applies to.
            log_time = int(round((scenario.start + at - 0.5 / scenario.rate) * 1e9))
            writer.write(layout_channel, log_time,
                         string_message(dump_document(mapping)))
        block = MessageBlock([(joint_channel, joint_state_layout('', [scenario.joint_name]))],
                             len(stamps))
        block.array['0.sec'], block.array['0.nanosec'] = np.divmod(stamps, 1_000_000_000)
        block.array['0.position_0'], block.array['0.velocity_0'] = angle, omega
        writer.write_block(block, stamps)
        if scenario.cells is not None:
            for name, (cell_stamps, force, torque) in scenario.cell_readings().items():
                channel = writer.add_channel(f'/{topics.measured_load(name)}',
                                             topics.WRENCH_TYPE, best_effort=True)
                block = MessageBlock([(channel, wrench_stamped_layout(STATOR_FRAME))],
                                     len(cell_stamps))
                block.array['0.sec'], block.array['0.nanosec'] = np.divmod(cell_stamps,
                                                                           1_000_000_000)
                for i, axis in enumerate('xyz'):
                    block.array[f'0.force_{axis}'] = force[:, i]
                    block.array[f'0.torque_{axis}'] = torque[:, i]
                writer.write_block(block, cell_stamps)
    return len(stamps)
