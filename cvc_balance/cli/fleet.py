"""
``cvc-balance fleet``, ``trends`` and ``simulate-fleet``: every run of every machine.

``fleet PATH... --out RESULTS`` analyses each bag not yet in RESULTS (by content digest)
on Dask (an embedded LocalCluster, or ``--scheduler``) or in this process, into a Parquet
table and a table of failures; ``trends RESULTS`` fits each machine's drift per plane and
ranks the machines by when they leave their grade (``--rank life``: by their bearings'
life left at the current duty); ``simulate-fleet`` writes a fleet of simulated runs to try
both on (the docs' "Watch a fleet").
"""

import argparse
from datetime import datetime, timezone
import math
from pathlib import Path
import sys

from cvc_balance.cli.arguments import add_bounded, input_file, input_path, print_json
from cvc_balance.physics import limits


def register(commands):
    """Add fleet, trends and simulate-fleet."""
    fleet = commands.add_parser(
        'fleet', help='analyse every new bag under some paths, on Dask, into a Parquet table',
        description='Find every bag (.mcap, .db3, rosbag2 directory) under the paths, replay '
        'each one not yet in RESULTS (same content digest) on Dask workers, and add a row per '
        'run and layout segment to RESULTS (Parquet); bags that fail are listed with the '
        'reason in RESULTS.failures.parquet and the run goes on.')
    fleet.add_argument('paths', nargs='+', type=input_path, metavar='PATH',
                       help='bags or folders of bags')
    fleet.add_argument('--out', required=True, metavar='RESULTS',
                       help='the results table (.parquet), made or added to')
    fleet.add_argument('--engine', choices=('dask', 'local'), default='dask',
                       help='dask (default: a LocalCluster of worker processes, or '
                       '--scheduler) or local (this process, no Dask)')
    fleet.add_argument('--scheduler', metavar='ADDRESS',
                       help="an existing Dask scheduler (tcp://host:8786) whose workers see "
                       "the same paths and have cvc_balance installed")
    add_bounded(fleet, '--workers', limit=limits.WORKERS, metavar='N',
                help='LocalCluster worker processes (default: the cores, at most 2)')
    add_bounded(fleet, '--batch', limit=limits.BATCH, metavar='N',
                help='bags per task (default: small bags together, up to ~4 MB and 16 bags a '
                'task; large ones alone)')
    fleet.add_argument('--retry-failures', action='store_true',
                       help='analyse again the bags listed as failed before')
    fleet.add_argument('--progress', action=argparse.BooleanOptionalAction, default=None,
                       help='progress bar (default: on a terminal)')
    fleet.add_argument('--json', action='store_true', help='print the run\'s report as JSON')
    fleet.set_defaults(run=_fleet)

    trends = commands.add_parser(
        'trends', help="each machine's unbalance over time, its drift, when it leaves grade",
        description='Per machine and correction plane: the unbalance of every run (identified '
        "from load cells where there are some, else the layout's) against its grade, a drift "
        'fitted across layout changes with its 95 % interval, and the date it is projected '
        'to leave the grade; the machines ranked by urgency.')
    trends.add_argument('results', type=input_path, metavar='RESULTS',
                        help='a table written by fleet')
    trends.add_argument('--machine', metavar='M', help='only this machine')
    trends.add_argument('-o', '--output', metavar='DIR', help='write a chart per machine '
                        '(DIR/<machine>.png), the urgency chart (DIR/fleet.png) and the '
                        'table (DIR/trends.csv)')
    trends.add_argument('--now', type=_date, metavar='DATE', help='project from this date '
                        '(ISO 8601, UTC; default: each machine\'s last run)')
    add_bounded(trends, '--top', limit=limits.TOP, metavar='N',
                help='list only the N most urgent')
    trends.add_argument('--rank', choices=('grade', 'life'), default='grade',
                        help='rank the machines by when they leave their grade (default) or '
                        "by their bearings' life: the running hours a bearing has left at "
                        'the current duty (the latest layout\'s runs), fewest first; the '
                        'layouts must describe the bearings (supports[].bearing)')
    trends.add_argument('--json', action='store_true', help='print one JSON object')
    trends.set_defaults(run=_trends)

    simulate = commands.add_parser(
        'simulate-fleet', help='simulated runs of many machines over months, with drifts',
        description='Write N machines x M runs (daily checks with load cells) over DAYS days '
        'as bags under DIR/<machine>/ (.mcap files and rosbag2 directories), each stamped with '
        'its machine id and date: slipping counterweights, tube swaps, steady machines.')
    simulate.add_argument('layout', type=input_file, metavar='LAYOUT',
                          help='layout of every machine (with components counterweight_rear '
                          'and xray_tube)')
    simulate.add_argument('-o', '--output', required=True, metavar='DIR')
    add_bounded(simulate, '--machines', limit=limits.MACHINES, default=20, metavar='N')
    add_bounded(simulate, '--runs', limit=limits.RUNS, default=5, metavar='M')
    add_bounded(simulate, '--days', limit=limits.DAYS, default=180.0, metavar='DAYS')
    simulate.add_argument('--start', type=_date, default=datetime(2026, 1, 5, 8,
                                                                  tzinfo=timezone.utc),
                          metavar='DATE', help='first run (ISO 8601, UTC)')
    add_bounded(simulate, '--seed', limit=limits.SEED, default=0, metavar='S')
    add_bounded(simulate, '--rate', limit=limits.SAMPLE_RATE, default=100.0, metavar='HZ',
                help='encoder samples/s (default 100)')
    add_bounded(simulate, '--cell-rate', limit=limits.SAMPLE_RATE, default=100.0,
                metavar='HZ', help='load-cell readings/s (default 100)')
    add_bounded(simulate, '--steady', limit=limits.STEADY, default=3.0, metavar='SECONDS',
                help="each run's time at the service speed (default 3; 596 makes 10-minute "
                'runs)')
    simulate.set_defaults(run=_simulate)


def _date(text):
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an ISO 8601 date: {text!r}') from None
    return when.replace(tzinfo=timezone.utc) if when.tzinfo is None \
        else when.astimezone(timezone.utc)


def _fleet(args):
    from cvc_balance.files import check_output
    from cvc_balance.fleet.engine import run_fleet
    from cvc_balance.fleet.store import failures_path, lock_path
    for table in (args.out, failures_path(args.out), lock_path(args.out)):
        check_output(table)          # before any work: the folder exists and can be written
    report = run_fleet(args.paths, args.out, engine=args.engine, scheduler=args.scheduler,
                       workers=args.workers, progress=args.progress,
                       retry_failures=args.retry_failures, batch=args.batch)
    if args.json:
        data = dict(vars(report))
        data['new_failures'] = [{'bag': b, 'reason': r} for b, r in report.new_failures]
        print_json(data)
        return 0
    rate = report.analysed / report.analysis_seconds if report.analysis_seconds else 0.0
    print(f'{report.found} bags found: {report.analysed} analysed ({report.rows} rows, '
          f'{report.samples} samples), {report.already} already in {report.results}, '
          f'{report.failed} failed'
          + (f', {report.failed_before} failed before (not retried: --retry-failures)'
             if report.failed_before else '')
          + (f', {report.duplicates} duplicates of another bag' if report.duplicates else ''))
    print(f'engine {report.engine} ({report.workers} worker{"s" * (report.workers != 1)}, '
          f'{report.batch} bag{"s" * (report.batch != 1)} a task): '
          f'{report.seconds:.2f} s in all, digests {report.digest_seconds:.2f} s, analysis '
          f'{report.analysis_seconds:.2f} s ({rate:.1f} bags/s)')
    if report.new_failures:
        print(f'failed (in {report.failures}):')
        for bag, reason in report.new_failures:
            print(f'  {bag}: {reason}')
    return 0


def _trends(args):
    from cvc_balance.files import check_output
    from cvc_balance.fleet.trends import life_ranked, machine_trends, trend_summary
    if not Path(args.results).is_file():
        raise FileNotFoundError(f'{args.results}: no such results table (make it with '
                                'cvc-balance fleet PATH --out RESULTS)')
    if args.output:         # before the work: a folder that can be written, not the table
        check_output(args.output, [args.results], directory=True)
    try:
        trends = machine_trends(args.results, args.machine, args.now)
    except Exception as error:
        if type(error).__module__.startswith(('duckdb', '_duckdb')):
            raise ValueError(f'{args.results}: not a fleet results table '
                             f'({str(error).splitlines()[0]})') from None
        raise
    if args.machine is not None and not trends:
        raise ValueError(f'{args.results}: no runs of machine {args.machine!r}')
    if args.rank == 'life':
        trends = life_ranked(trends)
    shown = trends[:args.top] if args.top else trends
    row = _life_row if args.rank == 'life' else _row
    rows = [row(rank, trend) for rank, trend in enumerate(shown, 1)]
    if args.output:         # charts and table moved in together once all are written
        from cvc_balance.files import moved_into_when_done
        with moved_into_when_done(args.output) as staging:
            _write_outputs(staging, trends, rows)
    if args.json:
        print_json({'results': str(args.results), 'machines': [
            dict(trend_summary(t), rank=rank) for rank, t in enumerate(shown, 1)]})
        return 0
    print(_table(rows))
    if args.output:
        print(f'charts and table in {args.output}/ (fleet.png, <machine>.png, trends.csv)')
    return 0


def _row(rank, trend):
    worst = next((p for p in trend.planes if p.plane == trend.worst_plane), None)

    def day(when):
        return f'{when:%Y-%m-%d}' if when is not None else ''
    drift = '' if worst is None or not math.isfinite(worst.drift) else \
        f'{worst.drift:+.0f} +- {worst.drift_ci95:.0f}'
    interval = ''
    if worst is not None and worst.leaves is not None:
        interval = f'{day(worst.leaves_earliest)} .. {day(worst.leaves_latest) or "never"}'
    change = ''
    if trend.changes and worst is not None:
        step = trend.changes[-1].steps.get(worst.plane, (math.nan, math.nan))
        if math.isfinite(step[0]):
            change = f'{day(trend.changes[-1].when)} {step[0]:+.0f} +- {step[1]:.0f}'
    return {'rank': rank, 'machine': trend.machine_id, 'status': trend.status,
            'plane': trend.worst_plane or '',
            'of grade now': f'{worst.now_fraction:.2f}' if worst is not None else '',
            'drift [g mm/day]': drift, 'leaves grade': day(trend.leaves),
            '95 % interval': interval, 'runs': str(trend.runs), 'last run': day(trend.last),
            'last layout change [g mm]': change}


def _life_row(rank, trend):
    """Return a machine's line ranked by bearing life: the bearing with fewest hours left."""
    worst = trend.worst_bearing

    def number(value, form):
        return '' if value is None else format(value, form)
    if worst is None:
        return {'rank': rank, 'machine': trend.machine_id, 'bearing': 'none described',
                'life used': '', 'per running hour': '', 'hours left': '',
                'rating life reached': '', 'runs': str(trend.runs),
                'last run': f'{trend.last:%Y-%m-%d}'}
    return {'rank': rank, 'machine': trend.machine_id, 'bearing': worst.support,
            'life used': f'{worst.life_used:.3g}',
            'per running hour': number(worst.duty_per_hour, '.3g'),
            'hours left': number(worst.left_hours, '.4g'),
            'rating life reached': f'{worst.worn_out:%Y-%m-%d}' if worst.worn_out else
            ('beyond 10 years' if worst.duty_per_day else ''),
            'runs': str(worst.runs), 'last run': f'{trend.last:%Y-%m-%d}'}


def _table(rows):
    if not rows:
        return 'no machine with judged runs in the table'
    keys = list(rows[0])
    cells = [keys] + [[str(row[k]) for k in keys] for row in rows]
    widths = [max(len(line[i]) for line in cells) for i in range(len(keys))]
    return '\n'.join('  '.join(c.ljust(w) for c, w in zip(line, widths)).rstrip()
                     for line in cells)


def _write_outputs(directory, trends, rows):
    import csv
    from cvc_balance.fleet.charts import chart_name, fleet_chart, machine_chart
    for trend in trends:
        machine_chart(trend, directory / chart_name(trend.machine_id))
    fleet_chart(trends, directory / 'fleet.png')
    with open(directory / 'trends.csv', 'w', newline='', encoding='utf-8') as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]) if rows else ['rank'])
        writer.writeheader()
        writer.writerows(rows)


def _simulate(args):
    from cvc_balance.files import check_output
    from cvc_balance.fleet.simulate import simulate_fleet
    from cvc_balance.physics.documents import dump_document
    check_output(args.output, [args.layout], directory=True)     # before the work
    plans = simulate_fleet(args.layout, args.output, args.machines, args.runs, args.days,
                           args.start.replace(tzinfo=None).isoformat(), args.seed, args.rate,
                           args.cell_rate, steady=args.steady)
    truth = [{'machine_id': p.machine_id, 'kind': p.kind,
              'slip_mm_per_day': p.slip_mm_per_day,
              'tube_swap': p.swap.isoformat() if p.swap else None,
              'tube_extra_kg': p.tube_extra_kg, 'as_built': p.as_built,
              'runs': [str(r.path) for r in p.runs]} for p in plans]
    plan_path = Path(args.output) / 'fleet_plan.yaml'
    plan_path.write_text(dump_document({'machines': truth}),
                         encoding='utf-8')
    runs = sum(len(p.runs) for p in plans)
    print(f'{args.output}: {len(plans)} machines, {runs} runs over {args.days:g} days '
          f'(what each machine really did: {plan_path})', file=sys.stdout)
    for p in plans:
        print(f'  {p.machine_id}: {p.kind}'
              + (f', counterweight slipping {p.slip_mm_per_day * 1e3:.1f} um/day'
                 if p.slip_mm_per_day else '')
              + (f', tube swap {p.swap:%Y-%m-%d} ({p.tube_extra_kg * 1e3:.0f} g more than '
                 'declared)' if p.swap else ''))
    return 0
