"""
The node's load cells (:mod:`cvc_balance.ros.load_cells`) in this process, against Pinocchio.

The node subscribes to each support's cell and publishes what the live fit identified
(test/test_identify_live.py runs the node in another process, which a mutation run cannot
see). Here the same object is given a stand-in node and WrenchStamped bytes rclpy itself
serialises: the cells read the support loads of the TRUE rotor (the CT gantry and a mass
its layout does not list), computed by Pinocchio's RNEA and split by statics by hand
(test/independent.py), at a constant 20 rad/s. What it publishes at each revolution must
be Pinocchio's unbalance wrench of the true rotor, and the residual that of the mass the
layout misses; its status's numbers the planes of that mass by hand (ISO 21940-2).
"""

import cmath
import copy
from functools import partial
import math
from pathlib import Path

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from rclpy.serialization import serialize_message
import yaml

from cvc_balance.identify.evidence import verdict_of_record
from cvc_balance.physics import assessment
from cvc_balance.physics.engine import RotorModel
from cvc_balance.physics.layout import parse_layout
from cvc_balance.ros.load_cells import LoadCells
from independent import PinocchioRotor
from reference import component_planes_by_hand

ROOT = Path(__file__).resolve().parents[1]
GANTRY = yaml.safe_load((ROOT / 'config' / 'ct_gantry.yaml').read_text())
HIDDEN = {'name': 'as_built', 'mass': 0.08, 'radius': 0.6, 'angle_deg': 30.0, 'z': 0.1}
OMEGA, RATE = 20.0, 500.0
ORIGIN_S = 1_700_000_000


class Node:
    """What LoadCells asks of its node: subscriptions, recorded."""

    def __init__(self):
        self.subscriptions, self.destroyed = [], []

    def create_subscription(self, msg_type, topic, callback, qos, raw):
        self.subscriptions.append((msg_type, topic, callback, qos, raw))
        return f'subscription {len(self.subscriptions)}'

    def destroy_subscription(self, subscription):
        self.destroyed.append(subscription)


def wrench(sec, nanosec, force, torque=(0.0, 0.0, 0.0)):
    message = WrenchStamped()
    message.header.stamp.sec, message.header.stamp.nanosec = sec, nanosec
    message.header.frame_id = 'cell'
    (message.wrench.force.x, message.wrench.force.y, message.wrench.force.z) = map(float, force)
    (message.wrench.torque.x, message.wrench.torque.y,
     message.wrench.torque.z) = map(float, torque)
    return bytes(serialize_message(message))


def true_layout(base=GANTRY):
    true = copy.deepcopy(base)
    true['components'].append(dict(HIDDEN))
    return true


def run(cells, turns, base=GANTRY, read=None):
    """
    Turn at OMEGA for ``turns`` revolutions: each sample's motion, then every cell.

    Each cell reads its support's force and moment (a single support's moment about it);
    ``read``: the samples the cells read (default all).
    """
    rotor = PinocchioRotor(true_layout(base))
    steps = int(turns * 2 * math.pi / OMEGA * RATE)
    for j in range(steps + 1):
        ns = round(j * 1e9 / RATE)
        sec, nanosec = ORIGIN_S + ns // 10**9, ns % 10**9
        angle = OMEGA * j / RATE
        cells.motion(sec, nanosec, math.remainder(angle, 2 * math.pi), OMEGA, 0.0)
        if read is None or j < read:
            for name, (force, moment) in rotor.loads(angle, OMEGA, 0.0)['supports'].items():
                cells._on_reading(name, wrench(sec, nanosec, force, moment))
    return steps


def test_the_cells_subscribed_and_let_go():
    node = Node()
    model = RotorModel.from_layout(parse_layout(GANTRY))
    cells = LoadCells(node, model, 3, 'qos', None)
    assert [(kind, topic, qos, raw) for kind, topic, _, qos, raw in node.subscriptions] == [
        (WrenchStamped, 'supports/front/measured_load', 'qos', True),
        (WrenchStamped, 'supports/rear/measured_load', 'qos', True)]
    callback = node.subscriptions[1][2]
    assert isinstance(callback, partial) and callback.args == ('rear',)
    assert callback.func == cells._on_reading
    assert cells.readings == {'front': 0, 'rear': 0} and cells.found is None
    assert cells.estimate is None and cells.diagnose(None) is None
    assert cells.fit.window_revs == 3 and cells.fit.g_z == 0.0
    cells.close()
    assert node.destroyed == ['subscription 1', 'subscription 2'] and cells._subscriptions == []
    cells.close()
    assert len(node.destroyed) == 2


def test_readings_counted_dropped_or_left_out():
    model = RotorModel.from_layout(parse_layout(GANTRY))
    emitted = []
    cells = LoadCells(Node(), model, 3, 'qos', lambda *args: emitted.append(args))
    cells.motion(ORIGIN_S, 0, 0.0, OMEGA, 0.0)
    cells._on_reading('front', wrench(ORIGIN_S, 40_000_000, (1.0, 2.0, 3.0)))
    # A two-support rotor's cells: their torque is not the fit's (not even 2e12 N m).
    cells._on_reading('rear', wrench(ORIGIN_S, 0, (1.0, 2.0, 3.0), (2e12, 0.0, 0.0)))
    cells._on_reading('rear', wrench(ORIGIN_S, 60_000_000, (1.0, 2.0, 3.0)))   # too late
    cells._on_reading('rear', b'\x00\x01\x00\x00' + bytes(8))
    cells._on_reading('rear', b'\x00\x00\x00\x00' + wrench(ORIGIN_S, 0, (1, 2, 3))[4:])
    # Dropped: the two unreadable and the one too late for the latest motion sample.
    assert cells.readings == {'front': 1, 'rear': 1} and cells.fit.dropped == 3
    # Readings but no revolution yet: an estimate that cannot tell, nothing published.
    estimate = cells.estimate
    assert (estimate.identifiable, estimate.readings, estimate.sigma) == (False, 2, math.inf)
    assert emitted == [] and cells.found is None
    of_record = verdict_of_record(model, estimate, OMEGA)
    level, message, values = cells.diagnose(of_record)
    assert (level, message) == (assessment.NOT_JUDGED, of_record.reason)
    assert values == {'cell front readings': 1, 'cell rear readings': 1,
                      'cell readings dropped': 3}


def expected_wrenches(base=GANTRY):
    """
    Return the identified and residual wrenches by Pinocchio, about the layout's centre.

    The fit can only refer the couple to the centre of mass its layout declares (the
    hidden 80 g moves the true one by 8.6 um): the true products of inertia about O
    (Pinocchio's about its centre of mass, moved by the parallel-axis rule: P_O = P_c +
    m c_x c_z), less z_declared m c_xy.
    """
    mass, com, inertia = PinocchioRotor(true_layout(base)).mass_properties()
    _, declared_com, _ = PinocchioRotor(base).mass_properties()
    p_xz = -inertia[0, 2] + mass * com[0] * com[2] - declared_com[2] * mass * com[0]
    p_yz = -inertia[1, 2] + mass * com[1] * com[2] - declared_com[2] * mass * com[1]
    w2 = OMEGA ** 2
    force = np.array([w2 * mass * com[0], w2 * mass * com[1], 0.0])
    torque = np.array([-w2 * p_yz, w2 * p_xz, 0.0])
    declared_force, declared_torque = PinocchioRotor(base).unbalance(OMEGA)
    return (force, torque), (force - declared_force, torque - declared_torque)


def test_each_revolution_publishes_the_true_rotors_unbalance_and_what_the_layout_misses():
    """
    Publish the identified and residual unbalance at each revolution, against Pinocchio.

    2.5 revolutions at 20 rad/s: at each of the two completed the wrench of the true rotor
    (force U omega^2, torque omega^2 (-P_yz, P_xz, 0), rotor frame) and the residual, the
    hidden mass's: force m r omega^2 at 30 degrees.
    """
    model = RotorModel.from_layout(parse_layout(GANTRY))
    emitted = []
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: emitted.append(args))
    steps = run(cells, 2.5)
    assert cells.readings == {'front': steps + 1, 'rear': steps + 1}
    identified, missed = expected_wrenches()
    hidden = HIDDEN['mass'] * HIDDEN['radius'] * OMEGA ** 2
    angle = math.radians(HIDDEN['angle_deg'])
    assert np.allclose(missed[0], [hidden * math.cos(angle), hidden * math.sin(angle), 0.0],
                       rtol=1e-9)
    assert [(topic, sec) for topic, sec, *_ in emitted] == [
        ('identified_unbalance', ORIGIN_S), ('unbalance_residual', ORIGIN_S)] * 2
    scale = np.abs(identified[0]).max()
    for k, revolution in enumerate((1, 2)):
        # The sample that completed the revolution: the first past 2 pi k rad.
        j = math.ceil(revolution * 2 * math.pi / OMEGA * RATE)
        for (topic, sec, nanosec, force, torque), (want_force, want_torque) in zip(
                emitted[2 * k:2 * k + 2], (identified, missed)):
            assert nanosec == round(j * 1e9 / RATE), topic
            assert np.allclose(force, want_force, rtol=0, atol=1e-7 * scale), (topic, force)
            assert np.allclose(torque, want_torque, rtol=0, atol=1e-7 * scale), topic
    estimate = cells.estimate
    assert estimate is cells.found[0] and estimate.identifiable


def test_the_cells_status_says_the_measured_rotor_and_what_its_layout_misses():
    """
    Say the measured verdict and each plane, measured and missed, against the hand values.

    The planes of the true rotor's point components and of the hidden mass by the lever
    rule (ISO 21940-2), each plane's permissible share of G 6.3 at 23.27 rad/s (U_per = G m
    / Omega, shared by the levers about the centre of mass, within 0.3-0.7) and the grade
    achieved, 6.3 max(U_p / share_p); the fit's floor: its sigma under 1e-7 of the weight
    (normal equations of 9 kN loads), its 95 % radii under 1 g mm.
    """
    model = RotorModel.from_layout(parse_layout(GANTRY))
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: None)
    run(cells, 2.2)
    true = true_layout()
    components = GANTRY['components']
    planes = GANTRY['balancing']['planes']
    mass = sum(c['mass'] for c in components)
    z_com = sum(c['mass'] * c.get('z', 0.0) for c in components) / mass
    u_per = 6.3e-3 * mass / 23.27
    shares = [u_per * min(max(lever, 0.3), 0.7) for lever in (
        (planes[1] - z_com) / (planes[1] - planes[0]),
        (z_com - planes[0]) / (planes[1] - planes[0]))]
    static = sum(c['mass'] * c['radius'] * cmath.exp(1j * math.radians(c['angle_deg']))
                 for c in true['components'])
    found = component_planes_by_hand(true['components'], planes)
    missed = component_planes_by_hand([HIDDEN], planes)
    grade = 6.3 * max(abs(u) / share for u, share in zip(found, shares))
    of_record = verdict_of_record(model, cells.estimate, OMEGA)
    level, message, values = cells.diagnose(of_record)
    text = f'G {grade:.3g} at the service speed 23.27 rad/s: WITHIN G 6.3'
    assert (level, message) == (assessment.OK, f'measured: {text}')
    assert values['cell front readings'] == values['cell rear readings'] > 0
    assert values['cell readings dropped'] == 0
    assert values['fit window [rev]'] == 2 and values['fit readings'] > 0
    assert values['fit sigma [N]'] < 1e-7 * mass * 9.80665
    assert values['measured verdict'] == text
    assert values['measured static [g mm]'] == pytest.approx(abs(static) * 1e6, rel=1e-6)
    assert abs(values['measured static angle [deg]']
               - math.degrees(cmath.phase(static)) % 360) < 1e-5
    assert values['measured static 95% radius [g mm]'] < 1.0
    for label, got, off, share in zip(('I', 'II'), found, missed, shares):
        assert values[f'measured plane {label} [g mm]'] == pytest.approx(
            abs(got) * 1e6, rel=1e-6)
        assert abs(values[f'measured plane {label} angle [deg]']
                   - math.degrees(cmath.phase(got)) % 360) < 1e-5
        assert values[f'measured plane {label} 95% radius [g mm]'] < 1.0
        assert values[f'residual plane {label} [g mm]'] == pytest.approx(
            abs(off) * 1e6, rel=1e-6)
        assert abs(values[f'residual plane {label} angle [deg]'] - 30.0) < 1e-5
        assert values[f'residual plane {label} / permissible'] == pytest.approx(
            abs(off) / share, rel=1e-6)
    assert abs(missed[0]) * 1e6 == pytest.approx(4000.0) and \
        abs(missed[1]) * 1e6 == pytest.approx(44000.0)


def test_a_single_supports_cell_moment_is_fitted_too():
    """One support (its cell reads the moment about it): the couple is identified too."""
    one = copy.deepcopy(GANTRY)
    one['supports'] = [{'name': 'hub', 'z': 0.0, 'axial': True}]
    model = RotorModel.from_layout(parse_layout(one))
    emitted = []
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: emitted.append(args))
    run(cells, 1.2, one)
    identified, missed = expected_wrenches(one)
    ((_, _, _, force, torque), (_, _, _, off_force, off_torque)) = emitted
    scale = np.abs(identified[0]).max()
    assert np.allclose(force, identified[0], rtol=0, atol=1e-7 * scale)
    assert np.allclose(torque, identified[1], rtol=0, atol=1e-7 * scale)
    assert np.allclose(off_torque, missed[1], rtol=0, atol=1e-7 * scale)
    assert np.linalg.norm(missed[1]) > 0.5                   # the hidden mass's couple


def test_nothing_is_fitted_before_a_whole_revolution_or_from_readings_that_cannot_tell():
    model = RotorModel.from_layout(parse_layout(GANTRY))
    emitted = []
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: emitted.append(args))
    steps = run(cells, 0.9)
    estimate = cells.estimate
    assert cells.found is None and emitted == []
    assert (estimate.identifiable, estimate.readings) == (False, 2 * (steps + 1))
    # One reading a cell (4 real numbers for 8 unknowns): a revolution gives a fit that
    # cannot tell; the status says why, nothing is published.
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: emitted.append(args))
    run(cells, 1.1, read=1)
    assert cells.found is not None and not cells.estimate.identifiable and emitted == []
    of_record = verdict_of_record(model, cells.estimate, OMEGA)
    assert of_record.measured is None
    level, message, values = cells.diagnose(of_record)
    assert (level, message) == (assessment.NOT_JUDGED, of_record.reason)
    assert values == {'cell front readings': 1, 'cell rear readings': 1,
                      'cell readings dropped': 0}


def test_the_status_says_why_the_measurement_is_not_yet_the_verdict_and_what_disagrees():
    model = RotorModel.from_layout(parse_layout(GANTRY))
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: None)
    run(cells, 1.1)
    # The residual plane II (29 % of its share) over a 1 % warning: a disagreement.
    of_record = verdict_of_record(model, cells.estimate, OMEGA, residual_warn=0.01)
    assert of_record.source == 'measured' and of_record.disagreements
    level, message, _ = cells.diagnose(of_record)
    assert (level, of_record.measured.level) == (assessment.WARN, assessment.OK)
    assert message == f'measured: {of_record.measured.text}; {of_record.disagreement_text}'
    # Where the layout's verdict stands, the cells' status is the measured rotor's level.
    from dataclasses import replace
    standing = replace(of_record, source='layout', level=assessment.ERROR, disagreements=(),
                       reason='the layout was just changed')
    level, message, _ = cells.diagnose(standing)
    assert level == assessment.OK
    assert message == (f'measured: {of_record.measured.text} (not yet the verdict of record: '
                       'the layout was just changed)')
    # No service speed and the rotor not turned: the layout's verdict stands, said why.
    plain = copy.deepcopy(GANTRY)
    del plain['balancing']['service_speed']
    model = RotorModel.from_layout(parse_layout(plain))
    cells = LoadCells(Node(), model, 2, 'qos', lambda *args: None)
    run(cells, 1.1, plain)
    of_record = verdict_of_record(model, cells.estimate, 0.0)
    assert of_record.source == 'layout' and of_record.measured.assessment is None
    level, message, values = cells.diagnose(of_record)
    assert level == of_record.measured.level
    assert message == (f'measured: {of_record.measured.text} (not yet the verdict of record: '
                       'no service speed and the rotor has not turned)')
    assert 'residual plane I / permissible' not in values
    assert values['residual plane II [g mm]'] == pytest.approx(44000.0, rel=1e-6)
