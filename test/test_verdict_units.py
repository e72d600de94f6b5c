"""
Every printed and published quantity in its unit, against values computed by hand.

Two rotors whose numbers need no engine:
* COUPLE: 1 kg at r 0.5 m, 0 deg, z +0.2 m and 1 kg at 180 deg, z -0.2 m, supports and
  planes at z -/+0.2, no gravity. Static unbalance 0; couple P_xz = 2 (1 kg)(0.5 m)(0.2 m)
  = 0.2 kg m^2 = 2e8 g mm^2 at 0 deg; each plane 0.5 kg m = 5e5 g mm (I at 180 deg, II at
  0 deg), corrected by 1 kg (1000 g) at r 0.5 m opposite. At omega 10 rad/s, alpha 4
  rad/s^2, q = 0: each mass loads its support with m r omega^2 = 50 N outward and
  m r alpha = 2 N against the turn; the moment about O is (alpha P_xz, omega^2 P_xz, 0)
  = (0.8, 20, 0) N m; the drive torque I_zz alpha = (2 x 1 x 0.25) 4 = 2 N m. G 6.3 at
  10 rad/s: U_per = 6.3e-3 x 2 / 10 kg m = 1260 g mm, 630 g mm per plane (shares 0.5).
* ISO 21940-11's worked example (shared/domain/FACTS.md): 1000 kg at 240 rpm, G 6.3 ->
  U_per 250.7 kg mm, force 158 N; here 999 kg on the axis and 1 kg at 0.125 m (U = 125 000
  g mm, U omega^2 = 0.125 x 25.1327^2 = 78.96 N).

The node's diagnostics judge at the service speed whatever the current speed, name STALE
after ``stale_after`` without input and log each change of level once.
"""

import json
import math
import re
import signal

from diagnostic_msgs.msg import DiagnosticStatus
import pytest
from sensor_msgs.msg import JointState
import yaml

from in_process import cvc
from test_balance_monitor import (diagnostic_values, joint_state, probe,  # noqa: F401
                                  start_node, vector, wait_for_diagnostics,
                                  wait_until_connected)

COUPLE = {
    'name': 'couple_pair', 'gravity': [0.0, 0.0, 0.0],
    'components': [{'name': 'a', 'mass': 1.0, 'radius': 0.5, 'angle': 0.0, 'z': 0.2},
                   {'name': 'b', 'mass': 1.0, 'radius': 0.5, 'angle_deg': 180.0, 'z': -0.2}],
    'supports': [{'name': 'front', 'z': -0.2}, {'name': 'rear', 'z': 0.2, 'axial': True}],
    'balancing': {'planes': [-0.2, 0.2], 'correction_radius': 0.5, 'grade': 6.3,
                  'service_speed': 10.0}}
RPM_240 = 240 * 2 * math.pi / 60
ISO_EXAMPLE = {
    'name': 'iso_21940_11_example', 'gravity': [0.0, 0.0, 0.0],
    'components': [{'name': 'rotor', 'mass': 999.0, 'radius': 0.0, 'angle': 0.0},
                   {'name': 'residual', 'mass': 1.0, 'radius': 0.125, 'angle': 0.0}],
    'supports': [{'name': 'bearing', 'z': 0.0}],
    'balancing': {'grade': 6.3, 'service_speed': RPM_240}}


def write(tmp_path, layout):
    path = tmp_path / f"{layout['name']}.yaml"
    path.write_text(yaml.safe_dump(layout))
    return path


def cli(*args):
    return cvc(*args)               # in this process (test/in_process.py)


def number_before(text, unit, label):
    """Return the number printed before ``unit`` on the line that starts with ``label``."""
    line = next(line for line in text.splitlines() if line.strip().startswith(label))
    match = re.search(r'(-?[\d.]+(?:e[+-]?\d+)?)\s+' + re.escape(unit) + r'(\s|$)', line)
    assert match, (line, unit)
    return float(match.group(1))


def test_solve_table_units_of_a_pure_couple(tmp_path):
    run = cli('solve', write(tmp_path, COUPLE), '--omega', 10, '--alpha', 4)
    assert run.returncode == 0, run.stderr
    out = run.stdout
    # Loads: N and N m (printed to 0.01).
    rows = {line.split('  ')[0].strip(): line.split() for line in out.splitlines()}
    assert [float(v) for v in rows['force, stator frame'][-3:]] == [0.0, 0.0, 0.0]
    assert rows['moment, stator frame'][3] == 'N' and rows['moment, stator frame'][4] == 'm'
    assert [float(v) for v in rows['moment, stator frame'][-3:]] == [0.8, 20.0, 0.0]
    assert number_before(out, 'N m', 'drive torque') == pytest.approx(2.0, abs=5e-4)
    front = next(line for line in out.splitlines() if line.startswith('front')).split()
    assert [float(v) for v in front[2:6]] == [-50.0, 2.0, 0.0, pytest.approx(50.04, abs=0.005)]
    # Unbalance: g mm, g mm^2.
    assert number_before(out, 'g mm', 'static') == pytest.approx(0.0, abs=0.05)
    assert number_before(out, 'g mm^2', 'couple') == pytest.approx(2.0e8, abs=0.05)
    assert number_before(out, 'g mm', 'ISO 21940-11') == pytest.approx(1260.0, abs=0.05)
    planes = [line.split() for line in out.splitlines() if re.match(r'(I|II)\s', line)]
    assert [(p[0], float(p[2]), float(p[3]), float(p[4])) for p in planes] == [
        ('I', 500000.0, 180.0, 630.0), ('II', 500000.0, 0.0, 630.0)]
    assert [float(p[6]) for p in planes] == [1000.0, 1000.0]      # grams of correction
    assert 'OUT OF G 6.3' in out and 'G 5e+03 mm/s' in out         # 793.65 x 6.3 = 5000


def test_solve_json_units_of_a_pure_couple(tmp_path):
    run = cli('solve', write(tmp_path, COUPLE), '--omega', 10, '--alpha', 4, '--json')
    s = json.loads(run.stdout)
    assert s['force_stator'] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert s['moment_stator'] == pytest.approx([0.8, 20.0, 0.0], rel=1e-12, abs=1e-12)
    assert s['drive_torque'] == pytest.approx(2.0, rel=1e-12)
    assert s['supports']['front']['force'] == pytest.approx([-50.0, 2.0, 0.0], rel=1e-12)
    assert s['static_unbalance']['kg_m'] == pytest.approx(0.0, abs=1e-15)
    assert s['couple_unbalance']['kg_m2'] == pytest.approx(0.2, rel=1e-12)
    assert s['couple_unbalance']['angle_deg'] == pytest.approx(0.0, abs=1e-9)
    balance = s['balance']
    assert balance['permissible_g_mm'] == pytest.approx(1260.0, rel=1e-12)
    assert [p['g_mm'] for p in balance['planes']] == pytest.approx([5e5, 5e5], rel=1e-12)
    assert [p['permissible_g_mm'] for p in balance['planes']] == pytest.approx([630.0] * 2)
    assert [p['correction_mass_kg'] for p in balance['planes']] == pytest.approx([1.0, 1.0])
    assert balance['equivalent_grade'] == pytest.approx(5000.0, rel=1e-12)
    assert (balance['level'], balance['verdict']) == ('ERROR', 'OUT OF G 6.3')


def test_iso_21940_11_worked_example_through_solve_and_replay(tmp_path):
    """U_per 250.7 kg mm and 158 N (FACTS.md, four figures) as the commands print them."""
    layout = write(tmp_path, ISO_EXAMPLE)
    run = cli('solve', layout, '--omega', 1.0)     # judged at the service speed, not 1 rad/s
    assert run.returncode == 0, run.stderr
    u_per = number_before(run.stdout, 'g mm', 'ISO 21940-11')
    assert u_per / 1e3 == pytest.approx(250.7, abs=0.05)                 # kg mm
    assert u_per * 1e-6 * RPM_240 ** 2 == pytest.approx(158.0, abs=0.5)   # N = m G Omega
    assert number_before(run.stdout, 'g mm', 'static') == pytest.approx(125000.0, abs=0.05)
    assert 'at the service speed 25.13 rad/s' in run.stdout
    # The same rotor in a bag, 2 s at 240 rpm: replay prints the same units.
    scenario = tmp_path / 'steady.yaml'
    scenario.write_text(yaml.safe_dump({
        'name': 'steady', 'layout': ISO_EXAMPLE, 'rate': 200, 'profile': [
            {'type': 'spin_up', 'to': RPM_240, 'alpha': 50.0},
            {'type': 'steady', 'duration': 2.0}]}))
    bag = tmp_path / 'steady.mcap'
    assert cli('simulate', scenario, '-o', bag).returncode == 0
    run = cli('replay', bag)
    assert run.returncode == 0, run.stderr
    line = next(line for line in run.stdout.splitlines() if 'static unbalance' in line)
    assert re.search(r'static unbalance 125000\.0 g mm = 0\.50 of the permissible '
                     r'(\d+\.\d) g mm', line), line
    assert float(re.search(r'permissible (\d+\.\d) g mm', line).group(1)) / 1e3 == \
        pytest.approx(250.7, abs=0.05)
    # Peak load, no gravity: U sqrt(omega^4 + alpha^2) at the end of the spin-up (alpha 50
    # rad/s^2): 0.125 sqrt(25.1327^4 + 50^2) = 79.20 N (78.96 N from U omega^2 alone).
    assert number_before(run.stdout, 'N;', 'peak load') == pytest.approx(
        0.125 * math.hypot(RPM_240 ** 2, 50.0), abs=0.05)
    # G = U Omega / m = 0.125 m x 8 pi rad/s / 1000 = pi mm/s.
    assert 'verdict OK: G 3.14 at the service speed 25.13 rad/s: WITHIN G 6.3' in run.stdout


def test_node_publishes_and_reports_in_their_units(probe, tmp_path):  # noqa: F811
    """Topics in N and N m, diagnostics in g mm, g mm^2, N, against the hand values."""
    node = start_node(tmp_path, COUPLE)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    wait_until_connected(probe, node, 'joint_states')
    for k in range(30):
        joints.publish(joint_state(10**9 + k * 2_000_000, 0.0, 10.0))
        probe.spin_for(0.003)
    assert probe.spin_until(lambda: len(probe.received['unbalance']) == 30), node.log()
    unbalance = probe.received['unbalance'][-1].wrench
    assert vector(unbalance.force) == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert vector(unbalance.torque) == pytest.approx([0.0, 20.0, 0.0], rel=1e-12)   # N m
    front = probe.received['supports/front/load'][-1].wrench
    assert vector(front.force) == pytest.approx([-50.0, 0.0, 0.0], rel=1e-12, abs=1e-12)
    assert wait_for_diagnostics(probe, lambda s, v: v.get('accepted') == '30'), node.log()
    _, values = diagnostic_values(probe)
    hand = {'static unbalance [g mm]': 0.0, 'couple unbalance [g mm^2]': 2e8,
            'permissible [g mm]': 1260.0, 'plane I unbalance [g mm]': 5e5,
            'plane II unbalance [g mm]': 5e5, 'plane I permissible [g mm]': 630.0,
            'plane I correction mass [g]': 1000.0, 'achieved grade [mm/s]': 5000.0,
            'judged at [rad/s]': 10.0}
    for key, want in hand.items():
        assert float(values[key]) == pytest.approx(want, rel=1e-5, abs=1e-6), key   # 6 digits
    assert values['verdict level'] == 'ERROR'
    assert node.stop(signal.SIGINT) == 0


HEAVY = {'name': 'heavy_lump', 'mass': 8.0, 'radius': 0.65, 'angle_deg': 40.0, 'z': 0.1}


def test_node_judges_at_the_service_speed_goes_stale_and_logs_each_change_once(
        probe, tmp_path):  # noqa: F811
    """Out of grade at service speed reads ERROR while coasting at 0.0137 rad/s too."""
    gantry = yaml.safe_load(open('config/ct_gantry.yaml'))
    heavy = dict(gantry, components=gantry['components'] + [HEAVY])
    node = start_node(tmp_path, heavy, params={'stale_after': 0.6})
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    wait_until_connected(probe, node, 'joint_states')
    solve = json.loads(cli('solve', tmp_path / 'layout.yaml', '--omega', 0.01372,
                           '--json').stdout)['balance']
    for k in range(100):      # coasting, nearly at rest
        joints.publish(joint_state(10**9 + k * 5_000_000, 0.0, 0.01372))
        probe.spin_for(0.005)
    assert wait_for_diagnostics(probe, lambda s, v: v.get('accepted') == '100'), node.log()
    status, values = diagnostic_values(probe)
    assert status.level == DiagnosticStatus.ERROR, status.message
    assert float(values['judged at [rad/s]']) == 23.27 and values['judged at'] == \
        'service speed'
    # One verdict: the node's equals solve's for the same layout (6 printed digits).
    assert float(values['achieved grade [mm/s]']) == pytest.approx(
        solve['equivalent_grade'], rel=1e-5)
    assert solve['level'] == values['verdict level'] == 'ERROR'
    assert values['verdict'].endswith('OUT OF G 6.3 (from the layout: no load cells)')
    assert values['verdict source'] == 'layout'
    # Input stops: STALE within stale_after + one period, the verdict still said.
    assert wait_for_diagnostics(probe, lambda s, v: s.level == DiagnosticStatus.STALE,
                                timeout=3.0), node.log()
    status, _ = diagnostic_values(probe)
    assert 'no motion sample for' in status.message and 'OUT OF G 6.3' in status.message
    probe.spin_for(1.0)      # five more periods: no more log lines about the level
    assert node.stop(signal.SIGINT) == 0
    # Logged at each change, not each period (0.2 s: about 30 periods went by): ERROR at
    # the layout, STALE while it waited for input (if it waited over 0.6 s), ERROR with it.
    levels = re.findall(r'balance (OK|WARN|ERROR|STALE):', node.log())
    assert levels[-2:] == ['ERROR', 'STALE'] and len(levels) <= 4, node.log()
    assert all(a != b for a, b in zip(levels, levels[1:])), node.log()


def test_node_without_service_speed_judges_at_the_top_speed_seen(probe, tmp_path):  # noqa: F811
    """The live speed only decides the top speed: slower samples later do not lower it."""
    layout = dict(COUPLE, balancing={'planes': [-0.2, 0.2], 'grade': 6.3})
    node = start_node(tmp_path, layout)
    joints = probe.publisher(JointState, 'joint_states', sensor=True)
    wait_until_connected(probe, node, 'joint_states')
    assert wait_for_diagnostics(probe, lambda s, v: v.get('verdict level') == 'NOT JUDGED')
    _, values = diagnostic_values(probe)
    assert 'not judged' in values['verdict']
    clock = iter(range(1, 10**6))
    for omega in [20.0] * 20 + [1.0] * 20:
        joints.publish(joint_state(10**9 + next(clock) * 2_000_000, 0.0, omega))
        probe.spin_for(0.003)
    assert wait_for_diagnostics(probe, lambda s, v: v.get('accepted') == '40'), node.log()
    _, values = diagnostic_values(probe)
    assert (values['judged at'], float(values['judged at [rad/s]'])) == ('top speed seen', 20.0)
    assert float(values['speed [rad/s]']) == 1.0
    # U_per at 20 rad/s: 6.3e-3 x 2 / 20 kg m = 630 g mm, 315 g mm a plane.
    assert float(values['plane I permissible [g mm]']) == pytest.approx(315.0, rel=1e-6)
    assert node.stop(signal.SIGINT) == 0


def test_solve_replay_and_view_give_the_same_verdict_for_the_bundled_bag(tmp_path):
    """Each layout of the tube-swap bag: replay's verdict line equals solve's."""
    from cvc_balance.bag.scenario import load_scenario
    scenario = load_scenario('bags/spin_up_tube_swap.yaml')
    replayed = cli('replay', 'bags/spin_up_tube_swap.mcap').stdout
    verdicts = [line.strip() for line in replayed.splitlines() if line.startswith('  verdict')]
    assert len(verdicts) == len(scenario.layouts) == 2
    for (_, mapping), said in zip(scenario.layouts, verdicts):
        path = tmp_path / 'layout.yaml'
        path.write_text(yaml.safe_dump(mapping))
        balance = json.loads(cli('solve', path, '--omega', 0.0, '--json').stdout)['balance']
        assert said.startswith(f"verdict {balance['level']}: G "
                               f"{balance['equivalent_grade']:.3g} at the service speed")
        # No load cells in this bag: the layout's verdict is the verdict of record, labelled.
        assert said.endswith(f"{balance['verdict']} (from the layout: no load cells)")
    assert [v.split()[1] for v in verdicts] == ['OK:', 'ERROR:']   # the view: test_rerun_view


def test_the_verdict_is_the_full_models_when_a_smaller_model_computes_the_loads(tmp_path):
    """A tilted body's own product of inertia is a couple unbalance the point masses lack."""
    layout = dict(COUPLE, components=COUPLE['components'] + [{
        'name': 'tilted_disc', 'mass': 5.0, 'radius': 0.0, 'angle': 0.0,
        'inertia': {'ixx': 0.3, 'iyy': 0.3, 'izz': 0.5, 'ixy': 0.0, 'ixz': -0.02,
                    'iyz': 0.0}}])     # ixz = -int x z dm: P_xz = +0.02 kg m^2 of its own
    path = write(tmp_path, layout)
    full = json.loads(cli('solve', path, '--omega', 10, '--json').stdout)
    small = json.loads(cli('solve', path, '--omega', 10, '--json',
                           '--tolerance', '1e9', '1e9', '1e9').stdout)
    assert small['model'] == 'point masses, planar' and full['model'] == 'rigid bodies'
    assert full['couple_unbalance']['kg_m2'] == pytest.approx(0.22, rel=1e-12)  # 0.2 + 0.02
    assert small['balance'] == full['balance']
    assert small['couple_unbalance'] == full['couple_unbalance']


def test_support_load_parts_of_a_point_mass_and_of_a_balanced_rotor():
    """
    Split the loads of a point mass and of a balanced rotor by hand.

    A 2 kg point at r 0.3 m midway between two supports: each carries m g / 2 at rest and
    m r sqrt(omega^4 + alpha^2) / 2 turning; a balanced rotor's turning part is only the
    rounding of its first moments (S = (-5.6e-17, 7.3e-17) kg m, sin of fl(pi)): measured
    5.8e-14 N at 30 rad/s.
    """
    import numpy as np
    from cvc_balance.physics.engine import RotorModel
    from cvc_balance.physics.layout import parse_layout
    from cvc_balance.physics.load_parts import support_load_parts
    supports = [{'name': 'a', 'z': -0.5}, {'name': 'b', 'z': 0.5, 'axial': True}]
    point = RotorModel.from_layout(parse_layout({
        'name': 'point', 'supports': supports,
        'components': [{'name': 'p', 'mass': 2.0, 'radius': 0.3, 'angle': 0.4}]}))
    q, omega, alpha = np.linspace(0, 6, 7), np.linspace(0, 30, 7), np.full(7, 4.0)
    parts = support_load_parts(point, q, omega, alpha)
    for name in ('a', 'b'):
        assert parts.static[name] == pytest.approx(np.full(7, 9.80665), rel=1e-14)
        assert parts.rotating[name] == pytest.approx(0.3 * np.hypot(omega ** 2, alpha),
                                                     rel=1e-14)
    balanced = RotorModel.from_layout(parse_layout({
        'name': 'balanced', 'supports': supports,
        'components': [{'name': 'p', 'mass': 2.0, 'radius': 0.3, 'angle': 0.0, 'z': 0.2},
                       {'name': 'q', 'mass': 3.0, 'radius': 0.2, 'angle_deg': 180.0,
                        'z': 0.2}]}))
    # 2 x 0.3 = 3 x 0.2 at the same z: the first moments cancel to rounding.
    rotating = support_load_parts(balanced, q, omega, alpha).rotating
    assert all(np.all(v < 1e-13) for v in rotating.values()), rotating
