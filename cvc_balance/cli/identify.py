"""
``cvc-balance identify BAG``: the real rotor's unbalance from its load cells, per layout.

For each layout segment of a recorded run: the verdict of record (the measured rotor's,
against its grade, with what the layout expects beside it), the unbalance identified from
the cells, the layout's, the residual (what the layout does not know) with 95 % radii, and
the fit's rms; a table for people or, with ``--json``, one object (the docs' "The measured
rotor"). A bag without load cells is refused (exit 1) with the topics it has: nothing reads
as a result when there is none.
"""

import sys

from cvc_balance.cli.arguments import (add_bounded, add_input_topics, BAG_HELP, EXIT_BAD_INPUT,
                                       EXIT_FAILURE, input_bag, input_file, input_topics,
                                       print_json)
from cvc_balance.physics import limits


def register(commands):
    """Add the identify command."""
    identify = commands.add_parser(
        'identify', help="the real rotor's unbalance from its load cells",
        description='Fit the static, couple and per-plane unbalance of each layout segment '
        'of a bag to its load-cell readings (supports/<name>/measured_load), judge the '
        'measured rotor against its grade, and compare it with what the layout declares. '
        'Never across a layout change: one fit per segment.')
    identify.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    identify.add_argument('--layout-file', type=input_file, metavar='FILE',
                          help="the declared layout for the whole run instead of the bag's")
    add_input_topics(identify)
    add_bounded(identify, '--window-revs', limit=limits.WINDOW_REVS, metavar='N',
                help='fit only the last N revolutions of each segment (default: all)')
    add_bounded(identify, '--segment', limit=limits.SEGMENT, metavar='N',
                help='report only layout segment N (1 = the first; default: all)')
    identify.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    identify.add_argument('--json', action='store_true', help='print one JSON object')
    identify.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance identify``."""
    from cvc_balance.bag.identify_run import identify_bag
    from cvc_balance.bag.rosbag2 import open_bag
    from cvc_balance.bag.run_summary import has_load_cells
    if not has_load_cells(args.bag):
        seen = ', '.join(f'{topic} ({kind})' for topic, kind in
                         sorted(open_bag(args.bag).topics().items())) or 'none'
        print(f'cvc-balance: error: {args.bag}: no load cells to identify from (topics '
              '.../supports/<name>/measured_load, geometry_msgs/msg/WrenchStamped); the bag '
              f'has: {seen}', file=sys.stderr)
        return EXIT_FAILURE
    segments, problems = identify_bag(args.bag, args.layout_file, args.joint_name,
                                      args.window_revs, names=input_topics(args))
    numbered = list(enumerate(segments, start=1))
    if args.segment is not None:
        if args.segment > len(segments):
            print(f'cvc-balance: error: {args.bag}: --segment {args.segment}, but the bag has '
                  f'{len(segments)} layout segment(s) with samples', file=sys.stderr)
            return EXIT_BAD_INPUT
        numbered = [numbered[args.segment - 1]]
    summary = {'bag': str(args.bag), 'problems': problems,
               'segments': [segment_summary(n, s) for n, s in numbered]}
    if args.json:
        print_json(summary)
    else:
        print(format_table(summary))
    return 0


def segment_summary(number, segment):
    """One identified segment as JSON-able data, its verdict of record first."""
    from cvc_balance.bag.run_summary import identified_summary
    from cvc_balance.identify.evidence import verdict_of_record
    from cvc_balance.physics.engine import RotorModel
    of_record = verdict_of_record(RotorModel.from_layout(segment.layout), segment.estimate,
                                  top_speed=segment.top_speed)
    return {'segment': number, 'verdict': of_record.record(), **identified_summary(segment)}


def format_table(summary):
    """Format the identify summary for people (g mm, degrees 0..360)."""
    lines = [f"bag {summary['bag']}"] + [f'  problem: {p}' for p in summary['problems']]
    for s in summary['segments']:
        verdict = s['verdict']
        lines.append(f"segment {s['segment']}: layout '{s['layout']['name']}' "
                     f"({s['layout']['digest']}) {s['from']:.3f}-{s['to']:.3f} s: "
                     f"{s['samples']} samples, {s['readings']} cell readings "
                     f"({s['dropped']} dropped), {s['revolutions']:.1f} revolutions")
        lines.append(f"  verdict {verdict['headline']}")
        if verdict['source'] == 'measured':
            lines.append(f"  {verdict['layout_expects']}")
        if verdict['disagreement']:
            lines.append(f"  {verdict['disagreement']}")
        if not s['identifiable']:
            continue
        lines.append(f"  fit: rms {s['fit']['rms_N']:.3g} N per reading")
        lines.append(f"  {'plane':6}{'z [m]':>8}{'identified [g mm]':>26}{'layout [g mm]':>24}"
                     f"{'residual [g mm]':>26}")
        for label, got, want, diff in zip(('I', 'II'), s['identified']['planes'],
                                          s['layout_prediction']['planes'],
                                          s['residual']['planes']):
            lines.append(f"  {label:6}{got['z']:8.3f}{_cell(got):>26}{_cell(want, False):>24}"
                         f"{_cell(diff):>26}")
        st = s['residual']['static_unbalance']
        lines.append(f"  static residual {st['kg_m'] * 1e6:.0f} +- {st['ci95_kg_m'] * 1e6:.0f} "
                     f"g mm at {st['angle_deg']:.1f} deg")
    return '\n'.join(lines)


def _cell(vector, interval=True):
    text = f"{vector['g_mm']:.0f} at {vector['angle_deg']:.1f}"
    return text + (f" +-{vector['ci95_g_mm']:.0f}" if interval else '')
