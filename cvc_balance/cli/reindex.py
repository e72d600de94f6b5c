"""``cvc-balance reindex BAG``: restore the summary of a killed recording (as ros2 bag reindex)."""

from cvc_balance.cli.arguments import BAG_HELP


def register(commands):
    """Add the reindex command."""
    reindex = commands.add_parser(
        'reindex', help='restore the summary of a killed recording',
        description='Keep a recording up to its last whole chunk and write the summary and '
        'footer a finished file has (and a rosbag2 directory\'s metadata.yaml), so that '
        'rosbags, ros2 bag and the mcap library read it. Written under a temporary name, '
        'then moved over the bag (or to -o).')
    reindex.add_argument('bag', metavar='BAG', help=BAG_HELP)
    reindex.add_argument('-o', '--output', metavar='OUT',
                         help='write the reindexed bag here instead of over BAG')
    reindex.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance reindex``."""
    from cvc_balance.bag.reindex import reindex
    from cvc_balance.files import check_output
    if args.output:
        check_output(args.output, [args.bag])
    for report in reindex(args.bag, args.output):
        state = 'was whole (summary rebuilt)' if report.already_whole else \
            f'kept {report.kept_bytes} bytes, dropped {report.dropped_bytes} torn ones'
        print(f'{report.path}: {report.chunks} chunks, {report.messages} messages; {state}')
        for problem in report.problems:
            print(f'  problem: {problem}')
    return 0
