"""
Mistakes in a recorded run's inputs, said offline by replay as the node says them live.

Issue 26, point 3: the checks of cvc_balance/identify/mistakes.py (a joint position in
degrees, a velocity in rpm, a cell's scale or support) ran in the node only; a bag
recorded with such a mistake replayed without a word. The run of test/tach_bags.py
(exact encoder, load cells under both supports) is rewritten here with one mistake each,
its messages decoded and encoded again by rosbags: the position in degrees, the velocity
in rpm, the front cell in kN, the rear cell's sign reversed. The expected figures are by
hand: 180 / pi = 57.30, pi / 30 = 0.1047, 1 / 1000 (and the cell's zero offset, scaled
too: 360 N on a share of 3583 N), -1.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import tach_bags
from in_process import run_cli

ROOT = Path(__file__).resolve().parents[1]
JOINT_STATE, WRENCH = 'sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped'


def rewrite(msg_type, change, topic):
    """Return a merge() change: decode with rosbags, ``change(msg)``, encode, on ``topic``."""
    def apply(log_time, data):
        msg = tach_bags.TYPESTORE.deserialize_cdr(data, msg_type)
        change(msg)
        return topic, tach_bags.serialized(msg, msg_type)
    return apply


def degrees(msg):
    msg.position = np.degrees(msg.position)         # wrapped at +-180 as it came


def rpm(msg):
    msg.velocity = msg.velocity * 30.0 / math.pi


def scaled(factor):
    def change(msg):
        for axis in 'xyz':
            setattr(msg.wrench.force, axis, getattr(msg.wrench.force, axis) * factor)
    return change


MISTAKES = {
    'degrees': {'/joint_states': rewrite(JOINT_STATE, degrees, '/joint_states')},
    'rpm': {'/joint_states': rewrite(JOINT_STATE, rpm, '/joint_states')},
    'kN': {'/supports/front/measured_load': rewrite(WRENCH, scaled(1e-3),
                                                    '/supports/front/measured_load')},
    'sign': {'/supports/rear/measured_load': rewrite(WRENCH, scaled(-1.0),
                                                     '/supports/rear/measured_load')},
}


@pytest.fixture(scope='module')
def encoder(tmp_path_factory):
    folder = tmp_path_factory.mktemp('mistakes')
    return tach_bags.write_run(folder, ROOT)[1]


def test_a_correct_run_has_no_input_check(encoder):
    code, out, err = run_cli('replay', encoder, '--json')
    assert code == 0, err
    assert json.loads(out)['input_checks'] == []


@pytest.mark.parametrize('mistake', sorted(MISTAKES))
def test_a_mistake_in_the_bag_is_said_by_replay(encoder, mistake, tmp_path):
    bag = tach_bags.merge(tmp_path / f'{mistake}.mcap', encoder, change=MISTAKES[mistake])
    code, out, err = run_cli('replay', bag, '--json')
    assert code == 0, err
    record = json.loads(out)
    [check] = record['input_checks']
    if mistake in ('degrees', 'rpm'):
        seen, judged = check['windows']
        assert check['input'] == '/joint_states' and check['segment'] is None
        assert seen == judged >= 10            # every window of the run that could tell
        expected = 180.0 / math.pi if mistake == 'degrees' else math.pi / 30.0
        assert check['figure'] == pytest.approx(expected, rel=0.01)
    else:
        assert check['input'] == 'load cells' and check['segment'] == 1
    assert check['cause'] == mistake
    messages = {
        'degrees': 'joint position looks like degrees: its rate is 57.3 x the velocity, '
                   'and it wraps at 360',
        'rpm': "joint velocity looks like rpm: it is 9.55 x the position's rate",
        'kN': "cell front reads 1/1000 of its support's static load: kN for N? (",
        'sign': "cell rear reads its support's static load with the sign reversed ("}
    assert check['message'].startswith(messages[mistake]), check['message']
    if mistake == 'kN':
        assert check['figure'] == pytest.approx(1e-3, rel=0.12)
    if mistake == 'sign':
        assert check['figure'] == pytest.approx(-1.0, rel=0.05)
    code, text, err = run_cli('replay', bag)
    assert code == 0, err
    where = (f"/joint_states ({check['windows'][0]} of {check['windows'][1]} windows of 2000 "
             'samples)' if check['segment'] is None else 'load cells of segment 1')
    lines = [line for line in text.splitlines() if line.startswith('  input check: ')]
    assert lines == [f"  input check: {where}: {check['message']}"]
