"""
Labelled runs of a field-balancing visit: ``record``/``simulate --run KIND [--trial ...]``.

The label is read back by readers the project did not write (the mcap library's Metadata
records, rosbag2's own ``rosbag2`` record as its MCAP storage reads it) and by what people
read (``info``'s text and JSON). ``calibrate`` on labelled bags, without ``--trial``, gives
exactly the coefficients of the same runs given their trial weights by hand; the mistakes a
label can catch (runs swapped, a trial weight typed in grams, a trial run without its weight)
are refused with one line naming the bag.
"""

import json
from pathlib import Path
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
import pytest
import yaml

from in_process import run_cli
from ros_harness import ros_environment

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / 'bags'
TRIAL_I, TRIAL_II = 'I:0.2@0,0.68', 'II:0.2@0,0.68'
"""The bundled trial runs' weights (bags/field_trial_*.yaml: 200 g at the 0 deg hole)."""


def metadata_of(path):
    """Return {name: {key: value}} of an MCAP file's Metadata records (the mcap library)."""
    with open(path, 'rb') as stream:
        return {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}


@pytest.fixture(scope='module')
def visit(tmp_path_factory):
    """Simulate the bundled visit's runs twice: labelled and not."""
    folder = tmp_path_factory.mktemp('visit')
    labels = {'baseline': ['--run', 'baseline'],
              'trial_I': ['--run', 'trial', '--trial', TRIAL_I],
              'trial_II': ['--run', 'trial', '--trial', TRIAL_II]}
    for name, label in labels.items():
        for suffix, extra in (('', label), ('_plain', [])):
            code, _, err = run_cli('simulate', BAGS / f'field_{name}.yaml', '-o',
                                   folder / f'{name}{suffix}.mcap', *extra)
            assert code == 0, err
    return folder


def test_the_label_is_in_the_bag_for_other_readers_and_in_info(visit):
    cvc, = [v for k, v in metadata_of(visit / 'trial_I.mcap').items() if k == 'cvc_balance']
    assert cvc == {'run': 'trial', 'trial': 'I:0.2@0.0,0.68'}
    rosbag2 = yaml.safe_load(metadata_of(visit / 'trial_I.mcap')['rosbag2']
                             ['serialized_metadata'])
    assert rosbag2['custom_data'] == {'run': 'trial', 'trial': 'I:0.2@0.0,0.68'}
    assert metadata_of(visit / 'baseline.mcap')['cvc_balance'] == {'run': 'baseline'}
    assert 'cvc_balance' not in metadata_of(visit / 'baseline_plain.mcap')

    code, out, err = run_cli('info', visit / 'trial_I.mcap')
    assert code == 0, err
    assert 'Run:               trial run: plane I, 0.2 kg at 0 deg, r 0.68 m' in out.splitlines()
    code, out, _ = run_cli('info', visit / 'baseline_plain.mcap')
    assert 'Run:               not labelled' in out.splitlines()
    code, out, _ = run_cli('info', visit / 'trial_II.mcap', '--json')
    assert json.loads(out)['run'] == {'kind': 'trial', 'trial': 'II:0.2@0.0,0.68'}


def test_calibrate_takes_the_recorded_trials(visit, tmp_path):
    """The same coefficients, to the bit, as the unlabelled runs with --trial typed."""
    code, labelled, err = run_cli('calibrate', *(visit / f'{n}.mcap' for n in
                                                 ('baseline', 'trial_I', 'trial_II')), '--json')
    assert code == 0, err
    code, typed, err = run_cli('calibrate', *(visit / f'{n}_plain.mcap' for n in
                                              ('baseline', 'trial_I', 'trial_II')),
                               '--trial', TRIAL_I, '--trial', TRIAL_II, '--json')
    assert code == 0, err
    labelled, typed = json.loads(labelled), json.loads(typed)
    # What a person reads: the weight each trial run carried, taken from its bag.
    code, text, err = run_cli('calibrate', *(visit / f'{n}.mcap' for n in
                                             ('baseline', 'trial_I', 'trial_II')))
    assert code == 0, err
    said = [line.split(':')[0] for line in text.splitlines() if 'largest change' in line]
    assert said == ['  trial run 1 (plane I, 0.2 kg at 0 deg, r 0.68 m)',
                    '  trial run 2 (plane II, 0.2 kg at 0 deg, r 0.68 m)']
    assert labelled['coefficients'] == typed['coefficients']
    assert labelled['trials'] == typed['trials']
    # The runs given in the other order: the labels travel with the bags, so the plane of
    # each trial run is still right (by hand: the same complex coefficient per plane).
    code, swapped, err = run_cli('calibrate', visit / 'baseline.mcap', visit / 'trial_II.mcap',
                                 visit / 'trial_I.mcap', '--json')
    assert code == 0, err
    swapped = json.loads(swapped)
    planes = [t['plane'] for t in swapped['trials']]
    assert planes == ['II', 'I']
    # A typed --trial equal to the recorded one is accepted (its angle in another form).
    code, _, err = run_cli('calibrate', *(visit / f'{n}.mcap' for n in
                                          ('baseline', 'trial_I', 'trial_II')),
                           '--trial', 'I:0.2@360,0.68', '--trial', TRIAL_II)
    assert code == 0, err


@pytest.mark.parametrize('runs, typed, says', [
    (('trial_I', 'baseline', 'trial_II'), [],
     '{trial_I} was recorded as a trial run, not the baseline: give the baseline run first, '
     'then the trial runs'),
    (('baseline', 'baseline', 'trial_II'), [],
     '{baseline} was recorded as a baseline run, not a trial run: give the baseline run '
     'first, then the trial runs'),
    (('baseline', 'trial_I', 'trial_II'), ['I:200@0,0.68', TRIAL_II],
     '--trial I:200.0@0.0,0.68 differs from the trial weight {trial_I} was recorded with '
     '(I:0.2@0.0,0.68): leave --trial out to use the recorded ones'),
    (('baseline', 'trial_I', 'trial_II'), [TRIAL_I],
     '1 --trial given for 2 trial runs: give one per trial run, in order, or none to use '
     'the weights recorded'),
    (('baseline', 'trial_I_plain', 'trial_II'), [],
     '{trial_I_plain} carries no trial weight (recorded without --run trial --trial ...): '
     'give --trial PLANE:MASS_KG@ANGLE_DEG,RADIUS_M for every trial run'),
])
def test_calibrate_refuses_what_the_labels_contradict(visit, runs, typed, says):
    paths = {n: visit / f'{n}.mcap' for n in runs}
    code, out, err = run_cli('calibrate', *(paths[n] for n in runs),
                             *[a for t in typed for a in ('--trial', t)])
    assert (code, out) == (2, '')
    assert err == f'cvc-balance: error: {says.format(**paths)}\n'


@pytest.mark.parametrize('extra, says', [
    (['--run', 'trial'], '--run trial: give the trial weight too (--trial '
     'PLANE:MASS_KG@ANGLE_DEG,RADIUS_M, e.g. I:0.2@0,0.68)'),
    (['--run', 'check', '--trial', TRIAL_I], '--trial goes with --run trial only (this run is '
     'a check run)'),
    (['--trial', TRIAL_I], '--trial goes with --run trial (say what run this is)'),
    (['--run', 'trial', '--trial', 'I:0.2@0'], "--trial: give PLANE:MASS_KG@ANGLE_DEG,RADIUS_M "
     "(e.g. I:0.2@0,0.68), got 'I:0.2@0'"),
])
def test_simulate_refuses_a_label_that_cannot_be_and_writes_nothing(tmp_path, extra, says):
    code, _, err = run_cli('simulate', BAGS / 'field_check.yaml', '-o', tmp_path / 'x.mcap',
                           *extra)
    assert (code, err) == (2, f'cvc-balance: error: {says}\n')
    assert list(tmp_path.iterdir()) == []


def test_record_writes_the_label(tmp_path):
    """``cvc-balance record --run check``, as its own process on this test run's domain."""
    out = tmp_path / 'check.mcap'
    record = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'record', '-o',
                               str(out), '--run', 'check', '--machine-id', 'gantry-7'],
                              env=ros_environment(), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not out.exists():
        time.sleep(0.1)
    time.sleep(1.5)         # the bag is created before the node spins and takes SIGINT
    record.send_signal(signal.SIGINT)
    _, err = record.communicate(timeout=30)
    assert record.returncode == 0, err
    assert metadata_of(out)['cvc_balance'] == {'machine_id': 'gantry-7', 'run': 'check'}
    code, text, _ = run_cli('info', out)
    assert 'Run:               check run' in text.splitlines()


def test_the_node_labels_its_recording_and_refuses_a_label_that_cannot_be(tmp_path):
    """The node's record_run / record_trial parameters, as its own process."""
    from ros_harness import NodeProcess
    out = tmp_path / 'trial_II.mcap'
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', f'record_path:={out}', '-p', 'record_run:=trial',
                        '-p', f'record_trial:={TRIAL_II}'], tmp_path / 'node.log')
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not out.exists():
        time.sleep(0.1)
    time.sleep(1.5)         # the bag is made while the node starts; it spins after
    assert node.stop(signal.SIGINT) == 0, node.log()
    assert metadata_of(out)['cvc_balance'] == {'run': 'trial', 'trial': 'II:0.2@0.0,0.68'}
    code, text, _ = run_cli('info', out)
    assert 'Run:               trial run: plane II, 0.2 kg at 0 deg, r 0.68 m' in \
        text.splitlines()
    for params, says in (
            ([f'record_path:={tmp_path / "a.mcap"}', 'record_run:=trail'],
             "parameters record_run/record_trial: record_run: give one of baseline, trial, "
             "check, trim, got 'trail'"),
            (['record_run:=check'], 'record_run and record_trial label a recording: set '
             'record_path')):
        bad = NodeProcess('cvc_balance.ros.balance_monitor',
                          [a for p in params for a in ('-p', p)], tmp_path / 'bad.log')
        bad.process.wait(60)
        assert (bad.stop(), bad.log().strip()) == (2, f'balance_monitor: error: {says}')
    assert not (tmp_path / 'a.mcap').exists()
