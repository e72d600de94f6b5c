"""``cvc-balance bench``: error against cost of every method, per scene."""

import os


def register(commands):
    """Add the bench command."""
    bench = commands.add_parser(
        'bench', help='error against cost of every method, per scene',
        description='Compute the loads of six scenes with every method; write the table '
        '(CSV) and the chart (PNG). By default a quick run (under a minute): an eighth of '
        'the samples, its conclusions checked against the full run\'s table; --full for '
        'every sample (a few minutes).')
    bench.add_argument('--full', action='store_true',
                       help='every sample (default outputs docs/bench.csv, docs/bench.png)')
    bench.add_argument('--csv', metavar='FILE', help='the table (default docs/bench.csv '
                       'with --full, else docs/bench_quick.csv)')
    bench.add_argument('--png', metavar='FILE', help='the chart (default docs/bench.png '
                       'with --full, else docs/bench_quick.png)')
    bench.add_argument('--compare', default='docs/bench.csv', metavar='FILE',
                       help="a full run's table whose conclusions a quick run is checked "
                       'against (default docs/bench.csv; skipped if it does not exist)')
    bench.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance bench``."""
    from cvc_balance.cli.arguments import staged_outputs
    from cvc_balance.study.bench import (ACCURACY_GAP, compare, pareto_front, read_rows, run,
                                         run_title, SPEED_GAP)
    name = 'bench' if args.full else 'bench_quick'
    csv_path = args.csv or f'docs/{name}.csv'
    png_path = args.png or f'docs/{name}.png'
    with staged_outputs([], csv=csv_path, png=png_path) as out:    # checked before the work
        rows = run(out['csv'], out['png'], full=args.full)
    for scene in dict.fromkeys(r['scene'] for r in rows):
        print(f'Pareto front, {scene}: {", ".join(pareto_front(rows, scene))}')
    print(f'{run_title(args.full)}; wrote {csv_path} and {png_path}')
    if not args.full and os.path.exists(args.compare):
        differences = compare(rows, read_rows(args.compare))
        if differences:
            print(f'conclusions NOT those of the full run ({args.compare}):')
            for line in differences:
                print(f'  {line}')
        else:
            print(f'conclusions those of the full run ({args.compare}): the methods run, '
                  'the Pareto fronts (to the timing noise), and the order of every two '
                  f'methods it sets {SPEED_GAP:g}x apart in time or {ACCURACY_GAP:g}x in error')
    return 0
