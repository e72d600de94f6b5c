"""
The fleet: a simulated fleet through Dask's LocalCluster, against what is known without it.

20 machines x 5 runs (short checks at 100 Hz with load cells, over 180 days; files and
rosbag2 directories mixed) plus two damaged bags, through ``cvc-balance fleet`` on the
embedded LocalCluster (two worker processes). Checked against things the fleet code did
not compute: every row against ``cvc-balance replay BAG --json`` of the same bag (a fresh
process for one of them), the machine ids and dates against the simulation's plan, the
drift of each slipping counterweight against the TRUE rotor's plane unbalance worked out
here by hand (ISO 21940-2's two-plane split of S and P), the digests against hashlib on
the documented byte stream, the identity records against the ``mcap`` library's reader
and rosbags. No timing is asserted (see benchmarks/fleet_throughput.py).
"""

from datetime import timedelta
import hashlib
import json
import math
from pathlib import Path
import re
import shutil
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from cvc_balance.bag.machine import bag_custom_data, machine_of
from cvc_balance.fleet import content_digest, find_bags, simulate_fleet
from cvc_balance.fleet.trends import LEAVES, machine_trends
from in_process import run_cli
from ros_harness import NodeProcess, ros_environment

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / 'config' / 'ct_gantry.yaml'
MACHINES, RUNS = 20, 5


@pytest.fixture(scope='module')
def fleet(tmp_path_factory):
    """Simulate the fleet, add two damaged bags, run ``fleet`` once on the LocalCluster."""
    base = tmp_path_factory.mktemp('fleet')
    root = base / 'runs'
    plans = simulate_fleet(LAYOUT, root, machines=MACHINES, runs=RUNS, days=180.0, seed=7)
    # Damaged: a file that is no bag, and a rosbag2 directory whose only file is missing.
    (root / 'gantry-0003' / 'garbage.mcap').write_bytes(bytes(range(256)) * 4)
    broken = root / 'gantry-0004' / 'lost_file'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': 'mcap', 'relative_file_paths': ['lost_file_0.mcap'],
        'compression_mode': ''}}), encoding='utf-8')
    results = base / 'fleet.parquet'
    code, out, err = run_cli('fleet', root, '--out', results, '--workers', 2, '--no-progress')
    assert code == 0, err
    return {'root': root, 'plans': plans, 'results': results, 'out': out, 'base': base}


def test_simulated_fleet_is_mixed_and_stamped(fleet):
    bags = find_bags([fleet['root']])
    assert len(bags) == MACHINES * RUNS + 2
    directories = [b for b, _ in bags if b.is_dir()]
    # Every third run of a machine is a rosbag2 directory; and the broken one.
    assert len(directories) == MACHINES * len(range(2, RUNS, 3)) + 1
    for plan in fleet['plans']:
        for run in plan.runs:
            assert bag_custom_data(run.path) == {'machine_id': plan.machine_id}
            assert machine_of(run.path, fleet['root']) == (plan.machine_id, 'bag')


def test_every_row_is_replay_json_of_its_bag(fleet):
    table = pq.read_table(fleet['results']).to_pylist()
    assert len(table) == MACHINES * RUNS        # one layout segment per run
    by_bag = {row['bag']: row for row in table}
    plan_of = {str(run.path): (plan, run) for plan in fleet['plans'] for run in plan.runs}
    assert set(by_bag) == set(plan_of)
    for bag, row in sorted(by_bag.items()):
        code, out, err = run_cli('replay', bag, '--json')
        assert code == 0, err
        record = json.loads(out)
        segment = record['segments'][0]
        plan, run = plan_of[bag]
        assert row['machine_id'] == record['machine_id'] == plan.machine_id
        assert row['machine_source'] == 'bag'
        # The run's time line starts at its date (to the microsecond the table keeps).
        assert abs(row['run_start'].timestamp() - run.when.timestamp()) < 1e-6
        assert abs(row['run_start'].timestamp() - record['start']) < 1e-6
        assert abs(row['segment_start'].timestamp() - segment['first_sample']) < 1e-6
        assert row['digest'] == content_digest(bag)
        for column, value in (
                ('samples', record['samples']), ('accepted', record['accepted']),
                ('rejected', record['rejected']), ('problems', record['problems']),
                ('layout_name', segment['layout']['name']),
                ('layout_digest', segment['layout']['digest']),
                ('segment_samples', segment['samples']), ('top_speed', segment['top_speed']),
                ('peak_load_N', segment['peak_load_N']), ('model', segment['model']),
                ('grade', segment['balance']['grade']),
                ('permissible_g_mm', segment['balance']['permissible_g_mm']),
                ('level', segment['verdict']['level']),
                ('verdict', segment['verdict']['verdict']),
                ('equivalent_grade', segment['verdict']['equivalent_grade']),
                ('verdict_source', segment['verdict']['source']),
                ('layout_level', segment['balance']['level']),
                ('layout_verdict', segment['balance']['verdict']),
                ('layout_equivalent_grade', segment['balance']['equivalent_grade'])):
            assert row[column] == value, (bag, column)
        assert dict(row['peak_support_load_N']) == segment['peak_support_load_N']
        identified = segment['identified']
        assert row['identified_readings'] == identified['readings']
        assert row['fit_rms_N'] == identified['fit']['rms_N']
        assert row['identified_level'] == identified['grade']['level']
        for k, p in enumerate(('I', 'II')):
            plane = segment['balance']['planes'][k]
            for key in ('z', 'g_mm', 'angle_deg', 'permissible_g_mm', 'fraction'):
                assert row[f'plane_{p}_{key}'] == plane[key], (bag, p, key)
            found = identified['identified']['planes'][k]
            assert row[f'identified_plane_{p}_g_mm'] == found['g_mm']
            assert row[f'identified_plane_{p}_g_mm_ci95'] == found['ci95_g_mm']
            assert row[f'residual_plane_{p}_g_mm'] == identified['residual']['planes'][k]['g_mm']
            assert row[f'identified_plane_{p}_fraction'] == identified['grade']['fractions'][k]


def test_replay_json_from_a_fresh_process(fleet):
    # The command itself, in its own process, for one bag of each kind.
    table = {row['bag']: row for row in pq.read_table(fleet['results']).to_pylist()}
    for bag in (min(b for b in table if b.endswith('.mcap')),
                min(b for b in table if not b.endswith('.mcap'))):
        done = subprocess.run([sys.executable, '-m', 'cvc_balance.cli', 'replay', bag, '--json'],
                              capture_output=True, text=True, timeout=120, check=True)
        record = json.loads(done.stdout)
        segment = record['segments'][0]
        assert table[bag]['identified_plane_II_g_mm'] == \
            segment['identified']['identified']['planes'][1]['g_mm']
        assert table[bag]['plane_I_g_mm'] == segment['balance']['planes'][0]['g_mm']


def test_replay_json_verdict_is_solves():
    # The bundled bag's first layout is config/ct_gantry.yaml, judged at its service speed:
    # replay --json's balance block must be solve --json's, key for key.
    code, out, err = run_cli('replay', ROOT / 'bags' / 'loose_bracket.mcap', '--json')
    assert code == 0, err
    replayed = json.loads(out)['segments'][0]['balance']
    code, out, err = run_cli('solve', LAYOUT, '--omega', 23.27, '--json')
    solved = json.loads(out)['balance']
    assert json.loads(out)['layout']['digest'] == \
        json.loads(run_cli('replay', ROOT / 'bags' / 'loose_bracket.mcap', '--json')[1])[
            'segments'][0]['layout']['digest']
    assert set(solved) <= set(replayed)
    for key, value in solved.items():
        assert replayed[key] == value, key
    assert replayed['static_g_mm'] == pytest.approx(
        json.loads(out)['static_unbalance']['kg_m'] * 1e6, rel=1e-12)


def test_damaged_bags_are_listed_and_the_rest_done(fleet):
    failures = pq.read_table(fleet['base'] / 'fleet.failures.parquet').to_pylist()
    reasons = {Path(row['bag']).name: row['reason'] for row in failures}
    assert set(reasons) == {'garbage.mcap', 'lost_file'}
    assert 'not an MCAP file' in reasons['garbage.mcap']
    assert 'missing' in reasons['lost_file'] or 'no readable bag file' in reasons['lost_file']
    assert all('\n' not in reason for reason in reasons.values())
    machines = {Path(row['bag']).parent.name: row['machine_id'] for row in failures}
    assert machines == {'gantry-0003': 'gantry-0003', 'gantry-0004': 'gantry-0004'}
    assert f'{MACHINES * RUNS} analysed' in fleet['out'] and '2 failed' in fleet['out']


def true_plane_unbalance(components, planes):
    """|U_I|, |U_II| (g mm) of point components by hand: S, P about O, ISO 21940-2's split."""
    s = sum(c['mass'] * c['radius'] * np.exp(1j * math.radians(c['angle_deg']))
            for c in components)
    p = sum(c['mass'] * c['radius'] * c.get('z', 0.0)
            * np.exp(1j * math.radians(c['angle_deg'])) for c in components)
    z_1, z_2 = planes
    return abs((s * z_2 - p) / (z_2 - z_1)) * 1e6, abs((p - s * z_1) / (z_2 - z_1)) * 1e6


def test_trends_recover_the_drift_put_in(fleet):
    # The slipping rear counterweight moves plane II. The truth: the real rotor's |U_II|
    # at each run, by hand, and its least-squares line over the same dates (what the fit
    # estimates, curvature and all). The fit's 95 % interval must hold it for most
    # machines (binomially, 95 % each), and the drift must be seen where it is large.
    trends = {t.machine_id: t for t in machine_trends(fleet['results'])}
    layout = yaml.safe_load(LAYOUT.read_text())
    planes = layout['balancing']['planes']
    inside, checked, leaving = 0, 0, 0
    for plan in fleet['plans']:
        if plan.kind != 'slipping counterweight':
            continue
        days = np.array([(r.when - plan.runs[0].when).total_seconds() / 86400
                         for r in plan.runs])
        truth = np.array([true_plane_unbalance(r.true_components, planes)[1]
                          for r in plan.runs])
        true_slope = np.polyfit(days, truth, 1)[0]
        fitted = next(p for p in trends[plan.machine_id].planes if p.plane == 'II')
        checked += 1
        inside += abs(fitted.drift - true_slope) <= fitted.drift_ci95
        leaving += trends[plan.machine_id].status == LEAVES
        # The identified amounts themselves sit on the truth (identify's own accuracy).
        assert np.all(np.abs(fitted.amount - truth) <= 2 * fitted.ci95 + 0.02 * truth)
    assert checked == MACHINES // 4
    assert inside >= checked - 1, (inside, checked)
    assert leaving >= 1


def test_trends_see_the_tube_swap_as_a_step_not_a_drift(fleet):
    trends = {t.machine_id: t for t in machine_trends(fleet['results'])}
    layout = yaml.safe_load(LAYOUT.read_text())
    planes = layout['balancing']['planes']
    inside = checked = still = 0
    for plan in fleet['plans']:
        if plan.kind != 'tube swap':
            continue
        machine = trends[plan.machine_id]
        assert len(machine.changes) == 1
        change = machine.changes[0]
        first_after = min(r.when for r in plan.runs if r.when >= plan.swap)
        assert abs(change.when - first_after) < timedelta(seconds=1)
        before = [true_plane_unbalance(r.true_components, planes)
                  for r in plan.runs if r.when < plan.swap]
        after = [true_plane_unbalance(r.true_components, planes)
                 for r in plan.runs if r.when >= plan.swap]
        for k, p in enumerate(('I', 'II')):
            true_step = after[0][k] - before[0][k]      # constant within each epoch
            step, half = change.steps[p]
            checked += 1
            inside += abs(step - true_step) <= half
            # No drift put in: 0 within the drift's 95 % interval (binomially, 95 % each;
            # measured 9 of 10, the interval 22 to 114 g mm/day).
            fitted = next(t for t in machine.planes if t.plane == p)
            still += abs(fitted.drift) <= fitted.drift_ci95
    assert inside >= checked - 1, (inside, checked)
    assert still >= checked - 1, (still, checked)


def test_a_second_run_adds_only_new_bags(fleet, tmp_path):
    results = tmp_path / 'fleet.parquet'
    shutil.copy(fleet['results'], results)
    shutil.copy(fleet['base'] / 'fleet.failures.parquet', tmp_path / 'fleet.failures.parquet')
    before = pq.read_table(results)
    more = tmp_path / 'later'
    added = simulate_fleet(LAYOUT, more, machines=3, runs=1, days=1.0,
                           start='2026-08-01T08:00:00', seed=8)
    code, out, err = run_cli('fleet', fleet['root'], more, '--out', results, '--engine',
                             'local', '--no-progress')
    assert code == 0, err
    first = out.splitlines()[0]
    assert re.fullmatch(rf'{MACHINES * RUNS + 5} bags found: 3 analysed \(3 rows, \d+ samples\), '
                        rf'{MACHINES * RUNS} already in {re.escape(str(results))}, 0 failed, '
                        r'2 failed before \(not retried: --retry-failures\)', first), first
    after = pq.read_table(results)
    assert after.num_rows == before.num_rows + 3
    assert after.slice(0, before.num_rows).equals(before)
    assert set(after.column('bag').to_pylist()[before.num_rows:]) == \
        {str(plan.runs[0].path) for plan in added}
    # Nothing new: nothing done, the table unchanged; a copy elsewhere is the same content.
    copied = tmp_path / 'copy'
    shutil.copytree(more, copied)
    code, out, err = run_cli('fleet', fleet['root'], more, copied, '--out', results,
                             '--engine', 'local', '--no-progress')
    assert code == 0, err
    first = out.splitlines()[0]
    assert re.fullmatch(rf'{MACHINES * RUNS + 8} bags found: 0 analysed \(0 rows, 0 samples\), '
                        rf'{MACHINES * RUNS + 6} already in {re.escape(str(results))}, 0 failed, '
                        r'2 failed before \(not retried: --retry-failures\)', first), first
    assert pq.read_table(results).equals(after)
    # Retrying failures replaces their rows, never doubles them.
    code, out, err = run_cli('fleet', fleet['root'], '--out', results, '--engine', 'local',
                             '--retry-failures', '--no-progress')
    assert code == 0 and '2 failed' in out
    assert pq.read_table(tmp_path / 'fleet.failures.parquet').num_rows == 2


def test_trends_charts_and_table(fleet, tmp_path):
    from PIL import Image
    code, out, err = run_cli('trends', fleet['results'], '-o', tmp_path / 'charts', '--top', 5)
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith('rank') and len(lines) >= 6
    pictures = sorted((tmp_path / 'charts').glob('gantry-*.png'))
    assert len(pictures) == MACHINES and (tmp_path / 'charts' / 'fleet.png').is_file()
    for picture in pictures[:4]:
        pixels = np.asarray(Image.open(picture).convert('RGB')).astype(int)
        assert pixels.shape[0] > 200 and pixels.shape[1] > 600
        red = (abs(pixels[..., 0] - 0xc0) < 20) & (pixels[..., 1] < 80) & (pixels[..., 2] < 80)
        blue = (abs(pixels[..., 0] - 0x1f) < 30) & (abs(pixels[..., 2] - 0x99) < 40)
        assert blue.sum() > 50             # the runs' points
        assert red.sum() > 100             # the permissible line
    overview = np.asarray(Image.open(tmp_path / 'charts' / 'fleet.png').convert('L'))
    assert (overview < 128).sum() > 1000   # machine names, text and bars drawn
    code, out, err = run_cli('trends', fleet['results'], '--json', '--machine', 'gantry-0001')
    machine = json.loads(out)['machines'][0]
    assert machine['machine_id'] == 'gantry-0001' and machine['runs'] == RUNS
    assert [p['plane'] for p in machine['planes']] == ['I', 'II']


def test_digest_is_sha256_of_the_documented_stream(fleet):
    bags = [b for b, _ in find_bags([fleet['root']])]
    a_file = next(b for b in bags if b.is_file())
    assert content_digest(a_file) == hashlib.sha256(a_file.read_bytes()).hexdigest()
    directory = next(b for b in bags if b.is_dir() and b.name != 'lost_file')
    expected = hashlib.sha256()
    for part in sorted(p for p in directory.iterdir() if p.is_file()):
        name = part.name.encode()
        expected.update(struct.pack('<Q', len(name)) + name)
        expected.update(struct.pack('<Q', part.stat().st_size) + part.read_bytes())
    assert content_digest(directory) == expected.hexdigest()


def test_machine_id_in_bags_read_by_others(tmp_path):
    from mcap.reader import make_reader
    from mcap.writer import Writer
    from rosbags.highlevel import AnyReader
    scenario = ROOT / 'bags' / 'spin_up_tube_swap.yaml'
    for output in (tmp_path / 'one.mcap', tmp_path / 'dir'):
        code, out, err = run_cli('simulate', scenario, '-o', output, '--machine-id',
                                 'site-a/gantry-17')
        assert code == 0, err
        files = [output] if output.suffix else sorted(output.glob('*.mcap'))
        with open(files[0], 'rb') as stream:
            reader = make_reader(stream, validate_crcs=True)
            records = [(m.name, m.metadata) for m in reader.iter_metadata()]
            # rosbag2's record when the file was opened and closed, ours after the first
            assert [name for name, _ in records] == ['rosbag2', 'cvc_balance', 'rosbag2']
            assert records[1][1] == {'machine_id': 'site-a/gantry-17'}
            for _, values in records[::2]:
                assert yaml.safe_load(values['serialized_metadata'])['custom_data'] == \
                    {'machine_id': 'site-a/gantry-17'}
            assert reader.get_summary().statistics.metadata_count == 3
            count = sum(1 for _ in reader.iter_messages())
        with AnyReader([output]) as bag:
            assert sum(1 for _ in bag.messages()) == count > 4000
        if output.is_dir():
            info = yaml.safe_load((output / 'metadata.yaml').read_text())
            assert info['rosbag2_bagfile_information']['custom_data'] == \
                {'machine_id': 'site-a/gantry-17'}
        assert machine_of(output) == ('site-a/gantry-17', 'bag')
    # A foreign file carrying rosbag2's own record (what its MCAP storage writes).
    foreign = tmp_path / 'site' / 'gantry-9' / 'run.mcap'
    foreign.parent.mkdir(parents=True)
    with open(foreign, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        # as rosbag2's MCAP storage writes it: the metadata itself, no outer key
        writer.add_metadata('rosbag2', {'serialized_metadata': yaml.safe_dump(
            {'version': 9, 'custom_data': {'machine_id': 'gantry-9b'}})})
        writer.finish()
    assert machine_of(foreign, tmp_path) == ('gantry-9b', 'bag')
    # No id anywhere: the folder below the root searched; a truncated file keeps its record.
    plain = tmp_path / 'site' / 'gantry-9' / 'plain.mcap'
    shutil.copy(ROOT / 'bags' / 'tilted_shift.mcap', plain)
    assert machine_of(plain, tmp_path) == ('site/gantry-9', 'path')
    truncated = tmp_path / 'cut.mcap'
    truncated.write_bytes((tmp_path / 'one.mcap').read_bytes()[:5000])
    assert machine_of(truncated) == ('site-a/gantry-17', 'bag')


@pytest.mark.parametrize('argv, says', [
    (['fleet', '/no/such/place', '--out', 'x.parquet'], 'no such file or directory'),
    (['fleet', 'bags', '--out', 'README.md'], 'not a readable Parquet table'),
    (['fleet', 'bags', '--out', 'x.parquet', '--engine', 'local', '--scheduler',
      'tcp://127.0.0.1:1'], '--scheduler needs --engine dask'),
    (['trends', '/no/such.parquet'], 'no such results table'),
    (['trends', 'README.md'], 'not a fleet results table'),
    (['simulate-fleet', 'config/thesis_two_particles.yaml', '-o', 'x'], "no component"),
    (['simulate', 'bags/spin_up_tube_swap.yaml', '-o', 'x.mcap', '--machine-id', 'a b'],
     'machine id'),
    (['simulate-fleet', 'config/ct_gantry.yaml', '-o', 'x', '--steady', '0'],
     '--steady: must be from 0.01 to 86400 s'),
])
def test_bad_input_one_line_exit_2(argv, says, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    readme = (ROOT / 'README.md').read_bytes()
    argv = [str(tmp_path / a) if a in ('x', 'x.parquet', 'x.mcap') else a for a in argv]
    code, out, err = run_cli(*argv)
    assert code == 2, (code, out, err)
    assert says in err and err.count('\n') == 1 and 'Traceback' not in err
    assert (ROOT / 'README.md').read_bytes() == readme


def test_node_and_recorder_write_the_machine_id(tmp_path):
    # The node's machine_id parameter and `cvc-balance record --machine-id`, as processes
    # on this test run's own ROS domain: their recordings carry the id.
    own = tmp_path / 'node_run'
    node = NodeProcess('cvc_balance.ros.balance_monitor',
                       ['-p', f'record_path:={own}', '-p', 'machine_id:=site-b/gantry-0042',
                        '-p', f'layout_file:={LAYOUT}'], tmp_path / 'node.log')
    record = subprocess.Popen([sys.executable, '-m', 'cvc_balance.cli', 'record', '-o',
                               str(tmp_path / 'rec.mcap'), '--machine-id', 'gantry-0043'],
                              env=ros_environment(), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (
            any(own.glob('*.mcap')) and (tmp_path / 'rec.mcap').exists()):
        time.sleep(0.2)
    time.sleep(1.0)
    record.send_signal(signal.SIGINT)
    out, err = record.communicate(timeout=30)
    assert record.returncode == 0, err
    assert node.stop(signal.SIGINT) == 0, node.log()
    assert machine_of(own) == ('site-b/gantry-0042', 'bag')
    assert yaml.safe_load((own / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data'] == {'machine_id': 'site-b/gantry-0042'}
    assert machine_of(tmp_path / 'rec.mcap') == ('gantry-0043', 'bag')


def test_simulate_fleet_steady_lengthens_each_run(tmp_path):
    """
    ``--steady SECONDS`` at the service speed: 7 s more steady running, 700 more samples.

    Counted by rosbags in the bags written (one machine, one run, 100 Hz encoder and cells);
    the spin-up and coast-down are the same.
    """
    from rosbags.highlevel import AnyReader
    counts = {}
    for steady in (3, 10):
        out = tmp_path / f'steady{steady}'
        code, text, err = run_cli('simulate-fleet', LAYOUT, '-o', out, '--machines', 1,
                                  '--runs', 1, '--steady', steady)
        assert code == 0, err
        (bag, _), = find_bags([out])
        with AnyReader([bag]) as reader:
            counts[steady] = {c.topic: c.msgcount for c in reader.connections}
    assert {t: counts[10][t] - counts[3][t] for t in counts[3] if t != '/layout'} == {
        '/joint_states': 700, '/supports/front/measured_load': 700,
        '/supports/rear/measured_load': 700}


def test_digest_tasks_split_by_bytes_and_count():
    """Ten-minute runs (106 MB) one a task; small checks 32 a task; never an empty task."""
    from cvc_balance.fleet.engine import DIGEST_BATCH, DIGEST_BYTES, digest_batches
    assert (DIGEST_BATCH, DIGEST_BYTES) == (32, 64 << 20)
    big = [f'b{i}' for i in range(5)]
    assert digest_batches(big, [106 << 20] * 5) == [[b] for b in big]
    small = [f's{i}' for i in range(70)]
    assert digest_batches(small, [140 << 10] * 70) == [small[:32], small[32:64], small[64:]]
    mixed = digest_batches(['a', 'b', 'c', 'd'], [40 << 20, 20 << 20, 10 << 20, 0])
    assert mixed == [['a', 'b'], ['c', 'd']]           # 60 MB, then 10 MB (+ unknown size)
    assert digest_batches([], []) == []


def test_a_worker_imports_only_what_its_tasks_need():
    """
    A Dask worker imports ``fleet.tasks``: not the trends' scipy.stats and DuckDB, nor Dask.

    In a fresh process; the package's public names still there when asked for.
    """
    code = ('import sys, cvc_balance.fleet.tasks\n'
            'print(sorted(m for m in ("scipy.stats", "duckdb", "dask", "distributed", '
            '"matplotlib") if m in sys.modules))\n'
            'from cvc_balance.fleet import run_fleet, machine_trends, FleetReport\n'
            'print(run_fleet.__module__, machine_trends.__module__, FleetReport.__name__)')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          check=True, cwd=ROOT)
    assert done.stdout.splitlines() == [
        '[]', 'cvc_balance.fleet.engine cvc_balance.fleet.trends FleetReport']
