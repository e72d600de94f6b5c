"""Argument types and exit codes shared by the commands."""

import argparse
from contextlib import contextmanager, ExitStack
import json
import math
import os
import re
import stat

from cvc_balance.files import check_output, distinct_outputs, replaced_when_done
from cvc_balance.physics.limits import MAX_MAGNITUDE

EXIT_FAILURE = 1
"""Exit code of a command that failed for another reason than its input (a bug)."""
EXIT_BAD_INPUT = 2
"""Exit code of a command given bad input (one line on stderr says what)."""


def number(text):
    """Parse a float (argparse type)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None


def finite(text):
    """Parse a finite float within +-MAX_MAGNITUDE, as layouts' numbers (argparse type)."""
    value = number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'must be finite, got {text!r}')
    if abs(value) > MAX_MAGNITUDE:
        raise argparse.ArgumentTypeError(f'must be within +-{MAX_MAGNITUDE:g}, got {text!r}')
    return value


def positive(text):
    """Parse a finite float > 0 (argparse type)."""
    value = finite(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text!r}')
    return value


def count(text):
    """Parse an integer >= 1 (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a whole number: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {text!r}')
    return value


def tolerance(text):
    """Parse a tolerance: a float >= 0 or inf (argparse type)."""
    value = number(text)
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f'must be >= 0 (or inf), got {text!r}')
    return value


_TOPIC = re.compile(r'^[~/]?[A-Za-z_{][A-Za-z0-9_{}/]*$')


def topic_name(text):
    """Parse a ROS topic name (argparse type): letters, digits, '_' and '/' (REP-144)."""
    if not _TOPIC.match(text) or '//' in text or text.endswith('/'):
        hint = ' (a layout file goes with --layout-file FILE)' if '.' in text else ''
        raise argparse.ArgumentTypeError(f'not a topic name: {text!r}{hint}')
    return text


def machine_id(text):
    """Parse a machine id (argparse type; :func:`cvc_balance.bag.machine.check_machine_id`)."""
    from cvc_balance.bag.machine import check_machine_id
    try:
        return check_machine_id(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_run_label(parser):
    """Add ``--run KIND`` and ``--trial PLANE:MASS_KG@ANGLE_DEG,RADIUS_M`` (the run's label)."""
    from cvc_balance.bag.run_label import KINDS
    parser.add_argument('--run', choices=KINDS, metavar='KIND', dest='run_kind',
                        help='what run of a field-balancing visit this is, written into the '
                        f'bag ({", ".join(KINDS)}); calibrate takes a trial run\'s weight '
                        'from it')
    parser.add_argument('--trial', metavar='PLANE:MASS_KG@ANGLE_DEG,RADIUS_M',
                        help='with --run trial: the trial weight on the rotor (kg, degrees '
                        'from the rotor\'s X axis, m), e.g. I:0.2@0,0.68')


def run_label_of(args):
    """Return the RunLabel of ``--run`` and ``--trial`` (None: not given); ValueError if wrong."""
    from cvc_balance.bag.run_label import run_label
    if args.run_kind is None:
        if args.trial is not None:
            raise ValueError('--trial goes with --run trial (say what run this is)')
        return None
    return run_label(args.run_kind, args.trial)


BAG_HELP = 'a bag: .mcap or .db3 file, or rosbag2 directory (metadata.yaml and its files)'
OUTPUT_BAG_HELP = ('bag to write: a .mcap file, or any other name for a rosbag2 directory '
                   '(as ros2 bag record -o)')


class Renamed(argparse.Action):
    """An old spelling of an option: refused with the new name (one vocabulary everywhere)."""

    def __init__(self, option_strings, dest, instead, **kwargs):
        """``instead``: what to give now, e.g. '--layout-topic TOPIC or --layout-file FILE'."""
        super().__init__(option_strings, dest, nargs='?', help=argparse.SUPPRESS, **kwargs)
        self.instead = instead

    def __call__(self, parser, namespace, values, option_string=None):
        """Refuse, naming the option to give instead."""
        parser.error(f'{option_string} is no longer an option here: give {self.instead}')


def renamed(parser, option, instead):
    """Refuse ``option`` (its old spelling) on ``parser``, naming what to give ``instead``."""
    parser.add_argument(option, action=Renamed, instead=instead,
                        dest=f'renamed_{option.strip("-").replace("-", "_")}')


def add_input_topics(parser):
    """
    Add the bag's input topics, if not the node's: motion (an encoder or a tach), layout.

    One vocabulary across the commands: a topic is ``--NAME-topic TOPIC`` (``--layout-topic``,
    ``--speed-topic``), a file ``--layout-file FILE``, a speed ``--speed W`` in rad/s; the
    old ``--layout TOPIC`` and ``--speed TOPIC`` are refused naming the new spelling.
    """
    parser.add_argument('--joint-states', type=topic_name, metavar='TOPIC',
                        help='JointState topic of the rotor (default: joint_states, also '
                        'under a namespace)')
    parser.add_argument('--speed-topic', type=topic_name, metavar='TOPIC',
                        help='Float64 speed topic (rad/s), used when there is no JointState '
                        '(default: speed); alone, it is used instead of joint_states')
    add_keyphasor(parser, 'a once-per-revolution tach instead of an encoder: the rotor '
                  'angle is 0 at each of its marks and interpolated between them, the speed '
                  'the mean over 8 revolutions; missed and doubled marks are repaired or '
                  'dropped and said (default: keyphasor, when the bag has neither '
                  'joint_states nor speed)')
    parser.add_argument('--layout-topic', type=topic_name, metavar='TOPIC',
                        help='String layout topic (default: layout)')
    renamed(parser, '--layout', '--layout-topic TOPIC (the bag\'s layout topic) or '
            '--layout-file FILE (a layout file)')
    renamed(parser, '--speed', '--speed-topic TOPIC (the bag\'s speed topic; --speed W is '
            'a speed in rad/s where a command takes one)')


def add_keyphasor(parser, what):
    """Add --keyphasor TOPIC (``what`` it is for), --keyphasor-edge and --keyphasor-threshold."""
    parser.add_argument('--keyphasor', type=topic_name, metavar='TOPIC',
                        help=f'{what}. std_msgs/Float64: a sampled tach signal, each sample '
                        'at its log time, the marks at the crossings of a threshold; or '
                        'sensor_msgs/TimeReference: one message a mark, time_ref its time')
    parser.add_argument('--keyphasor-edge', choices=('rising', 'falling'), default='rising',
                        help='the crossing of a sampled tach that is the mark (default '
                        'rising)')
    parser.add_argument('--keyphasor-threshold', type=finite, metavar='LEVEL',
                        help="a sampled tach's threshold, in its unit (default: midway "
                        'between its low and high levels)')


def input_topics(args):
    """Return the :class:`cvc_balance.bag.inputs.InputTopics` the options name."""
    from cvc_balance.bag.inputs import InputTopics
    return InputTopics(args.joint_states, args.speed_topic, args.layout_topic, args.keyphasor,
                       args.keyphasor_edge, args.keyphasor_threshold)


def print_json(data):
    """
    Print ``data`` as strict JSON (RFC 8259: no NaN or Infinity).

    A non-finite number is a bug upstream; it raises ValueError rather than printing
    something a JSON reader refuses.
    """
    print(json.dumps(data, indent=2, allow_nan=False))


@contextmanager
def staged_outputs(inputs, bags=(), **outputs):
    """
    Check a command's outputs before any work, and write them under temporary names.

    ``outputs``: name -> path (None: not asked); ``inputs``: the paths the command
    reads (an output may be none of them); ``bags``: the names of outputs that are bags
    (a directory name means a rosbag2 directory, which must be empty or a bag).
    Yields {name: temporary path or None}; each is moved onto its path when the block
    ends without error. Raises OutputError (or BagError) first, before any work.
    """
    distinct_outputs(outputs.values())
    for name, path in outputs.items():
        if path is None:
            continue
        directory = name in bags and not str(path).endswith('.mcap')
        check_output(path, inputs, directory=directory)
        if directory:
            from cvc_balance.bag.rosbag2 import writable_directory
            writable_directory(path)
    with ExitStack() as stack:
        yield {name: None if path is None else stack.enter_context(replaced_when_done(path))
               for name, path in outputs.items()}


def within(limit):
    """
    Return an argparse type: a number within ``limit`` (a :class:`limits.Limit`).

    A whole number when the limit's ends are (counts, seeds); the refusal names the
    range, its unit and its reason.
    """
    whole = isinstance(limit.low, int) and isinstance(limit.high, int)

    def parse(text):
        if whole:
            try:
                value = int(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f'not a whole number: {text!r}') from None
        else:
            value = number(text)
            if not math.isfinite(value):
                raise argparse.ArgumentTypeError(f'must be finite, got {text!r}')
        if not limit.contains(value):
            unit = f' {limit.unit}' if limit.unit else ''
            raise argparse.ArgumentTypeError(f'must be {limit.describe()} ({limit.reason}), '
                                             f'got {text}{unit}')
        return value
    parse.__name__ = 'whole number' if whole else 'number'
    return parse


def input_file(text):
    """
    Parse a path to read (argparse type): refused when it is there but no regular file.

    A FIFO, a device or a socket could block the command or never end; a directory is
    no file. A path that is not there is left to the reader (which says so).
    """
    return _input_path(text, directory=False)


def input_path(text):
    """Parse a path to read that may be a directory (argparse type): a bag, a table."""
    return _input_path(text, directory=True)


input_bag = input_path
"""A bag's path (argparse type): a regular file or a (rosbag2) directory."""


def _input_path(text, directory):
    from cvc_balance.physics.documents import file_kind
    try:
        mode = os.stat(text).st_mode
    except OSError:
        return text                              # absent or unreadable: the reader says
    if stat.S_ISREG(mode) or directory and stat.S_ISDIR(mode):
        return text
    wanted = 'a regular file or a directory' if directory else 'a regular file'
    raise argparse.ArgumentTypeError(f'{text}: {file_kind(mode)}, not {wanted}: refused')


def add_bounded(parser, *flags, limit, help='', **options):
    """
    Add a numeric option whose value must be within ``limit``; its help says the range.

    ``options`` as ``add_argument``'s (default, metavar, nargs...).
    """
    said = f'{help} ' if help else ''
    parser.add_argument(*flags, type=within(limit),
                        help=said + f'({limit.describe()})'.replace('%', '%%'), **options)
