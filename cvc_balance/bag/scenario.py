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

The motion is exact (piecewise constant alpha); the bag's samples are that
motion plus Gaussian noise. Times in the bag start at ``start`` (s, default 1).
"""

import copy
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np
import yaml

from cvc_balance.bag.mcap_writer import BagWriter, MessageBlock
from cvc_balance.messages.cdr import joint_state_layout, string_message
from cvc_balance.physics.frames import radians, STANDARD_GRAVITY, wrap_angle
from cvc_balance.physics.layout import LayoutError, parse_layout


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

    def measured(self):
        """Return the encoder's angle (wrapped to [-pi, pi]) and speed: motion plus noise."""
        rng = np.random.default_rng(self.seed)
        angle = self.angle + rng.normal(0.0, self.noise_angle, len(self.time))
        omega = self.omega + rng.normal(0.0, self.noise_speed, len(self.time))
        return wrap_angle(angle), omega

    def stamps_ns(self):
        """Sample stamps, ns."""
        return np.round((self.start + self.time) * 1e9).astype(np.int64)


def load_scenario(path):
    """Read and check a scenario file; raises :class:`ScenarioError`."""
    path = Path(path)
    try:
        spec = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise ScenarioError(f'{path}: cannot read scenario: {error}') from None
    if not isinstance(spec, dict):
        raise ScenarioError(f'{path}: a scenario is a mapping')
    if 'components' in spec and 'profile' not in spec:
        raise ScenarioError(f'{path}: this is a layout file (it has components), not a '
                            'scenario; a scenario names a layout (layout: FILE) and gives a '
                            'speed profile, e.g. bags/spin_up_tube_swap.yaml')
    known = {'name', 'layout', 'joint_name', 'rate', 'seed', 'noise', 'profile', 'events',
             'start'}
    for key in spec:
        if key not in known:
            raise ScenarioError(f'{path}: unknown field {key!r} (known: {", ".join(known)})')
    layout = spec.get('layout')
    if isinstance(layout, str):
        try:
            layout = yaml.safe_load((path.parent / layout).read_text())
        except (OSError, yaml.YAMLError) as error:
            raise ScenarioError(f'{path}: layout {spec["layout"]}: {error}') from None
    if not isinstance(layout, dict):
        raise ScenarioError(f'{path}: field layout: give a layout file path or mapping')
    rate = float(spec.get('rate', 500.0))
    if not rate > 0:
        raise ScenarioError(f'{path}: field rate must be > 0')
    time, angle, omega = _motion(spec.get('profile') or [], rate, path)
    layouts = _layouts(layout, spec.get('events') or [], path)
    noise = spec.get('noise') or {}
    return Scenario(str(spec.get('name', path.stem)), str(spec.get('joint_name', 'gantry_joint')),
                    rate, float(spec.get('start', 1.0)), time, angle, omega, layouts,
                    float(noise.get('angle', 0.0)), float(noise.get('speed', 0.0)),
                    int(spec.get('seed', 0)))


def _motion(profile, rate, path):
    """Exact motion: piecewise constant alpha segments from rest."""
    pieces, omega = [], 0.0
    for i, step in enumerate(profile):
        kind = step.get('type') if isinstance(step, dict) else None
        if kind in ('spin_up', 'coast_down', 'ramp'):
            alpha, target = float(step['alpha']), float(step['to'])
            duration = (target - omega) / alpha if alpha else -1.0
            if not duration > 0:
                raise ScenarioError(f'{path}: profile step {i + 1} ({kind}): alpha {alpha} '
                                    f'does not take {omega} rad/s to {target} rad/s')
        elif kind == 'steady':
            alpha, duration = 0.0, float(step['duration'])
        else:
            raise ScenarioError(f'{path}: profile step {i + 1}: type must be spin_up, steady, '
                                f'coast_down or ramp, got {kind!r}')
        pieces.append((duration, alpha))
        omega += alpha * duration
    if not pieces:
        raise ScenarioError(f'{path}: field profile: needs at least one step')
    total = sum(d for d, _ in pieces)
    time = np.arange(int(total * rate) + 1) / rate
    angle, omega_t = np.zeros_like(time), np.zeros_like(time)
    t0 = q0 = w0 = 0.0
    for duration, alpha in pieces:
        inside = (time >= t0) & (time <= t0 + duration)
        dt = time[inside] - t0
        angle[inside] = q0 + w0 * dt + 0.5 * alpha * dt * dt
        omega_t[inside] = w0 + alpha * dt
        q0 += w0 * duration + 0.5 * alpha * duration * duration
        w0 += alpha * duration
        t0 += duration
    return time, angle, omega_t


def _layouts(layout, events, path):
    """Return the layout mapping in force from each event's time (validated)."""
    current = copy.deepcopy(layout)
    out = [(0.0, copy.deepcopy(current))]
    for i, event in enumerate(sorted(events, key=lambda e: float(e.get('at', 0.0)))):
        at = float(event.get('at', -1.0))
        if not at > 0:
            raise ScenarioError(f'{path}: event {i + 1}: field at must be a time > 0 s')
        if 'set' in event:
            change = dict(event['set'])
            name = change.pop('component', None)
            matches = [c for c in current['components'] if c.get('name') == name]
            if not matches:
                raise ScenarioError(f'{path}: event {i + 1}: no component {name!r}')
            if 'angle_deg' in change:
                matches[0].pop('angle', None)
            if 'angle' in change:
                matches[0].pop('angle_deg', None)
            matches[0].update(change)
        if 'tilt_deg' in event:
            tilt = radians(float(event['tilt_deg']))
            current['gravity'] = [0.0, -STANDARD_GRAVITY * math.cos(tilt),
                                  STANDARD_GRAVITY * math.sin(tilt)]
        try:
            parse_layout(current)
        except LayoutError as error:
            raise ScenarioError(f'{path}: event {i + 1} makes a bad layout: {error}') from None
        out.append((at, copy.deepcopy(current)))
    return out


def write_bag(scenario, output, compression='zstd', chunk_bytes=1 << 16):
    """Write the scenario's input bag: /layout (latched) and /joint_states."""
    stamps = scenario.stamps_ns()
    angle, omega = scenario.measured()
    with BagWriter(output, compression=compression, chunk_bytes=chunk_bytes) as writer:
        layout_channel = writer.add_channel('/layout', 'std_msgs/msg/String', latched=True)
        joint_channel = writer.add_channel('/joint_states', 'sensor_msgs/msg/JointState',
                                           best_effort=True)
        for at, mapping in scenario.layouts:
            # A layout change goes out half a sample before the sample it first applies to.
            log_time = int(round((scenario.start + at - 0.5 / scenario.rate) * 1e9))
            writer.write(layout_channel, log_time,
                         string_message(yaml.safe_dump(mapping, sort_keys=False)))
        block = MessageBlock([(joint_channel, joint_state_layout('', [scenario.joint_name]))],
                             len(stamps))
        block.array['0.sec'], block.array['0.nanosec'] = np.divmod(stamps, 1_000_000_000)
        block.array['0.position_0'], block.array['0.velocity_0'] = angle, omega
        writer.write_block(block, stamps)
    return len(stamps)
