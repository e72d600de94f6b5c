"""
Mutation testing of the physics and the contract modules, module by module (mutmut).

Each module is mutated with mutmut (``requirements-mutation.txt``, installed into the
environment on first use) in a copy of the work tree, against the tests that guard it
(:data:`MODULES`): mutmut runs, for each mutant, only those of them that call the
mutated function. Prints per module killed / total and the kill rate, writes the
surviving mutants' diffs to ``<work>/<module>/survivors.txt`` and a summary to
``<work>/summary.json``. Outside CI (it takes a while): on this 2-core machine, run it
at low priority::

    nice -n 19 ./dev.sh run python benchmarks/mutation.py            # every module
    nice -n 19 ./dev.sh run python benchmarks/mutation.py engine motion   # some

A mutant is killed when a test fails (or it times out, or the type of its crash is a
test failure); it survives when every test that reaches it passes; "no tests" means
no selected test calls the mutated function.
"""

import argparse
import json
import os
from pathlib import Path
import shutil
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
REQUIREMENTS = ROOT / 'requirements-mutation.txt'

PHYSICS = ['test/test_pinocchio.py', 'test/test_thesis.py', 'test/test_edge_cases.py',
           'test/test_methods.py']
"""Fast and independent: Pinocchio, the thesis, the 40-digit reference. The hypothesis
properties, the model choice's replays and the whole pipelines (rerun, the node) are left
out: a surviving mutant runs every selected test, and those took minutes each."""
FLEET = ['test/test_survivors.py', 'test/test_independent_fleet.py', 'test/test_data_loss.py',
         'test/test_charts.py']
"""The fleet's tests: by hand and against the simulation's per-bag truths. Not
test/test_fleet.py: its module fixture (100 bags through a Dask LocalCluster, ~20 s) is
made again for every mutant."""
MODULES = {
    # name: (module file, tests that guard it)
    'engine': ('cvc_balance/physics/engine.py', PHYSICS),
    'layout': ('cvc_balance/physics/layout.py',
               ['test/test_layout.py', 'test/test_layout_messages.py',
                'test/test_hostile_layouts.py', 'test/test_field_layout.py',
                'test/test_edge_cases.py', 'test/test_unbalance.py']),
    'component_table': ('cvc_balance/physics/component_table.py',
                        ['test/test_layout_columns.py']),
    'layout_file': ('cvc_balance/physics/layout_file.py',
                    ['test/test_layout_columns.py', 'test/test_hostile_layouts.py',
                     'test/test_layout.py']),
    'inertia': ('cvc_balance/physics/inertia.py', PHYSICS + ['test/test_stability.py']),
    'compensated': ('cvc_balance/physics/compensated.py',
                    ['test/test_independent_compensated.py', 'test/test_compensated.py',
                     'test/test_stability.py', 'test/test_pinocchio.py']),
    'motion': ('cvc_balance/physics/motion.py',
               ['test/test_motion.py', 'test/test_stamp_gate.py', 'test/test_edge_cases.py']),
    'unbalance': ('cvc_balance/physics/unbalance.py',
                  ['test/test_unbalance.py', 'test/test_edge_cases.py',
                   'test/test_layout_messages.py']),
    'iso21940': ('cvc_balance/physics/iso21940.py',
                 ['test/test_unbalance.py', 'test/test_edge_cases.py',
                  'test/test_layout_messages.py']),
    'assessment': ('cvc_balance/physics/assessment.py',
                   ['test/test_unbalance.py', 'test/test_edge_cases.py',
                    'test/test_layout_messages.py']),
    'model_choice': ('cvc_balance/physics/model_choice.py',
                     ['test/test_model_choice.py', 'test/test_edge_cases.py']),
    'replay': ('cvc_balance/bag/replay.py',
               ['test/test_survivors.py', 'test/test_bags.py', 'test/test_edge_cases.py']),
    'mcap_writer': ('cvc_balance/bag/mcap_writer.py',
                    ['test/test_mcap_conformance.py', 'test/test_bags.py',
                     'test/test_edge_cases.py']),
    'mcap_reader': ('cvc_balance/bag/mcap_reader.py',
                    ['test/test_survivors.py', 'test/test_mcap_conformance.py',
                     'test/test_reindex.py', 'test/test_bags.py', 'test/test_edge_cases.py']),
    'scenario': ('cvc_balance/bag/scenario.py', ['test/test_bags.py']),
    'cdr': ('cvc_balance/messages/cdr.py',
            ['test/test_cdr.py', 'test/test_edge_cases.py', 'test/test_bags.py']),
    # Measured loads, field balancing and design: their own hand- and Pinocchio-checked tests.
    'identify_regressors': ('cvc_balance/identify/regressors.py', ['test/test_identify.py']),
    'identify_fit': ('cvc_balance/identify/fit.py', ['test/test_identify.py']),
    'identify_estimate': ('cvc_balance/identify/estimate.py', ['test/test_identify.py']),
    'field_influence': ('cvc_balance/field/influence.py',
                        ['test/test_field.py', 'test/test_field_checks.py']),
    'field_correction': ('cvc_balance/field/correction.py',
                         ['test/test_field.py', 'test/test_field_checks.py']),
    'design_sensitivity': ('cvc_balance/design/sensitivity.py', ['test/test_design.py']),
    # Issue 29: the modules the earlier runs skipped or stopped, and the new ones.
    'limits': ('cvc_balance/physics/limits.py',
               ['test/test_independent_limits.py', 'test/test_validation_limits.py',
                'test/test_layout_columns.py',
                'test/test_layout_messages.py']),
    'documents': ('cvc_balance/physics/documents.py',
                  ['test/test_validation_limits.py', 'test/test_layout_columns.py',
                   'test/test_hostile_layouts.py']),
    'keyphasor': ('cvc_balance/physics/keyphasor.py',
                  ['test/test_independent_keyphasor.py', 'test/test_keyphasor.py']),
    'identify_evidence': ('cvc_balance/identify/evidence.py',
                          ['test/test_survivors.py', 'test/test_evidence.py',
                           'test/test_verdict_units.py']),
    'identify_mistakes': ('cvc_balance/identify/mistakes.py',
                          ['test/test_input_mistakes.py', 'test/test_field_mistakes.py']),
    'identify_live': ('cvc_balance/identify/live.py',
                      ['test/test_survivors.py', 'test/test_identify.py']),
    'field_plan': ('cvc_balance/field/plan.py',
                   ['test/test_survivors.py', 'test/test_field.py', 'test/test_field_plans.py']),
    'field_model_check': ('cvc_balance/field/model_check.py',
                          ['test/test_field_mistakes.py', 'test/test_field_procedure.py']),
    'field_search': ('cvc_balance/field/search.py', ['test/test_field_plans.py']),
    # The node's pure parts: in this process (the node itself runs in another).
    'ros_input_checks': ('cvc_balance/ros/input_checks.py',
                         ['test/test_independent_input_checks.py']),
    'ros_bearing_life': ('cvc_balance/ros/bearing_life.py',
                         ['test/test_independent_ros_bearing_life.py']),
    'ros_keyphasor_input': ('cvc_balance/ros/keyphasor_input.py',
                            ['test/test_independent_ros_keyphasor.py']),
    'ros_load_cells': ('cvc_balance/ros/load_cells.py',
                       ['test/test_independent_ros_load_cells.py']),
    'ros_recorder': ('cvc_balance/ros/recorder.py', ['test/test_independent_ros_recorder.py']),
    'ros_qos': ('cvc_balance/ros/qos.py', ['test/test_independent_ros_node_parts.py']),
    'ros_executor': ('cvc_balance/ros/executor.py', ['test/test_independent_ros_node_parts.py']),
    # The module functions (prepare_layout, recording_label, _text, usage, main's refusals:
    # --mutants '*balance_monitor.x_*') and the node class in process (its callbacks
    # called directly: test_independent_ros_balance_monitor.py, and with its options on:
    # test_independent_ros_node_options.py; check its mutants with mutants_in_process.py,
    # one process; docs/mutation.md).
    'ros_balance_monitor': ('cvc_balance/ros/balance_monitor.py',
                            ['test/test_independent_ros_node_parts.py',
                             'test/test_independent_ros_balance_monitor.py',
                             'test/test_independent_ros_node_options.py']),
    **{f'fleet_{name}': (f'cvc_balance/fleet/{name}.py', FLEET)
       for name in ('discover', 'digest', 'rows', 'store', 'tasks', 'trends', 'engine',
                    'simulate')},
    # The charts: what they draw (the figure's objects) and how (reference pictures).
    'fleet_charts': ('cvc_balance/fleet/charts.py',
                     ['test/test_chart_pictures.py', 'test/test_independent_charts.py',
                      'test/test_charts.py']),
}
DESELECT = [
    # Tests that start ROS processes or the rerun viewer: slow, and they reach the
    # modules through other processes, which mutmut's test selection cannot see.
    'test/test_bags.py::test_recorder_killed_with_sigkill_leaves_all_but_the_last_chunk',
    'test/test_bags.py::test_rerun_opens_a_project_bag',
    # The command line's refusals start a process per case (about 1 s each, for each of
    # layout.py's 760 mutants): test_layout_messages.py has their in-process half, every
    # message in full.
    'test/test_layout.py::test_bad_layout_gets_one_line_and_exit_code_2',
    'test/test_layout.py::test_yaml_nan_is_rejected',
    'test/test_layout.py::test_unreadable_and_malformed_files',
    'test/test_layout.py::test_bad_speed_on_the_command_line',
    'test/test_layout.py::test_solve_table_names_every_support_and_the_verdict',
]
MILLION = ['test/test_stability.py::test_a_million_components_keep_a_residual_of_1e_11_of_'
           'their_mass_moment',
           'test/test_stability.py::test_float64_sums_lose_the_million_component_residual']
"""Ten seconds and more a run: they guard the compensated sums (kept for that module)."""
FRESH = {'compensated', 'inertia'}
"""Modules whose kernels are traced and cached per process: each test starts without them
(benchmarks/fresh_programs.py), else mutmut puts the tracing code down to the first test
that traced it and tests its mutants with that test only."""
COPY = ('cvc_balance', 'test', 'config', 'bags', 'docs', 'resource', 'pytest.ini',
        'package.xml', 'setup.py', 'setup.cfg')


def ensure_mutmut():
    """Install the pinned mutmut into this environment if it is not there."""
    try:
        import mutmut  # noqa: F401
    except ImportError:
        subprocess.run([sys.executable, '-m', 'pip', 'install', '-q', '-r', str(REQUIREMENTS)],
                       check=True)


def toml_list(values):
    return '[' + ', '.join(json.dumps(str(v)) for v in values) + ']'


def prepare(work, module, tests, deselected=(), fresh=False):
    """
    Copy the tree (tracked and new files) to ``work``, with mutmut's settings for a module.

    ``fresh``: load benchmarks/fresh_programs.py (copied to ``work``/plugins) in every test run.
    """
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    listed = subprocess.run(['git', 'ls-files', '-co', '--exclude-standard'], cwd=ROOT,
                            capture_output=True, text=True).stdout.split('\n')
    if listed == ['']:          # not a git checkout (an exported tree): every file
        listed = [str(p.relative_to(ROOT)) for p in ROOT.rglob('*') if p.is_file()]
    for name in listed:
        if name and name.split('/')[0] in COPY and (ROOT / name).is_file():
            target = work / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, target)
    present = [t for t in tests if (work / t.split('::')[0]).exists()]   # files or test ids
    deselect = DESELECT + ([] if module.endswith('compensated.py') else MILLION) + list(deselected)
    args = ['-p', 'no:cacheprovider', '-q'] + [f'--deselect={d}' for d in deselect]
    if fresh:
        (work / 'plugins').mkdir()
        shutil.copy2(ROOT / 'benchmarks' / 'fresh_programs.py', work / 'plugins')
        args += ['-p', 'fresh_programs']
    (work / 'pyproject.toml').write_text(
        '[tool.mutmut]\n'
        'source_paths = ["cvc_balance"]\n'
        f'only_mutate = {toml_list([module])}\n'
        f'pytest_add_cli_args = {toml_list(args)}\n'
        f'pytest_add_cli_args_test_selection = {toml_list(present)}\n'
        f'also_copy = {toml_list(["config", "bags", "docs", "resource", "pytest.ini"])}\n'
        'use_git_change_detection = false\n'
        'process_isolation = "forkserver"\n'
        'timeout_multiplier = 8.0\n'
        'timeout_constant = 10.0\n')
    return present


def run_module(name, work, children, tests=None, deselected=(), mutants=()):
    """
    Run mutmut on one module; return its counts and the survivors' diffs.

    ``mutants``: names (fnmatch patterns, e.g. ``*xǁBagǁ_walk__mutmut_*``) of the only
    mutants tested; the others count as not checked.
    """
    module, guarding = MODULES[name]
    fresh = name in FRESH
    present = prepare(work, module, tests or guarding, deselected, fresh)
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE='1', RERUN_TELEMETRY_ENABLED='false')
    if fresh:
        env['PYTHONPATH'] = os.pathsep.join(
            [str(work / 'plugins')] + [p for p in [os.environ.get('PYTHONPATH')] if p])
    started = time.monotonic()
    log = open(work / 'mutmut.log', 'w')
    subprocess.run([sys.executable, '-m', 'mutmut', 'run', '--max-children', str(children),
                    *mutants], cwd=work, env=env, stdout=log, stderr=subprocess.STDOUT)
    seconds = time.monotonic() - started
    subprocess.run([sys.executable, '-m', 'mutmut', 'export-cicd-stats'], cwd=work, env=env,
                   stdout=log, stderr=subprocess.STDOUT)
    stats_path = work / 'mutants' / 'mutmut-cicd-stats.json'
    if not stats_path.exists():
        raise SystemExit(f'{name}: mutmut gave no results; see {work / "mutmut.log"}')
    stats = json.loads(stats_path.read_text())
    results = subprocess.run([sys.executable, '-m', 'mutmut', 'results'], cwd=work, env=env,
                             capture_output=True, text=True).stdout
    survivors = []
    for line in results.splitlines():
        mutant, _, status = line.strip().rpartition(': ')
        if mutant and status != 'not checked':
            diff = subprocess.run([sys.executable, '-m', 'mutmut', 'show', mutant], cwd=work,
                                  env=env, capture_output=True, text=True).stdout
            survivors.append((mutant, status, diff))
    with open(work / 'survivors.txt', 'w') as stream:
        for mutant, status, diff in survivors:
            stream.write(f'## {mutant}: {status}\n{diff}\n')
    return {'module': module, 'tests': present, 'deselected': list(deselected),
            'mutants': list(mutants), 'seconds': round(seconds, 1), **stats}


def main():
    """Run the modules asked for (default all) and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('modules', nargs='*', metavar='MODULE',
                        help=f'modules to mutate (default: all): {", ".join(MODULES)}')
    parser.add_argument('--work', type=Path, default=Path('/tmp/cvc_balance_mutation'),
                        help='where the copies go (default %(default)s)')
    parser.add_argument('--children', type=int, default=2, help='mutants tested at once')
    parser.add_argument('--tests', nargs='+', metavar='FILE',
                        help="test files (or test ids, file::name) to run instead of the "
                             "module's own (MODULES): a narrower, faster selection, given in "
                             'docs/mutation.md with its results')
    parser.add_argument('--deselect', nargs='+', default=[], metavar='TEST',
                        help='tests (pytest node ids) left out besides DESELECT')
    parser.add_argument('--mutants', nargs='+', default=[], metavar='PATTERN',
                        help="only the mutants of these names (fnmatch patterns, as mutmut's "
                             "names: '*xǁBagǁ_walk__mutmut_*' for a method, "
                             "'*x_decode__mutmut_*' for a function)")
    args = parser.parse_args()
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        parser.error(f'unknown module {unknown[0]!r} (known: {", ".join(MODULES)})')
    ensure_mutmut()
    summary_path = args.work / 'summary.json'
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    for name in args.modules or list(MODULES):
        row = run_module(name, args.work / name, args.children, args.tests, args.deselect,
                         args.mutants)
        summary[name] = row
        args.work.mkdir(parents=True, exist_ok=True)
        summary_path.write_text(json.dumps(summary, indent=1))
        print(f"{name:13} killed {row['killed']:4d} of {row['total']:4d} "
              f'({100.0 * row["killed"] / max(row["total"], 1):5.1f} %), '
              f"survived {row['survived']}, no tests {row['no_tests']}, "
              f"timeout {row['timeout']}, {row['seconds']:.0f} s", flush=True)
    print('\n| module | killed / total | kill rate | survived | no tests | timeout |')
    print('|---|---|---|---|---|---|')
    for name, row in summary.items():
        print(f"| {name} | {row['killed']} / {row['total']} | "
              f"{100.0 * row['killed'] / max(row['total'], 1):.1f} % | {row['survived']} | "
              f"{row['no_tests']} | {row['timeout']} |")


if __name__ == '__main__':
    main()
