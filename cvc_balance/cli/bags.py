"""
Commands on bags: simulate, replay, view (rerun), play, info and record (live, ROS).

Heavy modules (rclpy, rerun) are imported by the command that needs them only.
"""

import argparse
import sys

from cvc_balance.cli.arguments import (add_bounded, add_input_topics, add_run_label,
                                       BAG_HELP, finite, input_bag, input_file, input_topics,
                                       machine_id, OUTPUT_BAG_HELP, print_json, run_label_of,
                                       staged_outputs, tolerance)
from cvc_balance.files import check_new_output, check_output
from cvc_balance.physics import limits
from cvc_balance.physics.model_choice import Tolerance
from cvc_balance.physics.motion import MAX_STAMP_JUMP


def register(commands):
    """Add simulate, replay, view, play, info and record."""
    simulate = commands.add_parser('simulate', help='make an input bag from a scenario',
                                   description='Write a bag of /layout and /joint_states '
                                   'from a scenario file (speed profile, noise, layout changes).')
    simulate.add_argument('scenario', type=input_file, metavar='SCENARIO',
                          help='scenario file (YAML)')
    simulate.add_argument('-o', '--output', required=True, metavar='BAG', help=OUTPUT_BAG_HELP)
    simulate.add_argument('--machine-id', type=machine_id, metavar='ID',
                          help='the machine the run is recorded on, written into the bag '
                          '(MCAP metadata; metadata.yaml custom_data for a directory)')
    add_run_label(simulate)
    simulate.set_defaults(run=_simulate)

    replay = commands.add_parser('replay', help='compute a bag\'s outputs offline',
                                 description='Read a bag\'s motion and layouts, compute every '
                                 'output with the vectorised engine, write them as a bag and '
                                 'print a summary. No ROS graph needed.')
    replay.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    replay.add_argument('-o', '--output', metavar='OUT', help=OUTPUT_BAG_HELP)
    replay.add_argument('--layout-file', type=input_file, metavar='FILE',
                        help='use this layout for the whole run ("what if") instead of the '
                        'bag\'s')
    add_input_topics(replay)
    replay.add_argument('--joint-name', default='gantry_joint', help='JointState joint')
    add_bounded(replay, '--alpha-time-constant', limit=limits.TIME_CONSTANT, default=0.1,
                metavar='S', help='as the node\'s parameter (s)')
    add_bounded(replay, '--max-speed', limit=limits.SPEED, default=1000.0, metavar='W',
                help='as the node\'s parameter (rad/s)')
    add_bounded(replay, '--max-stamp-jump', limit=limits.STAMP_JUMP, default=MAX_STAMP_JUMP,
                metavar='S', help='as the node\'s parameter (s): a sample stamped more than S '
                'from the previous is rejected unless the next one agrees')
    replay.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    replay.add_argument('--progress', action=argparse.BooleanOptionalAction, default=None,
                        help='progress bar (default: on a terminal)')
    replay.add_argument('--rrd', metavar='RUN.rrd', help='also log the run for rerun')
    replay.add_argument('--json', action='store_true',
                        help='print the summary as one JSON object (its fields: the docs\' '
                        '"JSON outputs"); with load cells in the bag, each segment\'s '
                        'identified unbalance too')
    replay.add_argument('--coefficients', type=input_file, metavar='FILE',
                        help='influence coefficients of this machine type (from calibrate or '
                        'influence -o, kg m per plane I and II): without load cells, the '
                        "vibration channels' 1x readings give each plane's unbalance through "
                        'them (readings = C u), hence the verdict "measured by the vibration '
                        'sensors through coefficients FILE"; coefficients made on another '
                        'layout (digest) or at another speed are not used, and the line says '
                        "why the layout's verdict stands")
    replay.add_argument('--tolerance', type=tolerance, nargs=3, metavar=('N', 'NM', 'TNM'),
                        help='largest change accepted in the forces (N), moments (N m) and '
                        'drive torque (N m), inf for an output not asked: each layout takes '
                        "the smallest model within it over its samples' speeds and "
                        'accelerations, and the summary says which')
    replay.set_defaults(run=_replay)

    view = commands.add_parser('view', help='log every sample of a bag to a rerun .rrd',
                               description='Compute a bag\'s run (as replay does) and log it '
                               'for the rerun viewer: the turning gantry, loads, unbalance.')
    view.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    view.add_argument('-o', '--output', required=True, metavar='RUN.rrd')
    add_bounded(view, '--every', limit=limits.EVERY, default=10, metavar='N',
                help='draw load arrows for every N-th sample (plots get all)')
    view.add_argument('--joint-name', default='gantry_joint')
    view.add_argument('--layout-file', type=input_file, metavar='FILE',
                      help="use this layout for the whole run instead of the bag's (a bag "
                      'recorded without a layout)')
    add_input_topics(view)
    view.add_argument('--screenshot', metavar='PNG', help='also render the viewer headless '
                      '(needs a Vulkan adapter, e.g. Mesa lavapipe) and save a picture')
    view.add_argument('--at', type=finite, metavar='S', help='the picture\'s moment: S '
                      'seconds after the first sample (default: the last sample)')
    view.set_defaults(run=_view)

    play = commands.add_parser('play', help='publish a bag\'s inputs live, record the outputs',
                               description='Publish the bag\'s layout and motion messages with '
                               'their timing (to drive a running balance_monitor) and record '
                               'the node\'s outputs. A tach (--keyphasor, or a bag with '
                               'neither joint_states nor speed) goes out on keyphasor: start '
                               'the node with -p keyphasor_topic:=keyphasor.')
    play.add_argument('bag', type=input_bag, metavar='BAG', help=BAG_HELP)
    add_bounded(play, '--rate', limit=limits.PLAY_RATE, default=1.0, metavar='X',
                help='playback speed factor (default 1)')
    play.add_argument('-o', '--output', metavar='OUT', help='record the node\'s outputs (and '
                      '/diagnostics) to this bag: a .mcap file, or a rosbag2 directory for '
                      'any other name; a name not taken (never replaced)')
    add_input_topics(play)
    add_bounded(play, '--wait', limit=limits.WAIT, default=20.0, metavar='S',
                help='give up (exit code 1) when no node subscribes to the motion topic, '
                "or the recorder sees none of the node's outputs, within S seconds "
                '(default 20)')
    play.set_defaults(run=_play)

    info = commands.add_parser('info', help='what ros2 bag info prints of a bag, and its '
                               'machine and layouts',
                               description='Print what ros2 bag info prints of a bag (files, '
                               'size, storage, ROS distro, duration, start and end in local '
                               'time, messages, each topic with its type, count and '
                               'serialization format), then the machine it was recorded on, '
                               'the run it is (record --run) and its layouts (name, digest, '
                               'log time they came into force). Counts and times are of '
                               'the messages read.')
    info.add_argument('bag', metavar='BAG', help=BAG_HELP)
    info.add_argument('--json', action='store_true',
                      help='print one JSON object: path, files, bag_size (bytes), '
                      'storage_identifier, ros_distro, duration_ns, start_ns, end_ns, '
                      'message_count, topics [{name, type, count, serialization_format}], '
                      'services [{name, type, event_count, serialization_format}], '
                      'machine_id, run {kind, trial} (null: not labelled), '
                      'layouts [{log_time_ns, name, digest, rejected}], problems')
    info.set_defaults(run=_info)

    record = commands.add_parser('record', help='record topics to a bag until Ctrl-C',
                                 description='Record the run\'s inputs and outputs (raw CDR) '
                                 'to a rosbag2 MCAP file; SIGINT or SIGTERM finalises it.')
    record.add_argument('-o', '--output', required=True, metavar='BAG',
                        help=OUTPUT_BAG_HELP + '; a name not taken (never replaced)')
    record.add_argument('topics', nargs='*', metavar='TOPIC',
                        help='topics (patterns with *); default: inputs, outputs, diagnostics')
    record.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    add_bounded(record, '--chunk-kib', limit=limits.CHUNK_KIB, default=1024, metavar='K',
                help='chunk size; a killed recorder loses at most one chunk')
    record.add_argument('--machine-id', type=machine_id, metavar='ID',
                        help='the machine recorded, written into the bag (MCAP metadata; '
                        'metadata.yaml custom_data for a directory)')
    add_run_label(record)
    record.add_argument('--ready-when', action='append', default=[], metavar='TOPIC',
                        help='print "ready" once this topic\'s publisher is matched')
    record.add_argument('--ros-args', nargs=argparse.REMAINDER, default=[],
                        help='ROS arguments (remapping, namespace)')
    record.set_defaults(run=_record)


def _simulate(args):
    from cvc_balance.bag.scenario import load_scenario, write_bag
    label = run_label_of(args)
    with staged_outputs([args.scenario], bags=('bag',), bag=args.output) as out:
        scenario = load_scenario(args.scenario)
        count = write_bag(scenario, out['bag'], machine_id=args.machine_id, label=label)
    print(f'{args.output}: {count} samples over {scenario.time[-1]:.3f} s, '
          f'{len(scenario.layouts)} layouts')
    return 0


def _replay(args):
    from cvc_balance.bag.machine import bag_custom_data, MACHINE_ID
    from cvc_balance.bag.replay import replay
    from cvc_balance.bag.run_summary import format_replay, replay_record
    show = args.progress if args.progress is not None else sys.stderr.isatty()
    with staged_outputs([args.bag, args.layout_file, args.coefficients], bags=('bag',),
                        bag=args.output, rrd=args.rrd) as out:
        # The verdict of record needs the cells' fit first: the text, the JSON and the
        # view all lead with it.
        identified = _identified(args)
        logger = _rerun_logger(out['rrd'], args.bag, identified=identified) \
            if args.rrd else None
        summary = replay(args.bag, out['bag'], args.layout_file, args.joint_name,
                         args.alpha_time_constant, args.max_speed,
                         '' if args.compression == 'none' else args.compression,
                         ReplayProgress() if show else None, observer=logger,
                         tolerance=Tolerance(*args.tolerance) if args.tolerance else None,
                         names=input_topics(args), max_stamp_jump=args.max_stamp_jump)
        if logger:
            _log_cells(logger, identified)
            logger.finish()
    summary.output = args.output or ''
    record = replay_record(summary, identified, bag_custom_data(args.bag).get(MACHINE_ID),
                           _coefficient_readings(args))
    if args.json:
        print_json(record)
    else:
        print(format_replay(record))
    return 0


def _coefficient_readings(args):
    """Return the bag's readings through ``--coefficients`` ([CoefficientReading]), or None."""
    if not args.coefficients:
        return None
    from cvc_balance.bag.field_run import coefficient_readings, coefficients_identity
    from cvc_balance.cli.field import read_coefficients
    calibration, record = read_coefficients(args.coefficients)
    return coefficient_readings(args.bag, calibration, record,
                                coefficients_identity(args.coefficients, record),
                                input_topics(args), args.layout_file,
                                joint_name=args.joint_name)


def _identified(args):
    """Return the bag's identified segments ([IdentifiedSegment]), None without cells."""
    from cvc_balance.bag.identify_run import identify_bag
    from cvc_balance.bag.run_summary import has_load_cells
    if not has_load_cells(args.bag):
        return None
    return identify_bag(args.bag, getattr(args, 'layout_file', None), args.joint_name,
                        time_constant=getattr(args, 'alpha_time_constant', 0.1),
                        max_speed=getattr(args, 'max_speed', 1000.0),
                        names=input_topics(args))[0]


class ReplayProgress:
    """A progress bar (tqdm: rate and time left) fed replay's (done, total) callback."""

    def __init__(self):
        """Make the bar on the first callback, when the total is known."""
        self._bar = None

    def __call__(self, done, total):
        """Show ``done`` of ``total`` samples; close the bar when all are done."""
        from tqdm import tqdm
        if self._bar is None:
            self._bar = tqdm(total=total, desc='replay', unit='samples', unit_scale=True,
                             file=sys.stderr, leave=False)
        self._bar.update(done - self._bar.n)
        if done >= total:
            self._bar.close()


def _log_cells(logger, identified):
    """Add a bag's load cells (if it has any) to its rerun view: measured and residual."""
    from cvc_balance.bag.identify_run import observe
    for segment in identified or ():
        observe(logger, segment)


def _rerun_logger(path, bag, every=10, identified=None):
    """Return a RunLogger saving to ``path``, told each segment's verdict of record first."""
    from cvc_balance.bag.identify_run import segment_verdict
    from cvc_balance.view.rerun_log import open_recording, RunLogger
    evidence = {(s.layout.digest(), s.start_ns): segment_verdict(s) for s in identified or ()}
    return RunLogger(open_recording('save', path, name=bag), every, evidence=evidence)


def _view(args):
    from cvc_balance.bag.replay import replay
    with staged_outputs([args.bag, args.layout_file], rrd=args.output,
                        png=args.screenshot) as out:
        identified = _identified(args)
        logger = _rerun_logger(out['rrd'], args.bag, args.every, identified)
        summary = replay(args.bag, layout_file=args.layout_file, joint_name=args.joint_name,
                         observer=logger, names=input_topics(args))
        _log_cells(logger, identified)
        logger.finish()
        print(f'{args.output}: {summary.accepted} samples of {args.bag}, '
              f'{len(summary.segments)} layouts')
        for problem in summary.problems:
            print(f'  problem: {problem}')
        if args.screenshot:
            from cvc_balance.view.screenshot import render, ViewerError
            try:
                when = render(out['rrd'], out['png'], args.at)
            except ViewerError as error:
                print(f'cvc-balance: error: {args.screenshot}: {error}', file=sys.stderr)
                return 1
            print(f'{args.screenshot}: the viewer {when * 1e-9:.3f} s after the first sample')
    return 0


def _play(args):
    from cvc_balance.ros.player import play_main
    if args.output:         # recorded live, in place (a killed run keeps its chunks)
        check_new_output(args.output)
        check_output(args.output, [args.bag], directory=not args.output.endswith('.mcap'))
    return play_main(args, input_topics(args))


def _info(args):
    from cvc_balance.bag.info import bag_info, format_info, info_record
    found = bag_info(args.bag)
    if args.json:
        print_json(info_record(found))
    else:
        print(format_info(found))
    return 0


def _record(args):
    from cvc_balance.ros.recorder import record_main
    args.run_label = run_label_of(args)
    check_new_output(args.output)    # recorded live, in place (see cvc-balance reindex)
    return record_main(args)
