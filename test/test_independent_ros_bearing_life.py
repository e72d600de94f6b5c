"""
The node's bearing life (:mod:`cvc_balance.ros.bearing_life`) in this process, by hand.

The node counts each bearing's life live and keeps it in a state file across restarts
(test/test_bearing_life.py runs the node itself, in another process, which a mutation run
cannot see). Here the same object is given layouts, samples and state files by hand: a
turn a second at 2 pi rad/s under constant loads, so each step is one revolution and the
damage of a step is ISO 281's (P / C)^p worked out here (ball p = 3, roller p = 10/3), the
life used damage / 10^6 / a1; each status line, value and state file as people read them.
"""

from dataclasses import asdict
from datetime import datetime, timedelta, timezone
import json
import math
import os

import pytest

from cvc_balance.physics import assessment
from cvc_balance.physics.layout import Bearing, Support
from cvc_balance.ros.bearing_life import BearingLife, read_state, state_path

KIND = 'cvc_balance bearing life'
BALL = Bearing(C=10000.0, limit_speed=50.0)
ROLLER = Bearing(C=20000.0, type='roller', a1=0.5)
SUPPORTS = (Support('front', -0.1, bearing=BALL), Support('rear', 0.1, bearing=ROLLER),
            Support('idler', 0.3))
TWO_PI = 2.0 * math.pi
LOADS = {'front': ((3000.0, 4000.0, 0.0), None), 'rear': ((0.0, -10000.0, 0.0), None),
         'idler': ((1.0, 1.0, 0.0), None)}
FRONT_RATE = 0.5 ** 3            # P = 5000 N of C = 10000 N, a ball bearing
REAR_RATE = 0.5 ** (10.0 / 3.0)  # 10000 N of 20000 N, a roller bearing


def turns(life, count, start=0.0):
    """Feed ``count`` + 1 samples a second apart, a revolution between each two."""
    for k in range(count + 1):
        t = start + k
        life.counting.add_sample(t, TWO_PI * t, TWO_PI, LOADS)


def logged():
    said = []
    return said, lambda severity, text: said.append((severity, text))


def state(path, supports):
    path.write_text(json.dumps({'kind': KIND, 'version': 1, 'supports': supports}))
    return path


def test_the_state_file_is_named_for_the_machine_beside_the_recording(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert state_path('runs/a.mcap', 'gantry 7/b') == tmp_path / 'runs' / \
        'bearing_life_gantry_7_b.json'
    assert state_path(tmp_path / 'x' / 'bag', 'Site-2.m_1') == tmp_path / 'x' / \
        'bearing_life_Site-2.m_1.json'
    assert state_path('a.mcap', '..') == tmp_path / 'bearing_life_node.json'
    assert state_path('a.mcap', '._m é_.') == tmp_path / 'bearing_life_m.json'
    assert state_path('a.mcap', 'a  b') == tmp_path / 'bearing_life_a_b.json'
    assert state_path('a.mcap', 'X-ray X') == tmp_path / 'bearing_life_X-ray_X.json'
    assert state_path('a.mcap', '') == tmp_path / 'bearing_life_node.json'


def test_a_state_file_read_back_or_refused_in_its_words(tmp_path):
    path = tmp_path / 'state.json'
    assert read_state(path) == {}
    bearing = asdict(BALL)
    state(path, {'front': {'bearing': bearing, 'revolutions': 10, 'damage': 2.5,
                           'seconds': 0}})
    ((name, read),) = read_state(path).items()
    assert name == 'front' and read == (bearing, 10.0, 2.5, 0.0)
    assert all(type(v) is float for v in read[1:])
    not_one = f"{path}: not a bearing life state file (kind '{KIND}')"
    for data in ([], {'kind': 'other', 'supports': {}}, {'supports': {}},
                 {'kind': KIND, 'supports': []}, {'kind': KIND}):
        path.write_text(json.dumps(data))
        with pytest.raises(ValueError) as caught:
            read_state(path)
        assert str(caught.value) == not_one
    bad = (f"{path}: support 'front': give bearing and revolutions, damage, seconds "
           '(finite, >= 0)')
    good = {'bearing': bearing, 'revolutions': 1.0, 'damage': 1.0, 'seconds': 1.0}
    missing = {k: v for k, v in good.items() if k != 'revolutions'}
    for entry in (3, {**good, 'bearing': 'ball'}, missing, {**good, 'damage': True},
                  {**good, 'seconds': -1e-300}, {**good, 'revolutions': '1'},
                  {**good, 'damage': None}):
        path.write_text(json.dumps({'kind': KIND, 'supports': {'front': entry}}))
        with pytest.raises(ValueError) as caught:
            read_state(path)
        assert str(caught.value) == bad, entry
    for value in ('Infinity', 'NaN'):
        path.write_text('{"kind": "%s", "supports": {"front": {"bearing": {}, '
                        '"revolutions": 1, "damage": %s, "seconds": 1}}}' % (KIND, value))
        with pytest.raises(ValueError) as caught:
            read_state(path)
        assert str(caught.value) == bad


def test_a_state_file_that_is_no_file_is_said_once_with_its_path(tmp_path):
    folder = tmp_path / 'state.json'
    folder.mkdir()
    with pytest.raises(ValueError) as caught:
        read_state(folder)
    assert str(caught.value) == f'{folder}: a directory, not a regular file: refused'
    link = tmp_path / 'gone.json'
    link.symlink_to(tmp_path / 'nowhere.json')
    with pytest.raises(ValueError) as caught:
        read_state(link)
    assert str(caught.value) == f'{link}: No such file or directory'
    big = tmp_path / 'big.json'
    big.write_text(' ' * ((1 << 20) + 1))
    with pytest.raises(ValueError) as caught:
        read_state(big)
    assert str(caught.value) == f'{big}: 1048577 bytes, over the limit of 1048576 bytes'


def test_each_bearing_counted_and_said_by_hand(tmp_path):
    said, log = logged()
    life = BearingLife(None, log)
    assert life.status(0.0) is None                         # no layout yet
    life.layout(SUPPORTS)
    assert set(life.counting.counters) == {'front', 'rear'}
    turns(life, 2)
    level, message, values = life.status(50.0)             # at the limit, not over it
    assert values.pop('state file') == 'none (the node does not record: counted since start)'
    front = 2 * FRONT_RATE / 1e6                            # 2 revolutions, a1 = 1
    rear = 2 * REAR_RATE / 1e6 / 0.5
    hours = 2.0 / 3600.0
    assert level == assessment.OK and said == []
    assert message == ('bearing life: front 2.5e-07 used since start (0.00045/h: rating '
                       'life 2222 h at this duty), 2.5e-07 in all; rear 3.97e-07 used since '
                       'start (0.000714/h: rating life 1400 h at this duty), 3.97e-07 in all')
    assert values == pytest.approx({
        'front life used since start': front, 'front life used in all': front,
        'front life used per hour of running': front / hours,
        'front rating life at this duty [h]': hours / front,
        'front life left at this duty [h]': (1.0 - front) / (front / hours),
        'front mean equivalent load since start [N]': 5000.0,
        'front revolutions since start': 2.0, 'front hours of running since start': hours,
        'rear life used since start': rear, 'rear life used in all': rear,
        'rear life used per hour of running': rear / hours,
        'rear rating life at this duty [h]': hours / rear,
        'rear life left at this duty [h]': (1.0 - rear) / (rear / hours),
        'rear mean equivalent load since start [N]': 10000.0,
        'rear revolutions since start': 2.0, 'rear hours of running since start': hours},
        rel=1e-12)
    level, message, _ = life.status(50.5)
    assert level == assessment.WARN
    assert message.startswith('bearing life: front: speed 50.5 rad/s over its limiting speed '
                              '50 rad/s; front 2.5e-07 used since start')
    life.save()                                             # no path: nothing written
    assert list(tmp_path.iterdir()) == []


def test_no_turn_yet_says_no_rate_and_no_load():
    life = BearingLife()
    life.layout(SUPPORTS[:1])
    life.counting.add_sample(0.0, 0.0, 0.0, LOADS)
    level, message, values = life.status(0.0)
    assert (level, message) == (assessment.OK, 'bearing life: front 0 used since start, 0 in '
                                               'all')
    assert values == {'front life used since start': 0.0, 'front life used in all': 0.0,
                      'front life used per hour of running': '',
                      'front rating life at this duty [h]': '',
                      'front life left at this duty [h]': '',
                      'front mean equivalent load since start [N]': '',
                      'front revolutions since start': 0.0,
                      'front hours of running since start': 0.0,
                      'state file': 'none (the node does not record: counted since start)'}
    life.layout([Support('front', 0.0)])                    # no bearing described: none
    assert life.counting is None and life.status(0.0) is None


def test_counts_go_on_from_the_state_file_and_across_layouts(tmp_path):
    path = state(tmp_path / 'state.json', {
        'front': {'bearing': asdict(BALL), 'revolutions': 1000.0, 'damage': 100.0,
                  'seconds': 3600.0},
        'rear': {'bearing': asdict(Bearing(C=1.0)), 'revolutions': 5.0, 'damage': 5.0,
                 'seconds': 5.0},
        'spare': {'bearing': {'C': 1.0}, 'revolutions': 7.0, 'damage': 6.0, 'seconds': 5.0}})
    said, log = logged()
    life = BearingLife(path, log)
    life.layout(SUPPORTS)
    assert said == [('warning', 'bearing life: support rear: the state file holds another '
                                'bearing: counted from 0')]
    # Before any sample: the duty is the file's (3600 s).
    _, _, values = life.status(0.0)
    assert values['front life used per hour of running'] == pytest.approx(100e-6 / 1.0)
    assert values['front life used since start'] == 0.0
    assert values['front revolutions since start'] == 0.0
    assert values['state file'] == str(path)
    turns(life, 1)
    life.layout(SUPPORTS[:2])                 # a layout change: the step across it counts
    life.counting.add_sample(2.0, 2 * TWO_PI, TWO_PI, LOADS)
    _, _, values = life.status(0.0)
    hours = 2.0 / 3600.0
    front_since, front_all = 2 * FRONT_RATE / 1e6, (100.0 + 2 * FRONT_RATE) / 1e6
    assert values['front revolutions since start'] == pytest.approx(2.0, rel=1e-12)
    assert values['front life used since start'] == pytest.approx(front_since, rel=1e-12)
    assert values['front life used in all'] == pytest.approx(front_all, rel=1e-12)
    assert values['front life used per hour of running'] == pytest.approx(front_since / hours)
    assert values['front life left at this duty [h]'] == pytest.approx(
        (1.0 - front_all) / (front_since / hours), rel=1e-12)
    assert values['rear life used in all'] == pytest.approx(2 * REAR_RATE / 1e6 / 0.5)
    life.save()
    assert sorted(os.listdir(tmp_path)) == ['state.json']   # renamed, nothing left beside
    data = json.loads(path.read_text())
    saved = datetime.fromisoformat(data.pop('saved_utc').replace('Z', '+00:00'))
    assert abs(saved - datetime.now(timezone.utc)) < timedelta(seconds=5)
    assert data == {'kind': KIND, 'version': 1, 'supports': {
        'front': {'bearing': asdict(BALL), 'revolutions': pytest.approx(1002.0),
                  'damage': pytest.approx(100.0 + 2 * FRONT_RATE), 'seconds': 3602.0,
                  'life_used': pytest.approx(front_all)},
        'rear': {'bearing': asdict(ROLLER), 'revolutions': pytest.approx(2.0),
                 'damage': pytest.approx(2 * REAR_RATE), 'seconds': 2.0,
                 'life_used': pytest.approx(2 * REAR_RATE / 1e6 / 0.5)},
        'spare': {'bearing': {'C': 1.0}, 'revolutions': 7.0, 'damage': 6.0, 'seconds': 5.0}}}
    # Read back by a restarted node: the same counts go on, counted since its start.
    again = BearingLife(path, log)
    again.layout(SUPPORTS)
    _, _, values = again.status(0.0)
    assert values['front life used in all'] == pytest.approx(front_all, rel=1e-12)
    assert values['front life used since start'] == 0.0
    assert values['front revolutions since start'] == 0.0


def test_another_bearing_on_a_support_is_counted_from_zero(tmp_path):
    said, log = logged()
    life = BearingLife(None, log)
    life.layout(SUPPORTS[:1])
    turns(life, 3)
    life.layout([Support('front', -0.1, bearing=Bearing(C=5000.0))])
    assert said == [('warning', 'bearing life: support front has another bearing now: '
                                'counted from 0')]
    life.counting.add_sample(4.0, 4 * TWO_PI, TWO_PI, LOADS)
    life.counting.add_sample(5.0, 5 * TWO_PI, TWO_PI, LOADS)
    _, message, values = life.status(0.0)
    assert values['front hours of running since start'] == pytest.approx(1.0 / 3600.0)
    # The first sample has no step.
    assert values['front revolutions since start'] == pytest.approx(1.0, rel=1e-12)
    assert values['front life used in all'] == pytest.approx(1.0 / 1e6)   # P = C
    assert values['front life used since start'] == pytest.approx(1.0 / 1e6)
    assert message == ('bearing life: front 1e-06 used since start (0.0036/h: rating life '
                       '277.8 h at this duty), 1e-06 in all')


def test_a_restart_forgets_the_last_sample():
    life = BearingLife()
    life.layout(SUPPORTS[:1])
    turns(life, 1)
    life.restart()
    life.counting.add_sample(10.0, 0.5, TWO_PI, LOADS)      # no step from before
    life.counting.add_sample(11.0, 0.5 + TWO_PI, TWO_PI, LOADS)
    _, _, values = life.status(0.0)
    assert values['front revolutions since start'] == pytest.approx(2.0)
    assert values['front hours of running since start'] == pytest.approx(2.0 / 3600.0)
    BearingLife().restart()                                  # nothing counted: no trouble


def test_a_whole_rating_life_used_warns(tmp_path):
    path = state(tmp_path / 'state.json', {
        'front': {'bearing': asdict(BALL), 'revolutions': 1e9, 'damage': 1e6,
                  'seconds': 7200.0}})
    life = BearingLife(path)
    life.layout(SUPPORTS[:1])
    level, message, values = life.status(0.0)
    assert level == assessment.WARN
    assert message == ('bearing life: front has used its whole rating life (1); front 0 used '
                       'since start (0.5/h: rating life 2 h at this duty), 1 in all')
    assert values['front life left at this duty [h]'] == 0.0
    assert values['front mean equivalent load since start [N]'] == ''


def test_a_state_file_not_written_is_said(tmp_path):
    folder = tmp_path / 'gone'
    folder.mkdir()
    path = folder / 'state.json'
    said, log = logged()
    life = BearingLife(path, log)
    life.layout(SUPPORTS[:1])
    folder.rmdir()
    life.save()
    problem = f'state file not written: No such file or directory: {path}'
    assert life.problem == problem and said == [('error', f'bearing life: {problem}')]
    life = BearingLife(tmp_path / 'unused.json')
    life.layout([Support('front', 0.0)])                     # nothing to keep: not written
    life.save()
    assert not (tmp_path / 'unused.json').exists()


def test_an_unreadable_state_file_is_said_kept_and_the_count_goes_on_in_memory(tmp_path):
    path = tmp_path / 'state.json'
    path.write_text('[1, 2]')
    said, log = logged()
    life = BearingLife(path, log)
    problem = ("state file unreadable, not written over (counted from 0 since start): "
               f"{path}: not a bearing life state file (kind '{KIND}')")
    assert said == [('error', f'bearing life: {problem}')] and life.problem == problem
    life.layout(SUPPORTS[:1])
    turns(life, 1)
    life.save()
    assert path.read_text() == '[1, 2]' and sorted(os.listdir(tmp_path)) == ['state.json']
    _, _, values = life.status(0.0)
    assert values['state file'] == problem
    assert values['front revolutions since start'] == pytest.approx(1.0)


def test_supports_in_any_order_and_added_later_are_all_counted_and_kept(tmp_path):
    """A support without a bearing first; one support, then two: both counted, both saved."""
    path = tmp_path / 'state.json'
    life = BearingLife(path)
    life.layout([SUPPORTS[2], SUPPORTS[0]])
    assert set(life.counting.counters) == {'front'}
    life.counting.add_sample(0.0, 0.0, TWO_PI, LOADS)
    life.counting.add_sample(0.5, math.pi, TWO_PI, LOADS)        # half a turn in 0.5 s
    _, _, values = life.status(0.0)
    assert values['front life used per hour of running'] == pytest.approx(
        0.5 * FRONT_RATE / 1e6 / (0.5 / 3600.0), rel=1e-12)
    life.layout(SUPPORTS[:2])
    assert set(life.counting.counters) == {'front', 'rear'}
    # A new bearing has no last load: the step across the change is not counted.
    life.counting.add_sample(1.0, TWO_PI, TWO_PI, LOADS)
    life.counting.add_sample(1.5, 3 * math.pi, TWO_PI, LOADS)
    life.save()                                   # the samples since the status counted too
    data = json.loads(path.read_text())
    assert data['saved_utc'].endswith('Z') and '+00:00' not in data['saved_utc']
    assert set(data['supports']) == {'front', 'rear'}
    assert data['supports']['front']['revolutions'] == pytest.approx(1.0, rel=1e-12)
    assert data['supports']['front']['seconds'] == 1.0
    assert data['supports']['rear']['revolutions'] == pytest.approx(0.5, rel=1e-12)


def test_the_duty_of_a_start_under_a_second_is_that_since_start(tmp_path):
    """Half a turn in 0.5 s after a state file's hour: the rate is that of the 0.5 s."""
    path = state(tmp_path / 'state.json', {
        'front': {'bearing': asdict(BALL), 'revolutions': 1000.0, 'damage': 100.0,
                  'seconds': 3600.0}})
    life = BearingLife(path)
    life.layout(SUPPORTS[:1])
    life.counting.add_sample(0.0, 0.0, TWO_PI, LOADS)
    life.counting.add_sample(0.5, math.pi, TWO_PI, LOADS)
    _, _, values = life.status(0.0)
    assert values['front life used per hour of running'] == pytest.approx(
        0.5 * FRONT_RATE / 1e6 / (0.5 / 3600.0), rel=1e-12)
