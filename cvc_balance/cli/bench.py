"""``cvc-balance bench``: error against cost of every method, per scene."""


def register(commands):
    """Add the bench command."""
    bench = commands.add_parser('bench', help='error against cost of every method, per scene',
                                description='Compute the loads of six scenes with every '
                                'method; write the table (CSV) and the chart (PNG).')
    bench.add_argument('--csv', default='docs/bench.csv', metavar='FILE')
    bench.add_argument('--png', default='docs/bench.png', metavar='FILE')
    bench.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance bench``."""
    from cvc_balance.cli.arguments import staged_outputs
    from cvc_balance.study.bench import pareto_front, run
    with staged_outputs([], csv=args.csv, png=args.png) as out:    # checked before 4 minutes
        rows = run(out['csv'], out['png'])
    for scene in dict.fromkeys(r['scene'] for r in rows):
        print(f'Pareto front, {scene}: {", ".join(pareto_front(rows, scene))}')
    print(f'wrote {args.csv} and {args.png}')
    return 0
