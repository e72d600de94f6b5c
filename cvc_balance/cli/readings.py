"""
``cvc-balance readings BAG``: each vibration channel's 1x amplitude and phase per steady stretch.

Against a once-per-revolution mark (keyphasor), as a field balancing instrument reads
them; no encoder, layout or load cell needed (:mod:`cvc_balance.bag.readings`).
"""

import sys

from cvc_balance.cli.arguments import (add_bounded, add_keyphasor, BAG_HELP, input_bag,
                                       print_json)
from cvc_balance.physics import limits


def register(commands):
    """Add the readings command."""
    readings = commands.add_parser(
        'readings', help='1x amplitude and phase of every vibration channel against a '
        'keyphasor, per steady stretch',
        description='Read the once-per-revolution (1x) amplitude and phase of every '
        'vibration channel of a bag (std_msgs/Float64 topics at their log times; '
        'geometry_msgs/Vector3Stamped and sensor_msgs/Imu linear acceleration as TOPIC/x, '
        '/y, /z at their header stamps) against a keyphasor, for every stretch of at least '
        '8 revolutions at steady speed, with its 95 % radius, the speed and the '
        'revolutions used. Phase: degrees 0-360, the LAG from the mark to the channel\'s '
        'first positive 1x peak (the angle the rotor turns after the mark). Missed, doubled '
        'and irregular marks are repaired, dropped or left as gaps, and said.',
        epilog='JSON (--json): {"segments": [{"from", "to" (s, the keyphasor\'s clock), '
        '"speed" (rad/s), "revolutions", "channels": [{"name", "unit", "amplitude", '
        '"phase_deg", "ci95"}]}]}')
    readings.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    add_keyphasor(readings, 'the once-per-revolution mark (default: keyphasor, also under '
                  'a namespace)')
    readings.add_argument('--channel-unit', action='append', metavar='TOPIC=UNIT',
                          help="a channel's unit, e.g. accel=m/s^2 or probe=counts "
                          "(repeat for each topic; default: an Imu's m/s^2, others 'as "
                          "recorded')")
    add_bounded(readings, '--speed-tolerance', limit=limits.SPEED_TOLERANCE, default=1.0,
                metavar='PERCENT', help='a stretch is steady while every mark\'s speed (over 8 '
                'revolutions) is within this of the stretch\'s (default 1 %%)')
    readings.add_argument('--json', action='store_true', help='print one JSON object')
    readings.set_defaults(run=run)


def run(args):
    """Run ``cvc-balance readings``."""
    from cvc_balance.bag.channels import parse_units
    from cvc_balance.bag.readings import bag_readings, readings_summary
    result = bag_readings(args.bag, args.keyphasor, args.keyphasor_edge,
                          args.keyphasor_threshold, parse_units(args.channel_unit),
                          args.speed_tolerance / 100.0)
    summary = readings_summary(result)
    if args.json:
        for problem in result.problems:
            print(f'cvc-balance: warning: {problem}', file=sys.stderr)
        print_json(summary)
    else:
        print(format_table(result, summary))
    return 0


def format_table(result, summary):
    """Format the readings for people: one block per stretch, a line per channel."""
    lines = [f'bag {result.bag}', result.keyphasor.summary()]
    lines += [f'  problem: {p}' for p in result.problems
              if p != result.keyphasor.summary()]
    width = max((len(c['name']) for s in summary['segments'] for c in s['channels']),
                default=7)
    for s in summary['segments']:
        lines.append(f"{s['from']:.3f}-{s['to']:.3f} s: {s['speed']:.4g} rad/s "
                     f"({s['speed'] * 60 / 6.283185307179586:.5g} rpm), "
                     f"{s['revolutions']} revolutions")
        lines.append(f"  {'channel':{width}}  {'1x amplitude':>14}  {'phase lag':>9}  "
                     f"{'95 % radius':>11}  unit")
        for c in s['channels']:
            lines.append(f"  {c['name']:{width}}  {c['amplitude']:14.5g}  "
                         f"{c['phase_deg']:7.1f} deg  {c['ci95']:11.3g}  {c['unit']}")
    return '\n'.join(lines)
