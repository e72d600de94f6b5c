"""``cvc-balance reindex BAG``: mend a killed or damaged recording (as ros2 bag reindex)."""

from cvc_balance.cli.arguments import BAG_HELP, input_bag


def register(commands):
    """Add the reindex command."""
    reindex = commands.add_parser(
        'reindex', help='mend a killed or damaged recording, beside it',
        description='Write what a recording holds (every chunk whose CRC holds, also past a '
        'damaged record) as a whole file with its summary and footer (and a rosbag2 '
        'directory\'s metadata.yaml, keeping its custom_data), so that rosbags, ros2 bag and '
        'the mcap library read it. Written beside the bag (run.mcap -> run.reindexed.mcap, '
        'a name not taken), or to -o, or over it with --in-place; refused, the bag left as it '
        'is, when the mcap library (CRCs checked) or rosbags reads more messages of a topic '
        'from the bag than the result keeps.')
    reindex.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    where = reindex.add_mutually_exclusive_group()
    where.add_argument('-o', '--output', metavar='OUT',
                       help='write the reindexed bag here (default: beside BAG)')
    where.add_argument('--in-place', action='store_true',
                       help='replace BAG by the result (once it is complete and checked)')
    reindex.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance reindex``."""
    from pathlib import Path

    from cvc_balance.bag.reindex import reindex
    from cvc_balance.files import check_output
    if args.output:
        check_output(args.output, [args.bag], directory=Path(args.bag).is_dir())
    for report in reindex(args.bag, args.output, args.in_place):
        if report.already_whole:
            state = 'already whole: nothing written'
        else:
            state = f'written to {report.output}'
            if report.dropped_chunks:
                state += f' ({report.dropped_chunks} unreadable chunks not copied)'
        print(f'{report.path}: {report.chunks} chunks, {report.messages} messages; {state}')
        for problem in report.problems:
            print(f'  problem: {problem}')
        if report.readers:
            print('  checked: ' + ', '.join(f'{name} reads {count}' for name, count in
                                            report.readers.items())
                  + f' messages of the bag; the result keeps {report.messages}')
    return 0
