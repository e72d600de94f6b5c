"""
``cvc-balance identify BAG``: the real rotor's unbalance from its load cells, per layout.

For each layout segment of a recorded run: the unbalance identified from the cells, the
layout's, the residual (what the layout does not know) with 95 % radii, and the fit's rms;
a table for people or, with ``--json``, one object (README "Monitor the real rotor").
"""

from cvc_balance.bag.run_summary import identified_summary as segment_summary
from cvc_balance.cli.arguments import (add_input_topics, BAG_HELP, count, input_topics,
                                       print_json)


def register(commands):
    """Add the identify command."""
    identify = commands.add_parser(
        'identify', help="the real rotor's unbalance from its load cells",
        description='Fit the static, couple and per-plane unbalance of each layout segment '
        'of a bag to its load-cell readings (supports/<name>/measured_load), and compare it '
        'with what the layout declares.')
    identify.add_argument('bag', metavar='BAG', help=BAG_HELP)
    identify.add_argument('--layout-file', metavar='FILE',
                          help="the declared layout for the whole run instead of the bag's")
    add_input_topics(identify)
    identify.add_argument('--window-revs', type=count, metavar='N',
                          help='fit only the last N revolutions of each segment (default: all)')
    identify.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    identify.add_argument('--json', action='store_true', help='print one JSON object')
    identify.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance identify``."""
    from cvc_balance.bag.identify_run import identify_bag
    segments, problems = identify_bag(args.bag, args.layout_file, args.joint_name,
                                      args.window_revs, names=input_topics(args))
    summary = {'bag': str(args.bag), 'problems': problems,
               'segments': [segment_summary(s) for s in segments]}
    if args.json:
        print_json(summary)
    else:
        print(format_table(summary))
    return 0


def format_table(summary):
    """Format the identify summary for people (g mm, degrees)."""
    lines = [f"bag {summary['bag']}"] + [f'  problem: {p}' for p in summary['problems']]
    for s in summary['segments']:
        lines.append(f"layout '{s['layout']['name']}' ({s['layout']['digest']}) "
                     f"{s['from']:.3f}-{s['to']:.3f} s: {s['samples']} samples, "
                     f"{s['readings']} cell readings ({s['dropped']} dropped), "
                     f"{s['revolutions']:.1f} revolutions")
        if not s['readings']:
            lines.append('  no load-cell readings (topics supports/<name>/measured_load)')
            continue
        if not s['identifiable']:
            lines.append('  not identifiable: too few readings, revolutions or speed')
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
