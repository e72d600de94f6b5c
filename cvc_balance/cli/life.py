"""
``cvc-balance life BAG``: what a recorded run's loads did to its bearings (ISO 281).

Per layout segment and support whose layout describes its bearing (``bearing: {C, type,
...}``): the revolutions, the mean equivalent load, the life used (Palmgren-Miner, a
fraction of the rating life), the rating life in hours at the run's duty and how much
more life the unbalance used than the same run of the rotor balanced; from the layout's
loads and, where a support's load cell can tell, from the measured ones
(:mod:`cvc_balance.bag.life_run`). A bag whose layouts describe no bearing gets one line
naming the field to add, no numbers, exit 1.
"""

import sys

from cvc_balance.cli.arguments import (add_input_topics, BAG_HELP, EXIT_FAILURE, input_bag,
                                       input_file, input_topics, print_json)


def register(commands):
    """Add the life command."""
    life = commands.add_parser(
        'life', help="what a run's loads did to its bearings (ISO 281 rating life)",
        description='For each layout segment of a bag and each support whose layout '
        'describes its bearing (supports[].bearing: C in N, type ball or roller, X, Y, e, '
        'a1, limit_speed): the revolutions, the mean equivalent load P_m, the life used '
        '(sum of (P/C)^p over the revolutions / 10^6 / a1: 1 is the whole rating life), '
        'the rating life in hours at the run\'s duty (L10h at a1 1), and how much more life '
        'the unbalance used than the same run of the rotor balanced; from the layout and, '
        "where a support's load cell (supports/<name>/measured_load) can tell, measured.")
    life.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    life.add_argument('--layout-file', type=input_file, metavar='FILE',
                      help="the layout for the whole run instead of the bag's (e.g. one "
                      'that describes the bearings)')
    add_input_topics(life)
    life.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    life.add_argument('--json', action='store_true', help='print one JSON object: '
                      '{"segments": [{"layout", "supports": [{"name", "bearing", '
                      '"revolutions", "layout", "measured"}]}]}')
    life.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance life``."""
    from cvc_balance.bag.life_run import FIELD, life_lines, NO_BEARINGS
    from cvc_balance.bag.run_summary import analyse_bag
    record = analyse_bag(args.bag, args.layout_file, args.joint_name,
                         names=input_topics(args))
    segments = record['segments']
    if not any(segment['life'] for segment in segments):
        layouts = ', '.join(dict.fromkeys(f"'{s['layout']['name']}' ({s['layout']['digest']})"
                                          for s in segments))
        print(f'cvc-balance: error: {args.bag}: {NO_BEARINGS}; its layouts: {layouts}',
              file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        print_json({'segments': [{'layout': s['layout'], 'supports': s['life'] or []}
                                 for s in segments]})
        return 0
    lines = [f"bag {record['bag']}: bearing life per layout segment (ISO 281 basic rating "
             'life, Palmgren-Miner over the run)']
    lines += [f'  problem: {p}' for p in record['problems']]
    for segment in segments:
        layout = segment['layout']
        start = segment['from'] if segment['from'] is not None else 0.0
        lines.append(f"layout '{layout['name']}' ({layout['digest']}) from {start:.3f} s: "
                     f"{segment['samples']} samples, top speed {segment['top_speed']:.4g} "
                     'rad/s')
        if not segment['life']:
            lines.append(f'  no bearing data in this layout (field {FIELD})')
            continue
        lines += life_lines(segment['life'], segment['top_speed'])
    print('\n'.join(lines))
    return 0
